"""Vectorised batch fit: the multi-start fits of many logs as vmapped lanes.

:func:`hdid.fit` runs its starts as lanes of one vmapped Levenberg–Marquardt program. Here
the lanes of *many* logs share those programs: logs whose problems have the same structure
and shape (runs × samples after padding, free parameters, set-ups) form a *bucket*; each
compiled call advances ``lanes`` (log, start) pairs at once, each lane with its own log's
arrays. The schedule is exactly :func:`hdid.fit`'s — grid, phase 1 (every start
``PHASE1_STEPS`` iterations), phase 2 (the best ``CONTINUED_STARTS`` in chunks of
``PHASE2_CHUNK``, lanes far behind their log's best dropped) — so every log gets the fit it
would get alone: lanes never interact, only share the vector instructions.

Samples are padded (repeated last sample, weight 0: zero-length intervals and zero
residuals) so that logs of slightly different lengths share a bucket; the analysis of each
log (covariance, warnings, :class:`~hdid.FitResult`) uses its own, unpadded problem.

The JAX parts of the analysis (Jacobian, dense prediction, derived quantities) are also
computed for many logs per call; the band bracket (event-driven reference simulation of
every run, 40–60 ms of CPU per log in SciPy) is optional.

Why the gain is modest on a CPU (``benchmarks/results/batch_speed.md``): a lane's cost is
dominated by the forward-mode simulation, which is compute-bound already at a few lanes,
and a vmapped ``while_loop`` runs as long as its slowest lane (a start that rings for the
whole record holds up the others). Lanes are therefore ordered by their current
simulation length (a cheap forward pass) so that long ones share calls, calls are narrow
(``DEFAULT_LANES``), and they run on ``threads`` threads.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Any

import equinox as eqx
import jax
import numpy as np

from . import _config  # noqa: F401
from ._errors import HdidError
from ._fit import (
    CONTINUED_STARTS,
    DROP_DCHI2,
    PHASE1_STEPS,
    PHASE2_CHUNK,
    _choose_starts,
    _finish,
    _grid_candidates,
    _levenberg_marquardt,
    _Setup,
    _setup,
)
from ._identifiability import derived_quantities
from ._problem import Problem
from ._simulate import simulate

#: Lanes per compiled call. The forward-mode simulation is compute-bound from a few lanes
#: on a CPU core and wider calls wait longer for their slowest lane: on 32 logs (2 shared
#: cores) 4–6 lanes took 1.3–1.5 ms per lane-step, 16 lanes 2.9 ms, 32 lanes 4.0 ms.
DEFAULT_LANES = 6
#: Lanes per call of the grid's forward-only cost evaluation (cheap, vectorises well).
GRID_LANES = 128
#: Logs set up, fitted and analysed together; bounds the host memory of a batch.
DEFAULT_WAVE = 256
#: Samples are padded up to a multiple of this, so that logs of nearly equal length share
#: one compiled program.
PAD_SAMPLES = 16

#: Exceptions that make a log's row an error instead of stopping the batch.
LOG_ERRORS = (HdidError, ValueError, KeyError, OSError, FloatingPointError)


def error_text(exc: BaseException) -> str:
    """One line for a failed log's ``error`` column."""
    msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
    return str(msg).replace("\n", " ") or type(exc).__name__


# ----------------------------------------------------------------------------- timing


class _CompileClock:
    """Wall time spent tracing, lowering and compiling (or reading the persistent cache).

    JAX reports these phases as monitoring events; nested jits overlap, so the union of
    the spans is kept.
    """

    KEYS = (
        "/jax/core/compile/jaxpr_trace_duration",
        "/jax/core/compile/jaxpr_to_mlir_module_duration",
        "/jax/core/compile/backend_compile_duration",
    )

    def __init__(self):
        self.spans: list[tuple[float, float]] = []
        self.lock = threading.Lock()
        from jax import monitoring

        monitoring.register_event_time_span_listener(self._span)

    def _span(self, event, start, end, **_):
        if event in self.KEYS:
            with self.lock:
                self.spans.append((start, end))

    def mark(self) -> int:
        with self.lock:
            return len(self.spans)

    def since(self, mark: int) -> float:
        with self.lock:
            spans = list(self.spans[mark:])
        return union_length(spans)


