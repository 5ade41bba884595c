"""The constants of a module that a stored program's record hashes
(:mod:`hdid._problems._program_deps`, ``"values"``): numbers, strings, tuples, arrays and
classes' plain attributes, so that a constant computed at import from a module not
listed still counts.

What is *not* a constant, because it depends on what the process did rather than on the
source: a name some function of the module rebinds (``global``), and a name a function
writes through ``globals()`` that the module's source does not bind at module level —
``hdid.__getattr__`` keeps each public name it imports lazily (``hdid.Model``, a class:
a plain value), so a process that had used ``hdid.Model`` hashed ``hdid`` differently
from a fresh one and every later process missed what it stored.

A module's hash is cached with the very objects it hashed (a module-level array also by
its bytes): a name rebound since (a test's monkeypatch, a reload) is seen and hashed
again, so no record carries a hash of an earlier state of the module.
"""

from __future__ import annotations

import ast
import dataclasses
import enum
import hashlib
import importlib
import re
import sys
import threading
from pathlib import Path

import numpy as np

_lock = threading.RLock()
#: Per file: names functions rebind with ``global``, and the module-level names its
#: source binds (``None``: every name, as no function writes ``globals()``).
_STATE: dict[str, tuple[tuple, frozenset, frozenset | None]] = {}
#: Per module name: (the objects hashed, the hash).
_VALUES: dict[str, tuple[tuple, str]] = {}
#: Why-miss support (``HDID_PROGRAM_DEBUG=1``): the hashed lines of each module.
_LINES: dict[str, tuple[str, ...]] = {}


def forget() -> None:
    with _lock:
        _STATE.clear()
        _VALUES.clear()
        _LINES.clear()


_GLOBAL = re.compile(r"^[ \t]+global[ \t]+([\w \t,]+)", re.M)


def _targets(node, out: set) -> None:
    if isinstance(node, ast.Name):
        out.add(node.id)
    elif isinstance(node, (ast.Tuple, ast.List)):
        for x in node.elts:
            _targets(x, out)
    elif isinstance(node, ast.Starred):
        _targets(node.value, out)


def _bound(tree: ast.Module) -> frozenset | None:
    """Names the module's own statements bind at module level (not inside functions or
    classes), or ``None`` where that cannot be told (``from m import *``)."""
    names: set[str] = set()
    todo = list(tree.body)
    while todo:
        node = todo.pop()
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
            names.add(node.name)
            continue
        if isinstance(node, (ast.Import, ast.ImportFrom)):
            for a in node.names:
                if a.name == "*":
                    return None
                names.add(a.asname or a.name.split(".")[0])
        elif isinstance(node, ast.Assign):
            for t in node.targets:
                _targets(t, names)
        elif isinstance(node, (ast.AnnAssign, ast.AugAssign)):
            _targets(node.target, names)
        elif isinstance(node, (ast.For, ast.AsyncFor)):
            _targets(node.target, names)
        elif isinstance(node, (ast.With, ast.AsyncWith)):
            for item in node.items:
                if item.optional_vars is not None:
                    _targets(item.optional_vars, names)
        elif isinstance(node, ast.ExceptHandler) and node.name:
            names.add(node.name)
        for field in ("body", "orelse", "finalbody", "handlers", "cases"):
            sub = getattr(node, field, None)
            if isinstance(sub, list) and not (field == "body" and _type_checking(node)):
                todo.extend(x for x in sub if isinstance(x, (ast.stmt, ast.excepthandler,
                                                             ast.match_case)))
        for sub in ast.iter_child_nodes(node):  # (a walrus at module level)
            if isinstance(sub, ast.expr):
                for w in ast.walk(sub):
                    if isinstance(w, ast.NamedExpr):
                        _targets(w.target, names)
    return frozenset(names)


def _type_checking(node) -> bool:
    """``if TYPE_CHECKING:`` (a body that never runs)."""
    test = getattr(node, "test", None) if isinstance(node, ast.If) else None
    return (isinstance(test, ast.Name) and test.id == "TYPE_CHECKING") or (
        isinstance(test, ast.Attribute) and test.attr == "TYPE_CHECKING")


def _writes_globals(tree: ast.Module) -> bool:
    """Whether a function of the module calls ``globals()`` (and may add names)."""
    for node in ast.walk(tree):
        if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef, ast.Lambda)):
            for w in ast.walk(node):
                if (isinstance(w, ast.Call) and isinstance(w.func, ast.Name)
                        and w.func.id == "globals"):
                    return True
    return False


