"""What a stored program depends on: the source that ran while it was traced (issue 37).

A program in the store (:mod:`hdid._problems._programs`) is a function of the arguments'
tree, static fields, shapes and dtypes (its key), of the library versions, and of the
Python code that ran while it was traced. Keying it on all of hdid's source made every
commit touching src/hdid cold-start the store (CI compiled ~540 of 569 programs); here
a program records only what its trace used, and a later process reuses it while all of
that is unchanged:

- **files**: every Python file with a frame in the traceback of any equation of the
  traced program, sub-programs included (loop bodies, branches, inner jits: JAX keeps a
  traceback per equation, and an inner program reused from JAX's tracing cache keeps the
  one of its first trace, so code not re-run in this trace is still seen); the files
  defining the classes (with their bases) of every object in the arguments and of the
  traced function; and the files those files import directly (relative and ``hdid``
  imports; a name re-exported by a package resolved to the module defining it). Each by
  the SHA-256 of its bytes; hdid's files by their path inside the package, so that a
  fresh clone elsewhere reuses them.
- **values**: each of those modules' constants (numbers, strings, tuples, arrays,
  classes' plain attributes; not a process's state: :mod:`._program_values`), hashed,
  so a constant computed at import from a module not listed still counts.
- **dists**: the version of any other installed package whose code appears.

Where in doubt — code from a file that cannot be read (``<string>``, a notebook cell not
on disk), or a file modified after this process started (the code that ran may not be
the file's) — :func:`record` returns ``None`` and the program is not stored; and a
stored program is used only when every recorded hash equals the current one
(:func:`matches`; :func:`mismatch` says which differs, :data:`MISSES` keeps the latest).
A changed numerics file therefore always misses; an edit to a module no trace touched
(the command line, the posterior, diagnose's driver) leaves every program warm.
"""

from __future__ import annotations

import ast
import hashlib
import logging
import os
import sys
import sysconfig
import threading
import time
from collections import deque
from pathlib import Path

from . import _program_values

#: hdid's package folder; its files are recorded by their path inside it (``hdid:...``).
HDID_ROOT = Path(__file__).resolve().parents[1]
_HDID = "hdid:"
#: The store's own modules: their one traced function (the wrapper that rebuilds the
#: arguments) is where tracebacks stop (``_program_trace.traced_files``), so they are not
#: followed as imports either; a change to that wrapper must change ``FORMAT``.
STORE_MODULES = frozenset(f"{_HDID}_problems/{m}.py" for m in (
    "_programs", "_program_keys", "_program_deps", "_program_files", "_program_trace",
    "_program_values"))


def _process_start() -> float:
    """When this process started (Linux: ``/proc``, to ~10 ms; a margin of 0.1 s taken
    off, so that a file written just before is in doubt), else when this module was
    imported."""
    now = time.time()
    try:
        ticks = int(Path("/proc/self/stat").read_text().rsplit(")", 1)[1].split()[19])
        uptime = float(Path("/proc/uptime").read_text().split()[0])
        return min(now - (uptime - ticks / os.sysconf("SC_CLK_TCK")) - 0.1, now)
    except (OSError, ValueError, IndexError, AttributeError):
        return now


#: Files modified after this moment may not hold the code this process runs: in doubt.
T0 = _process_start()

_INSTALLED = tuple({str(Path(p).resolve()) + os.sep for k in ("purelib", "platlib", "stdlib",
                                                                "platstdlib")
                    if (p := sysconfig.get_paths().get(k))} | {
    str(Path(p).resolve()) + os.sep for p in sys.path
    if p and ("site-packages" in p or "dist-packages" in p)})
_lock = threading.RLock()
_FILE_HASH: dict[str, tuple[tuple, str | None]] = {}
_EDGES: dict[str, tuple[tuple, tuple[str, ...]]] = {}
_MODULE_OF: dict[str, str] = {}
_DIST_OF: dict[str, str] = {}
_TREES: dict[str, tuple[tuple, ast.Module | None]] = {}


def forget() -> None:
    """Drop every cached hash, import list and module value (as a new process starts)."""
    with _lock:
        for cache in (_FILE_HASH, _EDGES, _MODULE_OF, _DIST_OF, _TREES):
            cache.clear()
    _program_values.forget()


#: Files that hdid itself executed after this process started (a user's effect file), by
#: path: a time taken before the file was read. Modified after it: in doubt.
LOADED: dict[str, float] = {}