def union_length(spans) -> float:
    """Total length of the union of ``(start, end)`` intervals (nested traces overlap)."""
    total, cur_s, cur_e = 0.0, None, None
    for s, e in sorted(spans):
        if cur_e is None or s > cur_e:
            if cur_e is not None:
                total += cur_e - cur_s
            cur_s, cur_e = s, e
        else:
            cur_e = max(cur_e, e)
    if cur_e is not None:
        total += cur_e - cur_s
    return total


_CLOCK: _CompileClock | None = None


def _clock() -> _CompileClock:
    global _CLOCK
    if _CLOCK is None:
        _CLOCK = _CompileClock()
    return _CLOCK


# ----------------------------------------------------------------------------- programs


@eqx.filter_jit
def _lane_costs(problems: Problem, U):
    """χ² of each lane's candidate under its own log's problem (forward simulation only)."""
    return jax.vmap(lambda p, u: p.cost(u))(problems, U)


@eqx.filter_jit
def _lane_lengths(problems: Problem, U):
    """Samples each lane's simulation runs before every run sticks (its cost in a call)."""

    def one(p: Problem, u):
        _, t_release, theta0_enc, offset = p.unpack(u)
        model = p.model(u)
        off = offset[p.setup_index]
        _, _, stuck = jax.vmap(
            lambda t, th0, tr, ai: simulate(
                model, t, th0, tr, added_inertia=ai, max_substep=p.max_substep,
                full_output=True,
            )
        )(p.times, theta0_enc - off, t_release, p.added_inertia)
        return jax.numpy.max(jax.numpy.sum(~stuck, axis=1))

    return jax.vmap(one)(problems, U)


@eqx.filter_jit
def _lane_solve(problems: Problem, U, active, max_steps):
    """:func:`hdid._fit._levenberg_marquardt` for each lane, with its own log and budget."""
    return jax.vmap(_levenberg_marquardt)(problems, U, active, max_steps)


@eqx.filter_jit
def _lane_analysis(problems: Problem, U):
    """The JAX parts of :func:`hdid._identifiability.analyse`, for each lane."""

    def one(p: Problem, u):
        r, J = p.data_residuals_and_jacobian(u)
        _, t_release, theta0_enc, offset = p.unpack(u)
        model = p.model(u)
        off = offset[p.setup_index]
        dense = jax.vmap(
            lambda t, th0, tr, ai: simulate(
                model, t, th0, tr, added_inertia=ai, max_substep=p.max_substep,
                full_output=True,
            )
        )(p.times, theta0_enc - off, t_release, p.added_inertia)
        P = p.n_physical

        def quantities(up):
            return derived_quantities(p.model(jax.numpy.concatenate([up, u[P:]])))

        derived = (quantities(u[:P]), jax.jacfwd(quantities)(u[:P]))
        return (J, r), dense, derived

    return jax.vmap(one)(problems, U)


# ----------------------------------------------------------------------------- buckets


def _pad_problem(problem: Problem, T: int) -> Problem:
    """``problem`` with every run padded to ``T`` samples: the last sample repeated, weight 0."""
    n = problem.times.shape[1]
    if n == T:
        return problem

    def pad(x):
        x = np.asarray(x)
        return np.concatenate([x, np.repeat(x[:, -1:], T - n, axis=1)], axis=1)

    return eqx.tree_at(
        lambda p: (p.times, p.theta, p.weight),
        problem,
        (pad(problem.times), pad(problem.theta),
         np.concatenate([np.asarray(problem.weight), np.zeros((problem.n_runs, T - n))], axis=1)),
    )


