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
    # errors, configuration, units, the version, small numerics with no hdid dependency
    {"_errors", "_config", "_units", "_compile_clock", "_covariance", "_version"},
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
    # posterior, diagnosis, and the design of experiments (information of a planned log)
    {"_posterior", "_diagnosis", "_design"},
    # the command line; the package's lazy public namespace
    {"cli", "__init__"},
]

#: Upward or cyclic imports still in the code: (importer, imported). Only shrinks.
DEBT: set[tuple[str, str]] = set()
MAX_LINES = 500
#: Modules still over ``MAX_LINES``: their size today is their ceiling. Only shrinks.
LONG: dict[str, int] = {}


def _modules(root: Path = ROOT) -> dict[str, Path]:
    """Every module under ``root`` by its dotted name relative to it; the package's own
    ``__init__.py`` is ``"__init__"``, a subpackage's is the subpackage's name."""
    mods = {}
    for p in root.rglob("*.py"):
        name = ".".join(p.relative_to(root).with_suffix("").parts)
        mods[name.removesuffix(".__init__") if name != "__init__" else "__init__"] = p
    return mods


def _layer(name: str) -> int:
    top = name.split(".")[0]
    for i, layer in enumerate(LAYERS):
        if top in layer:
            return i
    raise AssertionError(f"src/hdid/{name}: in no layer of tests/test_layers.py; add it")


def _targets(name: str, path: Path, node, mods) -> list[tuple[str, bool]]:
    """What one import statement of module ``name`` loads, as ``(module, explicit)``
    dotted relative to the package root (``""``: the package itself). ``explicit``: a
    name is read from that module's namespace (``from P import n`` where ``P.n`` is no
    module), not only its ``__init__`` run on the way to a submodule.

    Forms: ``from . import x``, ``from .. import x``, ``from ..pkg import x`` (any level),
    ``import hdid.x.y``, ``from hdid import x``, ``from hdid.x import y``."""
    if isinstance(node, ast.Import):
        out = []
        for a in node.names:
            parts = a.name.split(".")
            if parts[0] == "hdid":  # import hdid.a.b loads hdid, hdid.a and hdid.a.b
                out += [(".".join(parts[1:i]), False) for i in range(2, len(parts) + 1)]
                if a.asname is None:  # binds ``hdid``: the whole public namespace
                    out.append(("", True))
        return out
    if node.level:
        pkg = name.split(".") if path.name == "__init__.py" and name != "__init__" else name.split(".")[:-1]
        if node.level - 1 > len(pkg):
            return []  # above the package: not hdid's
        base = pkg[: len(pkg) - node.level + 1]
        parts = base + (node.module.split(".") if node.module else [])
    elif node.module and node.module.split(".")[0] == "hdid":
        parts = node.module.split(".")[1:]
    else:
        return []  # another package
    out = [(".".join(parts[:i]), False) for i in range(1, len(parts) + 1)]
    pkg_name = ".".join(parts)
    for a in node.names:
        sub = f"{pkg_name}.{a.name}" if pkg_name else a.name
        # a submodule, else a name read from the package's namespace
        out.append((sub, False) if sub in mods else (pkg_name, True))
    return out


def _imports(mods: dict[str, Path], root: Path = ROOT) -> dict[tuple[str, str], str]:
    """``(importer, imported)`` for every import in the modules, at any depth of the code
    (inside functions too), except under ``if TYPE_CHECKING:``, each with where it is
    (``file:line: statement``, the first one). A package's ``__init__`` that an importer
    lies inside of runs anyway and counts only when a name is read from it; the package
    root (``"__init__"``) the same."""
    edges: dict[tuple[str, str], str] = {}
    for name, path in mods.items():
        tree = ast.parse(path.read_text())
        skip = {id(n) for node in ast.walk(tree) if isinstance(node, ast.If)
                and "TYPE_CHECKING" in ast.unparse(node.test) for n in ast.walk(node)}
        for node in ast.walk(tree):
            if id(node) in skip or not isinstance(node, (ast.Import, ast.ImportFrom)):
                continue
            for t, explicit in _targets(name, path, node, mods):
                t = t or "__init__"
                inside = t == "__init__" or name.startswith(t + ".")
                if t in mods and t != name and (explicit or not inside):
                    edges.setdefault((name, t), f"{path.relative_to(root.parent)}:"
                                                f"{node.lineno}: {ast.unparse(node)}")
    return edges


