"""Compiled programs kept on disk under hdid's own key, so a later process skips tracing.

JAX's persistent compilation cache (:mod:`hdid._config`) saves the XLA compile, but its
key is the lowered program: every new process still traces and lowers each program
first — for the stick-exact simulator inside a Levenberg–Marquardt loop that is ~5–25 s
per model structure on a shared 2-core machine, most of a warm ``hdid diagnose``.
:func:`call` keys a program by what determines it — a name, the arguments' tree
structure (which holds every static field: model structure, free parameters, layout),
the shapes and dtypes of their arrays, the source of hdid and the versions of JAX and
its backend — and keeps the serialized executable (``jax.experimental.
serialize_executable``) under ``<cache>/programs``. A hit loads it without tracing. Any
failure (a backend that cannot serialize, a stale file, an executable XLA cannot restore
— seen on CPU for small programs: "Function wrapped_iota not found") falls back to
compiling in the process, and a program that failed to restore is never loaded again
(``<key>.bad``), so results never depend on the store.

Status (measured, jax 0.10.2, CPU): a program restored in a fresh process ran with the
same numbers (the base model's grid and Levenberg–Marquardt programs of a 250 Hz log:
0.3 s and 2.7 s instead of 18 s and 106 s of tracing and compiling), but some
executables do not restore ("Function multiply_sine_fusion not found" when several
programs with the same kernel names are loaded in one process). The fallback keeps the
results right, but the end-to-end gain on ``hdid diagnose`` is not yet measured, so the
store is off by default: ``HDID_PROGRAM_STORE=1`` turns it on. Without it :func:`call`
is a per-process cache of compiled programs on top of JAX's persistent cache.
"""

from __future__ import annotations

import hashlib
import os
import pickle
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

import equinox as eqx
import jax

from . import _config

#: Modules that only orchestrate (no function of theirs is traced into a stored program:
#: those come from ``_refit``, ``_residuals`` and the problem, model and effects they
#: call): editing them does not invalidate the store.
UNTRACED = frozenset({"_diagnose.py", "cli.py"})
_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")
_LOADED: dict[str, Any] = {}
_SALT: str | None = None


def _salt() -> str:
    """hdid's source, JAX's and the backend's versions: a change invalidates every key."""
    global _SALT
    if _SALT is None:
        h = hashlib.sha256()
        root = Path(__file__).resolve().parent
        for f in sorted(root.rglob("*.py")):
            if f.relative_to(root).as_posix() in UNTRACED:
                continue
            h.update(str(f.relative_to(root)).encode())
            h.update(f.read_bytes())
        try:
            import jaxlib

            h.update(jaxlib.__version__.encode())
        except ImportError:  # pragma: no cover
            pass
        h.update(jax.__version__.encode())
        dev = jax.devices()[0]
        h.update(f"{dev.platform}:{getattr(dev, 'device_kind', '')}".encode())
        h.update(str(jax.config.jax_enable_x64).encode())
        _SALT = h.hexdigest()
    return _SALT


def _store() -> Path | None:
    """The store's folder, or ``None``: off unless ``HDID_PROGRAM_STORE=1`` (see the
    module docstring: on jax 0.10's CPU backend some executables do not restore)."""
    if os.environ.get("HDID_NO_CACHE") or os.environ.get("HDID_PROGRAM_STORE") != "1":
        return None
    path = _config._cache_dir() / "programs"
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    return path


def _key(name: str, treedef, static, leaves) -> str:
    avals = tuple((tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False)))
                  for x in leaves)
    static_leaves = jax.tree_util.tree_leaves(static)
    text = "|".join([
        name, _ADDRESS.sub("", str(treedef)), _ADDRESS.sub("", repr(static_leaves)),
        repr(avals), _salt(),
    ])
    return hashlib.sha256(text.encode()).hexdigest()


def call(name: str, fn: Callable, *args):
    """``fn(*args)`` compiled once per key (arrays dynamic, everything else static) and
    loaded from the store in later processes."""
    dyn, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dyn)
    try:
        key = _key(name, treedef, static, leaves)
    except Exception:  # noqa: BLE001 - an unkeyable argument: the ordinary path
        return eqx.filter_jit(fn)(*args)
    prog = _LOADED.get(key)
    if prog is not None:
        return prog(*leaves)
    prog = _load(key)
    if prog is not None:
        try:
            # (errors of a restored executable surface when its results are read)
            out = jax.block_until_ready(prog(*leaves))
            _LOADED[key] = prog
            return out
        except Exception as exc:  # noqa: BLE001 - XLA could not restore it (seen on CPU:
            # "Function wrapped_iota not found"): never load it again, compile here
            del exc
            _mark_bad(key)
    prog = _compile(key, fn, treedef, static, leaves)
    _LOADED[key] = prog
    return prog(*leaves)


def _mark_bad(key: str) -> None:
    store = _store()
    if store is not None:
        try:
            (store / f"{key}.bad").touch()
        except OSError:
            pass


def _load(key: str):
    store = _store()
    if store is None:
        return None
    path = store / f"{key}.bin"
    if not path.exists() or (store / f"{key}.bad").exists():
        return None
    try:
        from jax.experimental import serialize_executable as se

        _ensure_backend_handlers()
        payload, in_tree, out_tree = pickle.loads(path.read_bytes())
        return se.deserialize_and_load(payload, in_tree, out_tree)
    except Exception:  # noqa: BLE001 - stale or unreadable: compile again
        return None


def _ensure_backend_handlers() -> None:
    """Register the CPU LAPACK kernels before loading an executable that calls them.

    JAX registers them lazily, when it first *lowers* a linear-algebra op; a program
    loaded without lowering would call an unregistered handler (a segfault, seen with
    jax 0.10). ``jax.export`` does the same before running a deserialized program.
    """
    from jax._src.lax import linalg

    linalg.initialize_lapack()


def _compile(key: str, fn: Callable, treedef, static, leaves):
    def flat(*xs):
        return fn(*eqx.combine(jax.tree_util.tree_unflatten(treedef, xs), static))

    store = _store()
    lowered = jax.jit(flat).lower(*leaves)
    if store is None or (store / f"{key}.bad").exists():
        return lowered.compile()
    # An executable read back from JAX's own persistent cache serializes without all of
    # its kernels (restoring it fails: "Function broadcast_add_fusion not found"), so
    # the program kept here is compiled afresh, once.
    was = jax.config.jax_enable_compilation_cache
    jax.config.update("jax_enable_compilation_cache", False)
    try:
        compiled = lowered.compile()
    finally:
        jax.config.update("jax_enable_compilation_cache", was)
    try:
        from jax.experimental import serialize_executable as se

        blob = pickle.dumps(se.serialize(compiled))
        tmp = store / f"{key}.{os.getpid()}.tmp"
        tmp.write_bytes(blob)
        os.replace(tmp, store / f"{key}.bin")
    except Exception:  # noqa: BLE001 - cannot serialize here: in-process only
        pass
    return compiled