def _bucket_key(problem: Problem):
    leaves, treedef = jax.tree_util.tree_flatten(problem)
    return treedef, tuple((np.shape(x), np.asarray(x).dtype.str) for x in leaves)


class _Bucket:
    """Logs whose (padded) problems share structure and shapes, stacked on a leading axis."""

    def __init__(self, problems: Sequence[Problem], key):
        self.key = key
        leaves = [jax.tree_util.tree_flatten(p) for p in problems]
        self.treedef = leaves[0][1]
        self.stacked = [np.stack([np.asarray(lv[0][i]) for lv in leaves]) for i in
                        range(len(leaves[0][0]))]

    def gather(self, index: np.ndarray) -> Problem:
        """The problems of logs ``index`` (one per lane), stacked."""
        return jax.tree_util.tree_unflatten(self.treedef, [x[index] for x in self.stacked])


# ----------------------------------------------------------------------------- state


@dataclass
class _LogFit:
    """One log's progress through the schedule of :func:`hdid.fit`."""

    setup: _Setup
    bucket: int
    row: int  # index within its bucket
    U: np.ndarray | None = None
    costs: np.ndarray | None = None
    ok: np.ndarray | None = None
    steps: np.ndarray | None = None
    active: np.ndarray | None = None
    used: int = 0
    done: bool = False
    extra: dict = field(default_factory=dict)


@dataclass
class BatchTiming:
    """Where the time of a batch went (wall seconds).

    ``compile_s`` is the union of JAX's tracing, lowering and XLA compile (or persistent
    cache read) spans; ``run_s = total_s − compile_s``.
    """

    total_s: float = 0.0
    compile_s: float = 0.0
    setup_s: float = 0.0
    grid_s: float = 0.0
    solve_s: float = 0.0
    analyse_s: float = 0.0
    n_logs: int = 0
    n_failed: int = 0
    n_buckets: int = 0
    lane_steps: int = 0
    lanes: int = DEFAULT_LANES
    threads: int = 1

    @property
    def run_s(self) -> float:
        return max(self.total_s - self.compile_s, 0.0)

    def add(self, other: BatchTiming) -> None:
        for k in ("total_s", "compile_s", "setup_s", "grid_s", "solve_s", "analyse_s",
                  "n_logs", "n_failed", "lane_steps"):
            setattr(self, k, getattr(self, k) + getattr(other, k))
        self.n_buckets = max(self.n_buckets, other.n_buckets)

    def to_dict(self) -> dict[str, Any]:
        keys = ("total_s", "compile_s", "setup_s", "grid_s", "solve_s", "analyse_s", "n_logs",
                "n_failed", "n_buckets", "lane_steps", "lanes", "threads")
        return {**{k: getattr(self, k) for k in keys}, "run_s": self.run_s}


# ----------------------------------------------------------------------------- driver


_SETUP_OPTIONS = ("model", "inertia", "fix", "free_inertia", "inertia_prior", "release_time",
                  "counts_per_rev", "max_substep")
_FIT_OPTIONS = (*_SETUP_OPTIONS, "n_starts", "max_steps", "start_from_model")


class _Runner:
    """Runs lane calls of one program shape, the first synchronously (it compiles)."""

    def __init__(self, pool: ThreadPoolExecutor | None):
        self.pool = pool
        self.seen: set = set()

    def map(self, key, fn: Callable, calls: list):
        if not calls:
            return []
        out: list = []
        if key not in self.seen:
            out.append(fn(*calls[0]))
            self.seen.add(key)
            calls = calls[1:]
        if self.pool is None or len(calls) < 2:
            out.extend(fn(*c) for c in calls)
        else:
            out.extend(self.pool.map(lambda c: fn(*c), calls))
        return out


