"""The shape of ``src/hdid``, read from the code (an ``ast`` walk; imports inside functions
count): data flows one way — log → model → simulate → problem → fit → posterior / diagnose
→ CLI — so a module imports only from its own layer or lower ones, never in a cycle, and
no module grows past ``MAX_LINES``.

What is not there yet (issue 20) is listed in ``DEBT``/``LONG``, and the lists may only
shrink: a test fails when an entry is no longer needed, so each fix is recorded here.
"""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1] / "src" / "hdid"

#: Layers, lowest first, one folder each (the top-level modules of the first are the
#: package's base); every module of src/hdid must be in one (a new folder: add it).
LAYERS = [
    # errors, configuration, units, small numerics with no hdid dependency
    {"_errors", "_config", "_units", "_compile_clock", "_covariance"},
    # logs: types, reading, validation, writing
    {"_log"},
    # physics: effects, the reference (event-driven, SciPy) simulator
    {"effects", "reference"},
    # models: the parameter set, free model, positional error, transforms
    {"_models"},
    # simulation (free and driven), data preparation, synthetic logs
    {"_simulation"},
    # problems: parameters ↔ residuals, and what is evaluated on them, compiled
    {"_problems"},
    # results: data, their persistence and their figures
    {"_results"},
    # fitting and the analysis at the optimum
    {"_fitting"},
    # posterior and diagnosis
    {"_posterior", "_diagnosis"},
    # the command line; the package's lazy public namespace
    {"cli", "__init__"},
]

#: Upward or cyclic imports still in the code: (importer, imported). Only shrinks.
DEBT: set[tuple[str, str]] = set()
MAX_LINES = 500
#: Modules still over ``MAX_LINES``: their size today is their ceiling. Only shrinks.
LONG: dict[str, int] = {}


def _modules() -> dict[str, Path]:
    mods = {}
    for p in ROOT.rglob("*.py"):
        name = ".".join(p.relative_to(ROOT).with_suffix("").parts)
        mods[name.removesuffix(".__init__") if name != "__init__" else "__init__"] = p
    return mods


def _layer(name: str) -> int:
    top = name.split(".")[0]
    for i, layer in enumerate(LAYERS):
        if top in layer:
            return i
    raise AssertionError(f"src/hdid/{name}: in no layer of tests/test_layers.py; add it")


def _imports(mods: dict[str, Path]) -> set[tuple[str, str]]:
    edges = set()
    for name, path in mods.items():
        tree = ast.parse(path.read_text())
        skip = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                and "TYPE_CHECKING" in ast.unparse(node.test) for n in ast.walk(node)}
        pkg = name.split(".") if path.name == "__init__.py" and name != "__init__" else name.split(".")[:-1]
        for node in ast.walk(tree):
            if id(node) in skip or not isinstance(node, ast.ImportFrom) or not node.level:
                continue
            base = pkg[: len(pkg) - node.level + 1] if node.level > 1 else pkg
            target = ".".join(base + ([node.module] if node.module else []))
            cands = [target] + [f"{target}.{a.name}".lstrip(".") for a in node.names]
            for t in cands:
                t = t.lstrip(".")
                if t in mods and t != name and not name.startswith(t + "."):
                    edges.add((name, t))
    return edges


def _cycles(edges) -> list[set[str]]:
    graph: dict[str, set[str]] = {}
    for a, b in edges:
        graph.setdefault(a, set()).add(b)
        graph.setdefault(b, set())
    index, low, stack, on, out, n = {}, {}, [], set(), [], [0]

    def visit(v):
        index[v] = low[v] = n[0]
        n[0] += 1
        stack.append(v)
        on.add(v)
        for w in graph[v]:
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            comp = set()
            while True:
                w = stack.pop()
                on.discard(w)
                comp.add(w)
                if w == v:
                    break
            if len(comp) > 1:
                out.append(comp)

    for v in list(graph):
        if v not in index:
            visit(v)
    return out


def test_every_import_goes_down_or_sideways_and_no_cycle():
    mods = _modules()
    edges = _imports(mods)
    upward = {(a, b) for a, b in edges if _layer(b) > _layer(a)}
    new_up = sorted(upward - DEBT)
    assert not new_up, "upward imports (a lower layer imports a higher one):\n" + "\n".join(
        f"  {a} → {b} (layer {_layer(a)} → {_layer(b)})" for a, b in new_up)
    cycles = _cycles(edges - DEBT)
    assert not cycles, "import cycles: " + "; ".join(" ⇄ ".join(sorted(c)) for c in cycles)
    gone = sorted(DEBT - edges)
    assert not gone, f"fixed, remove from DEBT: {gone}"


def test_no_module_grows_past_the_limit():
    mods = _modules()
    lines = {n: len(p.read_text().splitlines()) for n, p in mods.items()}
    over = {n: k for n, k in lines.items() if k > MAX_LINES}
    grown = sorted(f"{n}: {k} lines (limit {LONG.get(n, MAX_LINES)})" for n, k in over.items()
                   if k > LONG.get(n, MAX_LINES))
    assert not grown, "split these modules (one job each):\n" + "\n".join(grown)
    shrunk = sorted(n for n in LONG if lines.get(n, 0) <= MAX_LINES)
    assert not shrunk, f"now within {MAX_LINES} lines, remove from LONG: {shrunk}"


def test_the_walk_sees_function_level_and_relative_imports():
    """The checker itself: a function-level upward import and a two-level relative import
    are found (a walk that missed them would pass any code)."""
    mods = _modules()
    edges = _imports(mods)
    assert ("_problems._derived", "reference") in edges  # inside band_bracket
    assert ("_posterior.density", "_problems._evaluate") in edges  # `from .._evaluate`
    assert ("effects.stiffness", "effects._base") in edges