def loaded(path, before: float) -> None:
    """Note that the file at ``path`` was read and executed after ``before`` (a
    ``time.time()`` taken before reading it): its code is the file's while the file is
    not modified after that."""
    LOADED[str(Path(path).resolve())] = before


#: Why the last :func:`record` was in doubt (for :data:`hdid._problems._programs.UNSTORED`).
LAST_DOUBT = ""


class Doubt(Exception):
    """Something the trace used cannot be pinned down: the program is not stored."""


def _installed(path: str) -> bool:
    """Whether ``path`` is an installed package's (or the standard library's) file, which
    the packages' versions stand for; hdid's own files never are (an install of another
    build under the same version must not reuse programs)."""
    if not (path.startswith(("<frozen ", *_INSTALLED)) or f"{os.sep}site-packages{os.sep}" in path
            or f"{os.sep}dist-packages{os.sep}" in path):
        return False
    return (path.startswith("<frozen ") or "hdid" not in path
            or not _name(path).startswith(_HDID))


def _name(path: str) -> str:
    """The recorded name of a file: ``hdid:<path in the package>`` or its absolute path."""
    try:
        return _HDID + Path(path).resolve().relative_to(HDID_ROOT).as_posix()
    except ValueError:
        return str(Path(path).resolve())


def _path(name: str) -> Path:
    return HDID_ROOT / name[len(_HDID):] if name.startswith(_HDID) else Path(name)


def file_hash(name: str) -> str | None:
    """SHA-256 of a recorded file's bytes, or ``None`` (unreadable, or modified after this
    process started). Cached by the file's size and modification time."""
    path = _path(name)
    try:
        st = path.stat()
    except OSError:
        return None
    if st.st_mtime > max(T0, LOADED.get(str(path), T0)):
        return None
    stamp = (st.st_size, st.st_mtime_ns, st.st_ino)
    with _lock:
        got = _FILE_HASH.get(name)
        if got is not None and got[0] == stamp:
            return got[1]
    try:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
    except OSError:
        digest = None
    with _lock:
        _FILE_HASH[name] = (stamp, digest)
    return digest


def _module_of(path: str) -> str | None:
    """The imported module whose file is ``path`` (``None``: none, e.g. ``exec``'d code)."""
    with _lock:
        got = _MODULE_OF.get(path)
        if got is not None and _file_is(got, path):
            return got
        _MODULE_OF.pop(path, None)  # (a module since removed or imported from elsewhere)
        for mod_name, mod in list(sys.modules.items()):
            f = getattr(mod, "__file__", None)
            if f and not _installed(f):
                _MODULE_OF.setdefault(str(Path(f).resolve()), mod_name)
        got = _MODULE_OF.get(path)
        return got if got is not None and _file_is(got, path) else None


def _file_is(mod_name: str, path: str) -> bool:
    """Whether the imported module ``mod_name`` is the file at ``path`` (resolved)."""
    f = getattr(sys.modules.get(mod_name), "__file__", None)
    return bool(f) and (f == path or str(Path(f).resolve()) == path)


def _module_file(mod_name: str) -> str | None:
    mod = sys.modules.get(mod_name)
    f = getattr(mod, "__file__", None) if mod is not None else None
    if f is None and mod_name.split(".")[0] == "hdid":
        parts = mod_name.split(".")[1:]
        for cand in (HDID_ROOT.joinpath(*parts).with_suffix(".py"),
                     HDID_ROOT.joinpath(*parts, "__init__.py")):
            if parts and cand.is_file():
                return str(cand)
    return os.path.abspath(f) if f else None


def _tree(path: str) -> ast.Module | None:
    """The module's syntax tree (cached by size and modification time), or ``None``."""
    try:
        st = os.stat(path)
        stamp = (st.st_size, st.st_mtime_ns)
    except OSError:
        return None
    with _lock:
        got = _TREES.get(path)
    if got is not None and got[0] == stamp:
        return got[1]
    try:
        tree = ast.parse(Path(path).read_bytes())
    except (OSError, SyntaxError, ValueError):
        tree = None
    with _lock:
        _TREES[path] = (stamp, tree)
    return tree


def _statements(tree):
    """Every statement of a module, nested ones included (imports and ``global`` are
    statements: expressions need not be walked)."""
    todo = list(tree.body) if tree is not None else []
    while todo:
        node = todo.pop()
        yield node
        for field in ("body", "orelse", "finalbody", "handlers", "cases"):
            sub = getattr(node, field, None)
            if isinstance(sub, list):
                todo.extend(x for x in sub if isinstance(x, (ast.stmt, ast.excepthandler,
                                                             ast.match_case)))