def fit_batch(
    items: Sequence[Any],
    *,
    lanes: int = DEFAULT_LANES,
    threads: int | None = None,
    wave: int = DEFAULT_WAVE,
    bracket: bool = False,
    on_done: Callable[[int, Any], None] | None = None,
    sort_lanes: bool = True,
    **options,
) -> tuple[list[Any], BatchTiming]:
    """Fit every log of ``items``, vectorised across logs.

    Returns the per-log outcomes (a :class:`~hdid.FitResult` or the exception that
    stopped that log), in input order, and a :class:`BatchTiming`. ``on_done(i, outcome)``
    is called as each log finishes. ``options`` are those of :func:`hdid.fit`.
    """
    unknown = set(options) - set(_FIT_OPTIONS)
    if unknown:
        raise TypeError(f"fit_many: unknown option(s) {sorted(unknown)}; choose from "
                        f"{list(_FIT_OPTIONS)}")
    if lanes < 1:
        raise ValueError(f"lanes = {lanes!r}: must be >= 1")
    threads = min(os.cpu_count() or 1, 8) if threads is None else max(int(threads), 1)
    timing = BatchTiming(lanes=lanes, threads=threads)
    outcomes: list[Any] = [None] * len(items)
    clock = _clock()
    mark = clock.mark()
    t0 = time.perf_counter()
    pool = ThreadPoolExecutor(threads) if threads > 1 else None
    runner = _Runner(pool)
    try:
        for start in range(0, len(items), max(int(wave), 1)):
            idx = list(range(start, min(start + wave, len(items))))
            _fit_wave(items, idx, outcomes, runner, timing, lanes, bracket, on_done, options,
                      sort_lanes)
    finally:
        if pool is not None:
            pool.shutdown()
    timing.total_s = time.perf_counter() - t0
    timing.compile_s = clock.since(mark)
    timing.n_logs = len(items)
    timing.n_failed = sum(isinstance(o, BaseException) for o in outcomes)
    return outcomes, timing


