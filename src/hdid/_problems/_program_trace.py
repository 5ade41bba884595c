"""What a trace used, for the program store's dependency record
(:mod:`hdid._problems._program_deps`): the files of the code that built the traced
program (every equation's traceback, sub-programs included) and of the classes and
functions it was given."""

from __future__ import annotations

import dataclasses
import sys


def _jaxprs(params):
    from jax._src import core

    return core.jaxprs_in_params(params)


def generated(code) -> bool:
    """Whether ``code`` is a method :mod:`dataclasses` wrote (``__init__``, ``__eq__``,
    ...: no file; what it does follows from the class's fields, which the key holds)."""
    return code.co_filename == "<string>" and getattr(code, "co_qualname", "").startswith(
        "__create_fn__.<locals>.")


def traced_files(jaxpr, stop_codes=frozenset()) -> set[str] | None:
    """Files of every frame in the equations' tracebacks (sub-programs included), up to
    (not past) a frame whose code is in ``stop_codes`` (the store's own wrapper);
    ``None`` where an equation has no traceback (JAX told not to keep them: in doubt)."""
    files: set[str] = set()
    seen_jaxprs: set[int] = set()
    seen_codes: set[int] = set()
    todo = [jaxpr]
    while todo:
        jx = todo.pop()
        if id(jx) in seen_jaxprs:
            continue
        seen_jaxprs.add(id(jx))
        for eqn in jx.eqns:
            tb = eqn.source_info.traceback
            if tb is None:
                return None
            codes, _ = tb.raw_frames()
            for c in codes:  # innermost first
                if c in stop_codes:
                    break
                if generated(c):
                    continue
                if id(c) not in seen_codes:
                    seen_codes.add(id(c))
                    files.add(c.co_filename)
            todo.extend(_jaxprs(eqn.params))
    return files


def object_files(objs) -> set[str]:
    """Files defining the classes (and bases) of every object reachable in ``objs``
    (containers, dataclasses and equinox modules walked), and of functions' code."""
    files: set[str] = set()
    types: set[type] = set()
    seen: set[int] = set()
    todo = [(o, 0) for o in objs]
    while todo:
        o, depth = todo.pop()
        if id(o) in seen or depth > 64:
            continue
        seen.add(id(o))
        types.add(type(o))
        code = getattr(o, "__code__", None)
        if code is not None and hasattr(code, "co_filename"):
            files.add(code.co_filename)
            for cell in getattr(o, "__closure__", None) or ():
                try:
                    todo.append((cell.cell_contents, depth + 1))
                except ValueError:  # empty cell
                    pass
        if isinstance(o, (list, tuple, set, frozenset)):
            todo.extend((x, depth + 1) for x in o)
        elif isinstance(o, dict):
            todo.extend((x, depth + 1) for x in o.values())
        elif dataclasses.is_dataclass(o) and not isinstance(o, type):
            for f in dataclasses.fields(o):
                todo.append((getattr(o, f.name, None), depth + 1))
        elif isinstance(o, type):
            types.add(o)
        for attr in ("func", "__wrapped__"):  # functools.partial, eqx.Partial, wrappers
            inner = getattr(o, attr, None) if not isinstance(o, type) else None
            if callable(inner):
                todo.append((inner, depth + 1))
    for t in types:
        for k in getattr(t, "__mro__", (t,)):
            mod = sys.modules.get(getattr(k, "__module__", None) or "")
            f = getattr(mod, "__file__", None)
            if f:
                files.add(f)
            else:  # a module not registered (a file executed by path): its methods' file
                for v in vars(k).values():
                    code = getattr(getattr(v, "__func__", v), "__code__", None)
                    if code is not None and hasattr(code, "co_filename") and not generated(code):
                        files.add(code.co_filename)
    return files