def _reexport(pkg: str, name: str) -> str | None:
    """The module defining ``name`` where package ``pkg``'s ``__init__`` imports it from a
    submodule (``from .sub import name``), else ``None``."""
    init = _module_file(pkg)
    if init is None or not init.endswith("__init__.py"):
        return None
    tree = _tree(init)
    for node in tree.body if tree is not None else ():
        if isinstance(node, ast.ImportFrom) and node.level == 1 and node.module:
            if any((a.asname or a.name) == name for a in node.names):
                return f"{pkg}.{node.module}"
    return None


def _imports(path: str, mod_name: str) -> tuple[str, ...]:
    """Files that the module at ``path`` imports directly, relative or from hdid (names
    re-exported by a package resolved to their module)."""
    try:
        st = os.stat(path)
        stamp = (st.st_size, st.st_mtime_ns)
    except OSError:
        return ()
    with _lock:
        got = _EDGES.get(path)
        if got is not None and got[0] == stamp:
            return got[1]
    tree = _tree(path)
    pkg = mod_name if path.endswith("__init__.py") else mod_name.rpartition(".")[0]
    targets: set[str] = set()
    for node in _statements(tree):
        if isinstance(node, ast.Import):
            targets.update(a.name for a in node.names if a.name.split(".")[0] == "hdid")
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = pkg.split(".")
                if node.level - 1 >= len(base):
                    continue
                base = base[:len(base) - (node.level - 1)]
                mod = ".".join(base + ([node.module] if node.module else []))
            elif node.module and node.module.split(".")[0] == "hdid":
                mod = node.module
            else:
                continue
            for a in node.names:
                sub = f"{mod}.{a.name}"
                if _module_file(sub) is not None:
                    targets.add(sub)
                else:
                    targets.add(_reexport(mod, a.name) or mod)
    files = tuple(sorted({f for t in targets if (f := _module_file(t)) is not None
                          and not _installed(f)}))
    with _lock:
        _EDGES[path] = (stamp, files)
    return files


#: Packages whose versions are in every key already (``_programs.VERSIONED``).
KEYED = frozenset({"jax", "jaxlib", "equinox", "optimistix", "lineax", "jaxtyping", "numpy",
                   "scipy"})


def _dist(path: str) -> str | None:
    """``name==version`` of the installed distribution holding ``path`` (``None``: the
    standard library, or a package already in every key)."""
    if path.startswith("<frozen ") or not ("site-packages" in path or "dist-packages" in path):
        return None
    parts = Path(path).parts
    marker = "site-packages" if "site-packages" in parts else "dist-packages"
    i = parts.index(marker) if marker in parts else len(parts)
    if i + 1 >= len(parts):
        return None
    top = parts[i + 1].removesuffix(".py")
    if top in KEYED or top.endswith((".dist-info", ".egg-info")):
        return None
    with _lock:
        if top in _DIST_OF:
            return _DIST_OF[top]
    from importlib import metadata

    try:
        text = f"{top}=={metadata.version(top)}"
    except metadata.PackageNotFoundError:
        try:
            ds = metadata.packages_distributions().get(top, [])
            text = ",".join(sorted(f"{d}=={metadata.version(d)}" for d in ds)) or top
        except Exception:  # noqa: BLE001
            text = top
    with _lock:
        _DIST_OF[top] = text
    return text


def record(files: set[str] | None) -> dict | None:
    """The dependency record of a trace that used ``files``
    (:mod:`hdid._problems._program_trace`): ``{"files": {name: sha256}, "values":
    {module: sha256}, "dists": [...]}``, or ``None`` where something is in doubt (not
    stored)."""
    global LAST_DOUBT
    if files is None:
        LAST_DOUBT = "an equation without a traceback"
        return None
    try:
        return _record(files)
    except Doubt as e:
        LAST_DOUBT = str(e)
        return None