def _fit_wave(items, idx, outcomes, runner, timing, lanes, bracket, on_done, options,
              sort_lanes=True):
    setup_opts = {k: options[k] for k in _SETUP_OPTIONS if k in options}
    n_starts = int(options.get("n_starts", 6))
    max_steps = int(options.get("max_steps", 300))
    from_model = bool(options.get("start_from_model", False))

    def fail(i, exc):
        outcomes[i] = exc
        if on_done is not None:
            on_done(i, exc)

    # -- set up and bucket --------------------------------------------------------------
    t = time.perf_counter()
    fits: dict[int, _LogFit] = {}
    keys: dict = {}
    members: list[list[Problem]] = []
    bucket_keys: list = []
    for i in idx:
        try:
            setup = _setup(items[i], **setup_opts)
        except LOG_ERRORS as exc:
            fail(i, exc)
            continue
        T = setup.problem.times.shape[1]
        padded = _pad_problem(setup.problem, PAD_SAMPLES * math.ceil(T / PAD_SAMPLES))
        key = _bucket_key(padded)
        b = keys.setdefault(key, len(keys))
        if b == len(members):
            members.append([])
            bucket_keys.append(key)
        fits[i] = _LogFit(setup, b, len(members[b]))
        members[b].append(padded)
    buckets = [_Bucket(m, k) for m, k in zip(members, bucket_keys)]
    timing.n_buckets = max(timing.n_buckets, len(buckets))
    timing.setup_s += time.perf_counter() - t

    # -- grid -----------------------------------------------------------------------------
    t = time.perf_counter()
    cand: dict[int, tuple[np.ndarray, np.ndarray]] = {}
    for i, f in list(fits.items()):
        try:
            cand[i] = _grid_candidates(f.setup.problem, f.setup.prep, f.setup.model, from_model)
        except LOG_ERRORS as exc:
            del fits[i]
            fail(i, exc)
    for b, bucket in enumerate(buckets):
        lane_log = [(i, j) for i, f in fits.items() if f.bucket == b for j in range(len(cand[i][0]))]
        if not lane_log:
            continue
        rows = np.array([fits[i].row for i, _ in lane_log])
        U = np.stack([cand[i][0][j] for i, j in lane_log])
        costs = _run_lanes(runner, "grid", _lane_costs, bucket, rows, (U,), GRID_LANES)
        costs = np.concatenate([np.asarray(c) for c in costs])
        pos = 0
        for i, f in fits.items():
            if f.bucket != b:
                continue
            n = len(cand[i][0])
            U0, cost0 = _choose_starts(cand[i][0], costs[pos : pos + n], cand[i][1], n_starts,
                                       from_model)
            pos += n
            f.U = np.array(U0)
            f.costs = np.array(cost0, dtype=float)  # (only orders phase 1's lanes)
            f.steps = np.zeros(len(U0), dtype=int)
            f.ok = np.zeros(len(U0), dtype=bool)
    timing.grid_s += time.perf_counter() - t

    # -- phase 1: every start PHASE1_STEPS iterations ------------------------------------
    t = time.perf_counter()
    tasks = [(i, j, PHASE1_STEPS) for i, f in fits.items() for j in range(len(f.U))]
    _solve_tasks(runner, fits, buckets, tasks, lanes, timing, sort=sort_lanes)
    for f in fits.values():
        f.active = np.zeros(len(f.U), dtype=bool)
        finite_costs = np.where(np.isfinite(f.costs), f.costs, np.inf)
        f.active[np.argsort(finite_costs)[:CONTINUED_STARTS]] = True
        f.ok = np.zeros(len(f.U), dtype=bool)

    # -- phase 2: the best starts in chunks, lanes far behind their log's best dropped ---
    while True:
        tasks = []
        for i, f in fits.items():
            if f.active.any() and f.used < max_steps:
                chunk = min(PHASE2_CHUNK, max_steps - f.used)
                tasks.extend((i, j, chunk) for j in np.flatnonzero(f.active))
                f.extra["chunk"] = chunk
        if not tasks:
            break
        before = {i: f.active.copy() for i, f in fits.items() if "chunk" in f.extra}
        _solve_tasks(runner, fits, buckets, tasks, lanes, timing, phase2=True, sort=sort_lanes)
        for i, act in before.items():
            f = fits[i]
            f.used += f.extra.pop("chunk")
            best_now = np.min(np.where(np.isfinite(f.costs), f.costs, np.inf))
            f.active = act & ~f.extra.pop("done2") & (f.costs - best_now < DROP_DCHI2)
    timing.solve_s += time.perf_counter() - t

    # -- analysis ---------------------------------------------------------------------------
    t = time.perf_counter()
    for b, bucket in enumerate(buckets):
        logs = [i for i, f in fits.items() if f.bucket == b]
        best = {}
        for i in logs:
            c = np.where(np.isfinite(fits[i].costs), fits[i].costs, np.inf)
            best[i] = int(np.argmin(c))
        good = [i for i in logs if np.isfinite(fits[i].costs[best[i]])]
        pre: dict[int, dict] = {}
        if good:
            rows = np.array([fits[i].row for i in good])
            U = np.stack([fits[i].U[best[i]] for i in good])
            outs = _run_lanes(runner, "analysis", _lane_analysis, bucket, rows, (U,), lanes)
            flat = jax.tree_util.tree_map(lambda *xs: np.concatenate(xs), *outs)
            for k, i in enumerate(good):
                pre[i] = _unpad(jax.tree_util.tree_map(lambda x: x[k], flat),
                                fits[i].setup.problem)
        for i in logs:
            f = fits[i]
            ta = time.perf_counter()
            try:
                res = _finish(f.setup, f.U, f.costs, f.ok, f.steps, ta, bracket=bracket,
                              precomputed=pre.get(i))
                _check_finite(res)
            except LOG_ERRORS as exc:
                fail(i, exc)
                continue
            outcomes[i] = res
            if on_done is not None:
                on_done(i, res)
    timing.analyse_s += time.perf_counter() - t