def _state(path: str) -> tuple[frozenset, frozenset | None]:
    """``(rebound, bound)``: names functions rebind with ``global`` (state, not
    constants), and — where a function writes ``globals()`` — the names the source binds
    at module level (any other name is state); ``bound`` ``None``: hash every name."""
    try:
        p = Path(path)
        st = p.stat()
        stamp = (st.st_size, st.st_mtime_ns)
    except OSError:
        return frozenset(), None
    with _lock:
        got = _STATE.get(path)
    if got is not None and got[0] == stamp:
        return got[1], got[2]
    try:
        data = p.read_bytes()
    except OSError:
        data = b""
    text = data.decode(errors="replace")
    rebound = frozenset(n.strip() for names in _GLOBAL.findall(text) for n in names.split(","))
    bound = None
    if "globals" in text:
        try:
            tree = ast.parse(data)
        except (SyntaxError, ValueError):
            tree = None
        if tree is not None and _writes_globals(tree):
            bound = _bound(tree)
    with _lock:
        _STATE[path] = (stamp, rebound, bound)
    return rebound, bound


def plain(v, depth: int = 0):
    """A process-independent text of an immutable plain value, or ``None`` (skipped)."""
    if depth > 4:
        return None
    if v is None or isinstance(v, (bool, int, str, bytes)):
        return repr(v)
    if isinstance(v, float):
        return v.hex()
    if isinstance(v, complex):
        return f"{v.real.hex()},{v.imag.hex()}"
    if isinstance(v, enum.Enum):
        return f"{type(v).__qualname__}.{v.name}"
    if isinstance(v, np.ndarray):
        if v.dtype.hasobject:
            return None
        return f"{v.dtype}{v.shape}{hashlib.sha256(np.ascontiguousarray(v).tobytes()).hexdigest()}"
    if isinstance(v, np.generic):
        return f"{v.dtype}:{v!r}"
    if isinstance(v, type):
        return f"{v.__module__}.{v.__qualname__}"
    if dataclasses.is_dataclass(v) and not isinstance(v, type) and getattr(
            getattr(v, "__dataclass_params__", None), "frozen", False):  # (equinox modules)
        items = [f"{f.name}={plain(getattr(v, f.name, None), depth + 1) or '?'}"
                 for f in dataclasses.fields(v)]
        return f"{type(v).__module__}.{type(v).__qualname__}({','.join(items)})"
    if type(v).__module__.startswith("jax") and hasattr(v, "shape") and hasattr(v, "dtype"):
        try:
            return plain(np.asarray(v), depth)
        except Exception:  # noqa: BLE001 - not concrete
            return None
    if isinstance(v, (tuple, frozenset)):
        items = [plain(x, depth + 1) for x in v]
        items = ["?" if x is None else x for x in items]
        items = sorted(items) if isinstance(v, frozenset) else items
        return f"{type(v).__name__}({','.join(items)})"
    return None


def _items(mod, mod_name: str, skip: frozenset, bound: frozenset | None) -> tuple:
    """``(label, object)`` of what the hash covers, in order (classes' attributes after
    the class); the objects themselves, so that a rebinding is seen."""
    out = []
    for k, v in sorted(vars(mod).items()):
        if k.startswith("__") or k in skip or (bound is not None and k not in bound):
            continue
        if isinstance(v, type) and v.__module__ == mod_name:
            out.extend((f"{k}.{ck}", cv) for ck, cv in sorted(vars(v).items())
                       if not ck.startswith("__"))
        else:
            out.append((k, v))
    return tuple(out)


def _same(a: tuple, b: tuple) -> bool:
    """The same objects (and arrays with the same bytes: they may be written in place)."""
    return len(a) == len(b) and all(
        ka == kb and va is vb and not isinstance(va, np.ndarray) for (ka, va), (kb, vb) in zip(a, b))


def values(mod_name: str, path: str) -> str | None:
    """Hash of the module's constants and its classes' plain attributes (:func:`plain`),
    ``None`` where the module is not imported and cannot be."""
    mod = sys.modules.get(mod_name)
    if mod is None and mod_name.split(".")[0] == "hdid":
        try:
            mod = importlib.import_module(mod_name)
        except Exception:  # noqa: BLE001 - in doubt
            mod = None
    if mod is None:
        return None
    skip, bound = _state(path)
    items = _items(mod, mod_name, skip, bound)
    with _lock:
        got = _VALUES.get(mod_name)
    if got is not None and _same(got[0], items):
        return got[1]
    lines = tuple(f"{k}={t}\n" for k, v in items if (t := plain(v)) is not None)
    digest = hashlib.sha256("".join(lines).encode()).hexdigest()
    with _lock:
        _VALUES[mod_name] = (items, digest)
        _LINES[mod_name] = lines
    return digest


def lines(mod_name: str) -> tuple[str, ...]:
    """The hashed lines of the module's last :func:`values` (for a miss's reason)."""
    with _lock:
        return _LINES.get(mod_name, ())