def _record(files: set[str]) -> dict:
    own: dict[str, str | None] = {}  # resolved path -> module name (or None)
    dists: set[str] = set()
    for f in files:
        if _installed(f):
            if (d := _dist(f)) is not None:
                dists.add(d)
            continue
        if f.startswith("<"):
            raise Doubt(f)
        p = str(Path(f).resolve())
        own[p] = _module_of(p)
    for p, mod_name in list(own.items()):
        if mod_name is not None:
            for q in _imports(p, mod_name):
                if _name(q) not in STORE_MODULES:
                    own.setdefault(q, _module_of(q))
    out_files, out_values = {}, {}
    for p, mod_name in own.items():
        name = _name(p)
        digest = file_hash(name)
        if digest is None:
            raise Doubt(p)
        out_files[name] = digest
        if mod_name is not None:
            v = _program_values.values(mod_name, p)
            if v is None:
                raise Doubt(mod_name)
            out_values[mod_name] = v
    out = {"files": dict(sorted(out_files.items())), "values": dict(sorted(out_values.items())),
           "dists": sorted(dists)}
    if DEBUG:
        out["value_lines"] = {m: list(_program_values.lines(m)) for m in out_values}
    return out


def matches(rec: dict, given=None) -> bool:
    """Whether everything ``rec`` (:func:`record`) recorded is unchanged in this process
    (:func:`mismatch` finds nothing)."""
    return mismatch(rec, given) is None


def mismatch(rec: dict, given=None) -> str | None:
    """Why ``rec`` (:func:`record`) does not hold in this process — the first recorded
    file, module's constants or package version that differs, old and new — or ``None``.
    A file outside hdid must also be the one this process's code comes from: a loaded
    module's, one hdid read (:func:`loaded`), or one defining what the call is given
    (``given()``: :func:`hdid._problems._program_trace.object_files` of the function and
    its arguments), or a copy of it byte for byte — a recorded file left where it was
    does not stand for another file of the same classes elsewhere."""
    try:
        current = None
        for name, digest in rec["files"].items():
            now = file_hash(name)
            if now != digest:
                return (f"file {name}: recorded {digest[:12]}, now "
                        f"{now[:12] if now else 'unreadable or modified after the start'}")
            if not name.startswith(_HDID) and name not in LOADED and _module_of(name) is None:
                if current is None:
                    current = {str(Path(f).resolve()) for f in (given() if given else ())}
                if name not in current and not any(  # (or a copy with the same bytes)
                        not f.startswith(_HDID) and file_hash(f) == digest for f in current):
                    return f"file {name}: not where this process's code comes from"
        for mod_name, digest in rec["values"].items():
            path = _module_file(mod_name)
            now = _program_values.values(mod_name, path) if path is not None else None
            if now != digest:
                return (f"constants of {mod_name}: recorded {digest[:12]}, now "
                        f"{now[:12] if now else 'not importable'} "
                        f"{_diff(rec.get('value_lines', {}).get(mod_name), mod_name)}").rstrip()
        for d in rec.get("dists", ()):
            if not _dist_current(d, d.split("==")[0]):
                return f"package {d}: not installed at that version"
    except (KeyError, TypeError, AttributeError) as e:
        return f"unreadable record ({type(e).__name__}: {e})"
    return None


#: Set (``HDID_PROGRAM_DEBUG=1``) to keep each module's hashed constants in the records
#: stored (``value_lines``), so that a miss names the constants that differ, and to print
#: every miss's reason to stderr; misses are logged (``hdid.programs``, DEBUG) anyway.
DEBUG = os.environ.get("HDID_PROGRAM_DEBUG", "") not in ("", "0")
#: ``(stored version, reason)`` of the latest misses of a stored program in this process.
MISSES: deque = deque(maxlen=64)
_log = logging.getLogger("hdid.programs")


def missed(stem: str, reason: str) -> None:
    """Note that the stored version ``stem`` was not used, and why (:func:`mismatch`)."""
    MISSES.append((stem, reason))
    _log.debug("program %s not used: %s", stem, reason)
    if DEBUG:
        print(f"hdid: stored program {stem} not used: {reason}", file=sys.stderr)


def _diff(old, mod_name: str) -> str:
    """The constants' lines that differ (where the record kept them: :data:`DEBUG`)."""
    if not old:
        return ""
    new = set(_program_values.lines(mod_name))
    gone = sorted(set(old) - new)[:4]
    added = sorted(new - set(old))[:4]
    return "(" + "; ".join([f"-{x.strip()}" for x in gone] + [f"+{x.strip()}" for x in added]) + ")"


def _dist_current(text: str, top: str) -> bool:
    """Whether a recorded ``name==version`` (or bare top-level name) is installed now."""
    from importlib import metadata

    for part in text.split(","):
        name, _, version = part.partition("==")
        if not version:
            continue
        try:
            if metadata.version(name) != version:
                return False
        except metadata.PackageNotFoundError:
            return False
    return True