def _check_finite(res) -> None:
    from ._errors import FitError

    bad = [n for n, p in res.parameters.items() if not math.isfinite(p.value)]
    if bad or not math.isfinite(res.rms_residual_rad):
        raise FitError(
            f"{res.source}: the fit ended at non-finite values ({', '.join(bad) or 'RMS'}); "
            "check units (rad vs counts) and --inertia, or fix some parameters"
        )


def _unpad(pre, problem: Problem) -> dict:
    """The precomputed analysis parts of one lane, cut back to the log's own samples."""
    (J, r), dense, derived = pre
    R, T = problem.times.shape
    Tp = J.shape[0] // R
    J = J.reshape(R, Tp, -1)[:, :T].reshape(R * T, -1)
    r = r.reshape(R, Tp)[:, :T].reshape(-1)
    dense = tuple(x[:, :T] for x in dense)
    return {"jacobian": (J, r), "dense": dense, "derived": derived}


def _run_lanes(runner: _Runner, key, fn, bucket: _Bucket, rows, arrays, width):
    """``fn(problems, *arrays)`` over all lanes in calls of ``width`` (the last one padded)."""
    n = len(rows)
    calls, sizes = [], []
    for s in range(0, n, width):
        sl = slice(s, min(s + width, n))
        m = sl.stop - sl.start
        idx = np.concatenate([rows[sl], np.repeat(rows[sl][:1], width - m)])
        args = [np.concatenate([a[sl], np.repeat(a[sl][:1], width - m, axis=0)]) for a in arrays]
        calls.append((bucket.gather(idx), *args))
        sizes.append(m)
    outs = runner.map((key, bucket.key, width), fn, calls)
    return [jax.tree_util.tree_map(lambda x, m=m: np.asarray(x)[:m], o) for o, m in zip(outs, sizes)]


def _solve_tasks(runner, fits, buckets, tasks, lanes, timing, phase2=False, sort=True):
    """Advance lanes ``(log, start, max_steps)``; lanes of similar χ² share a call."""
    by_bucket: dict[int, list] = {}
    for task in tasks:
        by_bucket.setdefault(fits[task[0]].bucket, []).append(task)
    for b, group in by_bucket.items():
        rows = np.array([fits[i].row for i, _, _ in group])
        U = np.stack([fits[i].U[j] for i, j, _ in group])
        if sort:
            # A vmapped loop runs as long as its slowest lane, and a start that rings for
            # the whole record costs ~10x one that sticks early: lanes of similar
            # simulation length (at their current point, a cheap forward pass) share calls.
            length = np.concatenate(_run_lanes(runner, "lengths", _lane_lengths, buckets[b],
                                               rows, (U,), GRID_LANES))
            order = np.argsort(-length, kind="stable")
            group = [group[k] for k in order]
            rows, U = rows[order], U[order]
        active = np.ones(len(group), dtype=bool)
        steps = np.array([s for _, _, s in group])
        outs = _run_lanes(runner, "solve", _lane_solve, buckets[b], rows,
                          (U, active, steps), lanes)
        U2, c2, done2, s2 = (np.concatenate(x) for x in zip(*outs))
        timing.lane_steps += int(s2.sum())
        for k, (i, j, _) in enumerate(group):
            f = fits[i]
            f.U[j], f.costs[j], f.steps[j] = U2[k], c2[k], f.steps[j] + s2[k]
            if phase2:
                f.ok[j] = done2[k]
                f.extra.setdefault("done2", np.zeros(len(f.U), dtype=bool))[j] = done2[k]
        if phase2:
            for i in {t[0] for t in group}:
                fits[i].extra.setdefault("done2", np.zeros(len(fits[i].U), dtype=bool))