def check(root: Path = ROOT) -> tuple[list[str], set[tuple[str, str]]]:
    """The layer rules on the tree at ``root``: the problems found (upward imports not in
    ``DEBT``, cycles, ``DEBT`` entries no longer needed) and the import edges."""
    mods = _modules(root)
    where = _imports(mods, root)
    edges = set(where)
    upward = {(a, b) for a, b in edges if _layer(b) > _layer(a)}
    problems = [f"upward import (a lower layer imports a higher one): {a} → {b} (layer "
                f"{_layer(a)} → {_layer(b)}) at {where[a, b]}" for a, b in sorted(upward - DEBT)]
    problems += ["import cycle: " + " ⇄ ".join(sorted(c)) + " (" + "; ".join(
        where[e] for e in sorted(edges - DEBT) if e[0] in c and e[1] in c) + ")"
        for c in _cycles(edges - DEBT)]
    problems += [f"fixed, remove from DEBT: {e}" for e in sorted(DEBT - edges)]
    return problems, edges


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
    problems, _ = check()
    assert not problems, "\n".join(problems)


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
    """The checker itself on the real tree: a function-level import and a two-level
    relative import are found (a walk that missed them would pass any code)."""
    _, edges = check()
    assert ("_problems._derived", "reference") in edges  # inside band_bracket
    assert ("_posterior.density", "_problems._evaluate") in edges  # `from .._evaluate`
    assert ("effects.stiffness", "effects._base") in edges


#: Upward imports planted in a fake tree, one per import form, each in a module of the
#: logs layer (``_log``) reaching up to the command line or the package root. The checker
#: must name every one (a checker that misses a form would pass any code written in it).
PLANTED = {
    "from_dot": ("_log/_a.py", "from . import _b\n", None),  # sideways: not a problem
    "from_dotdot": ("_log/_c.py", "from .. import __version__\n", ("_log._c", "__init__")),
    "from_dotdot_pkg": ("_log/_d.py", "from ..cli import main\n", ("_log._d", "cli")),
    "from_dotdot_pkg_mod": ("_log/_e.py", "from ..cli._main import x\n", ("_log._e", "cli._main")),
    "import_hdid_x": ("_log/_f.py", "import hdid.cli\n", ("_log._f", "cli")),
    "import_hdid_x_binds_root": ("_log/_g.py", "import hdid._errors\n", ("_log._g", "__init__")),
    "from_hdid": ("_log/_h.py", "from hdid import cli\n", ("_log._h", "cli")),
    "from_hdid_name": ("_log/_i.py", "from hdid import fit\n", ("_log._i", "__init__")),
    "from_hdid_x": ("_log/_j.py", "from hdid.cli._main import y\n", ("_log._j", "cli._main")),
    "in_function": ("_log/_k.py", "def f():\n    from ..cli import _main\n", ("_log._k", "cli._main")),
    "from_dot_in_subpackage_init": ("_log/__init__.py", "from .. import cli\n", ("_log", "cli")),
}


def _fake_tree(root: Path, extra: dict[str, str]) -> Path:
    pkg = root / "hdid"
    files = {"__init__.py": "", "_errors.py": "", "_log/_b.py": "from .._errors import E\n",
             "cli/__init__.py": "", "cli/_main.py": "from .._log import _b\n", **extra}
    for rel, text in files.items():
        (pkg / rel).parent.mkdir(parents=True, exist_ok=True)
        (pkg / rel).write_text(text)
    return pkg


def test_the_checker_fails_on_every_planted_upward_import(tmp_path):
    pkg = _fake_tree(tmp_path, {rel: text for rel, text, _ in PLANTED.values()})
    problems, edges = check(pkg)
    for form, (rel, text, edge) in PLANTED.items():
        if edge is None:
            assert not any(rel.removesuffix(".py").replace("/", ".") in p for p in problems), form
            continue
        assert edge in edges, f"{form}: {text!r} not seen"
        assert any(f"{edge[0]} → {edge[1]} " in p for p in problems), f"{form}: not flagged"
    # the clean part of the tree passes, and a planted cycle is found
    assert check(_fake_tree(tmp_path / "clean", {}))[0] == []
    cyc = _fake_tree(tmp_path / "cycle", {"_log/_a.py": "from . import _z\n",
                                           "_log/_z.py": "import hdid._log._a as a\n"})
    assert any(p.startswith("import cycle: _log._a ⇄ _log._z") for p in check(cyc)[0])


def test_type_checking_imports_do_not_count(tmp_path):
    pkg = _fake_tree(tmp_path, {"_log/_a.py": "from typing import TYPE_CHECKING\n"
                                "if TYPE_CHECKING:\n    from ..cli import _main\n"})
    assert check(pkg)[0] == []
