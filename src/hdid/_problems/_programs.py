"""Programs kept on disk under hdid's own key, so that a later process skips tracing.

JAX's persistent compilation cache (:mod:`hdid._config`) saves the XLA compile, but its
key is the lowered program: every new process still traces and lowers each program
first — for the stick-exact simulator inside a Levenberg–Marquardt loop that is ~5–25 s
per model structure on a shared 2-core machine, most of a warm ``hdid diagnose``.
:func:`call` keys a program by what determines it — a name, the arguments' tree
structure (which holds every static field: model structure, free parameters, layout),
the shapes and dtypes of their arrays, float64, and the versions of JAX, its backend and
the libraries traced (:func:`_salt`) — and keeps the traced and lowered program (a
:mod:`jax.export` ``Exported``: StableHLO plus its calling convention) under
``<cache>/programs`` with a record of the source its trace ran
(:mod:`hdid._problems._program_deps`: the files, their constants, other packages'
versions). A later process uses it only where all of that is unchanged, so an edit to
code no trace ran leaves the store warm and an edit to code a trace ran misses. A later
process reads it instead of tracing: it only wraps the StableHLO in a call, and the XLA
compile of that call is read from JAX's persistent cache, so what runs is compiled by
JAX's ordinary path. (An earlier version kept serialized *executables*; some of them did
not restore on jax 0.10's CPU backend — "Function multiply_sine_fusion not found" — so
it was off by default.)

Any failure (a program that cannot be exported, a stale or unreadable file, a call that
fails) falls back to compiling in the process, and a program that failed is never loaded
again (``<key>.bad``), so results never depend on the store. The store is on unless
``HDID_NO_CACHE=1`` or ``HDID_PROGRAM_STORE=0``.

:data:`STATS` records, per call that had to prepare a program, where the time went
(read from the store or traced and lowered; compiled or read from JAX's cache), for
``benchmarks/diagnose_speed.py``.

:func:`prefetch` starts reading a stored program in a background thread (``hdid-programs``)
before it is called — the XLA compile's cache read releases the GIL and takes 0.2–2.7 s
per program, so ``hdid diagnose`` reads its candidates' programs on the second core while
the base model is fitted on the first. :func:`call` then waits for it (only the wait
counts as the caller's compile time) or, where the read failed, prepares it as before.
``HDID_PREFETCH=0`` turns it off.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import pickle
import re
import time
from collections import OrderedDict
from collections.abc import Callable
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path
from typing import Any

import equinox as eqx
import jax

from .. import _compile_clock
from . import _program_deps, _program_keys, _program_trace
from ._program_files import (FORMAT, MAX_VERSIONS, STALE_DAYS, VERSIONED,  # noqa: F401
                             _add_version, _find, _load, _mark_bad, _prune, _salt, _store,
                             _versions)

_ADDRESS = re.compile(r" at 0x[0-9a-fA-F]+")
#: Compiled programs of this process, most recently used last. Bounded: every XLA:CPU
#: executable holds memory mappings for its code (see tests/conftest.py).
_LOADED: OrderedDict[str, Any] = OrderedDict()
MAX_LOADED = 64
#: ... and bounded by what they cost: a model's programs hold ~1 400–2 700 memory
#: mappings (``/proc/self/maps``), so 64 of them can exceed the kernel's limit
#: (``vm.max_map_count``, 65 530 by default), and JAX's own caches keep executables of
#: their own besides. When the process holds more than this fraction of the limit after a
#: new program, every compiled program is dropped — this store's and JAX's caches
#: (:func:`release`) — and later calls read them again from the store. (A process that
#: diagnosed ~40 logs died of "LLVM compilation error: Cannot allocate memory".)
MAX_MAPS_FRACTION = 0.5
#: Times :func:`release` ran in this process (for tests and benchmarks).
RELEASES = 0
#: Programs being read in the background (:func:`prefetch`), by key.
_PENDING: dict[str, Future] = {}
_POOL: ThreadPoolExecutor | None = None
#: Background threads reading programs: one (the caller's thread runs on the other core of
#: a 2-core machine; more readers would compete with it).
PREFETCH_WORKERS = 1
#: Name prefix of those threads (:mod:`hdid._compile_clock` tells their compile events apart).
PREFETCH_THREAD = _compile_clock.BACKGROUND_THREAD
#: One dict per program prepared in this process: name, how (``stored``: read from the
#: store; ``traced``: traced and lowered here; ``jit``: store off), and seconds spent
#: reading/tracing (``prepare_s``), wrapping the program in a call and lowering it
#: (``wrap_s``) and compiling or reading JAX's cache (``compile_s``),
#: and the wall-clock ``span`` (``time.time()``, as JAX's compile events) of both.
STATS: list[dict[str, Any]] = []


def _key(name: str, treedef, static, leaves) -> str:
    avals = tuple((tuple(x.shape), str(x.dtype), bool(getattr(x, "weak_type", False)))
                  for x in leaves)
    static_leaves = jax.tree_util.tree_leaves(static)
    text = "|".join([
        name, _ADDRESS.sub("", str(treedef)), _ADDRESS.sub("", repr(static_leaves)),
        repr(avals), f"x64={bool(jax.config.jax_enable_x64)}", _salt(),
    ])
    return hashlib.sha256(text.encode()).hexdigest()


def call(name: str, fn: Callable, *args):
    """``fn(*args)`` compiled once per key (arrays dynamic, everything else static) and
    read from the store in later processes."""
    memo, leaves = _program_keys.memo_key(name, args)
    key = _program_keys.lookup(memo)
    if key is not None:
        prog = _LOADED.get(key)
        if prog is not None:
            _LOADED.move_to_end(key)
            return prog(*leaves)
    dyn, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dyn)
    if key is None:
        try:
            key = _key(name, treedef, static, leaves)
        except Exception:  # noqa: BLE001 - an unkeyable argument: the ordinary path
            return eqx.filter_jit(fn)(*args)
        _program_keys.remember(memo, key)
    prog = _LOADED.get(key)
    if prog is not None:
        _LOADED.move_to_end(key)
        return prog(*leaves)
    got = _prefetched(key, leaves)
    if got is not None:
        prog, out = got
    else:
        prog, out = _prepare(name, key, fn, treedef, static, leaves)
    _LOADED[key] = prog
    while len(_LOADED) > MAX_LOADED:
        _LOADED.popitem(last=False)
    if _maps_over_limit():
        release()
    return out


def _maps() -> int | None:
    """Memory mappings of this process (Linux), or ``None`` where it cannot tell."""
    try:
        with open("/proc/self/maps", "rb") as f:
            return sum(1 for _ in f)
    except OSError:
        return None


def _max_maps() -> int:
    try:
        return int(Path("/proc/sys/vm/max_map_count").read_text())
    except (OSError, ValueError):
        return 65530


def _maps_over_limit() -> bool:
    n = _maps()
    return n is not None and n > MAX_MAPS_FRACTION * _max_maps()


def release() -> None:
    """Drop every compiled program of this process: this store's and JAX's own caches
    (:func:`jax.clear_caches`), so their executables' memory is returned; later calls
    read the programs again from the store (or trace them)."""
    import gc

    global RELEASES
    _drain()
    _LOADED.clear()
    jax.clear_caches()
    gc.collect()
    RELEASES += 1


def prefetch(name: str, fn: Callable, *args) -> bool:
    """Start reading the stored program that ``call(name, fn, *args)`` will need, in a
    background thread; ``args`` need only the right tree, static fields, shapes and dtypes
    (their values are not used). Returns whether a read was started: not where the program
    is loaded or already being read, not stored yet (tracing stays in the caller's
    thread), the store is off, or ``HDID_PREFETCH=0``."""
    if os.environ.get("HDID_PREFETCH") == "0":
        return False
    dyn, static = eqx.partition(args, eqx.is_array)
    leaves, treedef = jax.tree_util.tree_flatten(dyn)
    try:
        key = _key(name, treedef, static, leaves)
    except Exception:  # noqa: BLE001 - an unkeyable argument: call() will jit it
        return False
    if key in _LOADED or key in _PENDING:
        return False
    stem = _find(key, lambda: _program_trace.object_files([fn, *args]))
    if stem is None:
        return False
    specs = [jax.ShapeDtypeStruct(x.shape, x.dtype, weak_type=bool(getattr(x, "weak_type", False)))
             for x in leaves]
    global _POOL
    if _POOL is None:
        _POOL = ThreadPoolExecutor(PREFETCH_WORKERS, thread_name_prefix=PREFETCH_THREAD)
    _PENDING[key] = _POOL.submit(_read_compiled, name, stem, specs)
    return True


def _read_compiled(name: str, stem: str, specs):
    """(background thread) The stored program ``stem`` (:func:`_find`) compiled for
    ``specs`` (JAX's persistent cache read), and its :data:`STATS` row; ``None`` on any
    failure."""
    w0, t0 = time.time(), time.perf_counter()
    exported = _load(stem)
    if exported is None:
        return None
    t1 = time.perf_counter()
    try:
        lowered = jax.jit(exported.call).lower(*specs)
        t2 = time.perf_counter()
        prog = lowered.compile()
    except Exception:  # noqa: BLE001 - the caller prepares it as without a prefetch
        return None
    t3 = time.perf_counter()
    return prog, {"name": name, "how": "stored", "background": True, "prepare_s": t1 - t0,
                  "wrap_s": t2 - t1, "compile_s": t3 - t2, "key": stem[:12],
                  "background_span": (w0, w0 + t3 - t0)}


def _prefetched(key: str, leaves):
    """The program read in the background for ``key`` and its result on ``leaves``, or
    ``None`` (none started, or it failed: the caller prepares it in its own thread). The
    caller's wait is its compile time (``span``)."""
    fut = _PENDING.pop(key, None)
    if fut is None:
        return None
    w0, t0 = time.time(), time.perf_counter()
    try:
        got = fut.result()
    except Exception:  # noqa: BLE001
        got = None
    wait = time.perf_counter() - t0
    if got is None:
        return None
    prog, row = got
    try:
        out = jax.block_until_ready(prog(*leaves))
    except Exception:  # noqa: BLE001 - e.g. an argument layout the specs did not give
        return None
    STATS.append({**row, "wait_s": wait, "span": (w0, w0 + wait)})
    return prog, out


def _drain() -> None:
    """Wait for every background read and drop what it read (before :func:`release`)."""
    while _PENDING:
        _, fut = _PENDING.popitem()
        try:
            fut.result()
        except Exception:  # noqa: BLE001
            pass


def _prepare(name, key, fn, treedef, static, leaves):
    """A compiled program for ``key`` and its first result."""
    w0 = time.time()  # (the clock of JAX's compile events, for hdid._fitting._vfit's union)
    t0 = time.perf_counter()
    stem = _find(key, lambda: _program_trace.object_files(
        [fn, *eqx.combine(jax.tree_util.tree_unflatten(treedef, leaves), static)]))
    exported = _load(stem) if stem is not None else None
    how = "stored" if exported is not None else "traced"
    if exported is None:
        exported, stem = _export(name, key, fn, treedef, static, leaves)
    t1 = time.perf_counter()
    if exported is not None:
        try:
            lowered = jax.jit(exported.call).lower(*leaves)
            t2 = time.perf_counter()
            prog = lowered.compile()
            t3 = time.perf_counter()
            out = jax.block_until_ready(prog(*leaves))
            STATS.append({"name": name, "how": how, "prepare_s": t1 - t0, "wrap_s": t2 - t1,
                          "compile_s": t3 - t2, "key": key[:12], "span": (w0, w0 + t3 - t0)})
            return prog, out
        except Exception:  # noqa: BLE001 - never load it again; compile it here
            _mark_bad(stem or key)
    t1 = time.perf_counter()
    prog = _compile(fn, treedef, static, leaves)
    t2 = time.perf_counter()
    STATS.append({"name": name, "how": "jit", "prepare_s": 0.0, "wrap_s": 0.0, "compile_s": t2 - t1,
                  "key": key[:12], "span": (w0, w0 + t2 - t0)})
    return prog, prog(*leaves)


def _flat(fn, treedef, static):
    def flat(*xs):
        return fn(*eqx.combine(jax.tree_util.tree_unflatten(treedef, xs), static))

    return flat


#: The wrapper's code: where a traced program's tracebacks leave the store
#: (:func:`hdid._problems._program_trace.traced_files`).
_STOP = frozenset({_flat(None, None, None).__code__})


def _compile(fn, treedef, static, leaves):
    return jax.jit(_flat(fn, treedef, static)).lower(*leaves).compile()


def _export(name: str, key: str, fn, treedef, static, leaves):
    """Trace and lower ``fn`` once (a :mod:`jax.export` ``Exported``) and keep it with the
    record of what its trace ran (:mod:`hdid._problems._program_deps`); ``(exported,
    stem)``, ``stem`` ``None`` where it was not stored (a record in doubt), ``(None,
    None)`` where the store is off, the key is marked bad, or it cannot be exported."""
    store = _store()
    if store is None or (store / f"{key}.bad").exists():
        return None, None
    try:
        from jax import export

        jitted = jax.jit(_flat(fn, treedef, static))
        traced = jitted.trace(*leaves)  # (export reuses this trace: JAX caches it)
        exported = export.export(jitted)(*leaves)
        # (the VJP hook is a closure and cannot be pickled; the store only calls)
        blob = pickle.dumps(dataclasses.replace(exported, _get_vjp=None))
    except Exception:  # noqa: BLE001 - cannot export here: in-process only
        _mark_bad(key)
        return None, None
    t0 = time.perf_counter()
    args = eqx.combine(jax.tree_util.tree_unflatten(treedef, leaves), static)
    files = _program_trace.traced_files(traced.jaxpr.jaxpr, _STOP)
    rec = _program_deps.record(None if files is None
                               else files | _program_trace.object_files([fn, *args]))
    DEPS_S.append(time.perf_counter() - t0)
    if rec is None:  # in doubt: this process only
        UNSTORED.append((name, _program_deps.LAST_DOUBT))
        return exported, None
    text = json.dumps(rec, sort_keys=True)
    vid = hashlib.sha256(text.encode()).hexdigest()[:16]
    stem = f"{key}.{vid}"
    try:
        tmp = store / f"{stem}.{os.getpid()}.tmp"
        tmp.write_bytes(blob)
        os.replace(tmp, store / f"{stem}.exp")
        _add_version(store, key, vid, rec)
        os.utime(store)  # in use: not stale
    except OSError:
        pass
    return exported, stem


#: Seconds spent recording each stored program's dependencies (for benchmarks).
DEPS_S: list[float] = []
#: ``(name, why)`` of programs traced but not stored: what their trace ran could not be
#: pinned down (:func:`hdid._problems._program_deps.record`).
UNSTORED: list[str] = []


def phase_reporter(progress):
    """For :func:`hdid.diagnose`: ``say(msg)`` with the elapsed time, and ``timing()``:
    wall seconds in all, compiling/loading programs (JAX's compile events and this
    store's :data:`STATS` spans: reading or tracing, compiling or reading JAX's cache)
    and the rest, CPU seconds, and how many programs were read from the store."""
    from .._compile_clock import _clock, union_length

    clock = _clock()
    mark, first = clock.mark(), len(STATS)
    with clock.lock:
        bg_mark = len(clock.background)
    t0, c0 = time.perf_counter(), time.process_time()

    def say(msg: str) -> None:
        if progress is not None:
            progress(f"[{time.perf_counter() - t0:5.1f} s] {msg}")

    def timing() -> dict[str, float]:
        total = time.perf_counter() - t0
        progs = STATS[first:]
        # JAX's compile events and the store's own spans (reading or tracing a program,
        # compiling it or reading JAX's cache), overlaps counted once
        with clock.lock:
            spans = list(clock.spans[mark:])
            background = list(clock.background[bg_mark:])
        comp = union_length(spans + [p["span"] for p in progs])
        # (a program read in the background counts as compile time only while the caller
        # waited for it; the background reads themselves overlap the fitting)
        return {"total_s": total, "compile_s": comp, "run_s": max(total - comp, 0.0),
                "compile_background_s": union_length(
                    background + [p["background_span"] for p in progs if "background_span" in p]),
                "programs_prefetched": sum(bool(p.get("background")) for p in progs),
                "cpu_s": time.process_time() - c0,
                "programs": len(progs),
                "programs_stored": sum(p["how"] == "stored" for p in progs),
                "programs_traced": sum(p["how"] != "stored" for p in progs)}

    return say, timing
