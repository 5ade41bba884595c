"""Vectorised batch fit: the multi-start fits of many logs as lanes of shared programs.

:func:`hdid.fit` runs its starts one at a time through the one-lane Levenberg–Marquardt
program of its structure (:mod:`hdid._fitting._one_lane`, :func:`hdid._fitting._lm._lm_lanes`).
Here the lanes of *many* logs share compiled programs: logs
whose problems have the same structure and shape (runs × samples after padding, free
parameters, set-ups) form a *bucket*; each call advances ``lanes`` (log, start) pairs, each
lane with its own log's arrays. The schedule is :func:`hdid.fit`'s own
(:class:`hdid._fitting._lm._Schedule`: grid, phase 1, phase 2 in chunks, lanes far behind their
log's best dropped), so every log gets the fit it would get alone: lanes never interact.

Samples are padded (repeated last sample, weight 0: zero-length intervals and zero
residuals) so that logs of slightly different lengths share a bucket; the analysis of each
log (covariance, warnings, :class:`~hdid.FitResult`) uses its own, unpadded problem.

The JAX parts of the analysis (Jacobian, dense prediction, derived quantities) are also
computed for many logs per call; the band bracket (event-driven reference simulation of
every run, 40–60 ms of CPU per log in SciPy) is optional.

Where the time goes and why the calls are one lane wide on a CPU
(``benchmarks/results/batch_speed.md``): a lane's cost is the stick-exact simulation,
which is compute-bound already at one lane, and the LM's control flow is per call — in a
one-lane program a rejected trial costs one forward pass and the forward-mode Jacobian
(≈ 3× a forward pass) is computed only for accepted trials; a wider call computes it when
*any* of its lanes needs it and runs as long as its slowest lane. Width 1 was the
cheapest in CPU time per log; one-lane programs also keep the simulator's event branch a
real ``cond`` (:func:`hdid._fitting._lm.lanes_vmap`). Threads do not add cores: JAX runs one CPU
program at a time per process (2 threads issuing calls: CPU time = wall time, measured),
so several cores need several processes (``fit_many(workers=…)``, dask). The Jacobian and
residuals at the end of a lane's call are carried to its next call. The grid's forward
passes are wide (``GRID_LANES``), with candidates ordered by how long they ring so that a
call's lanes stop at similar times.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import jax
import numpy as np

from .._compile_clock import _clock
from .._config import float64
from .._errors import HdidError
from ._fit import _finish, _setup, nested_check
from .._log import Log, read_log
from ._lm import LMState, _Schedule
from ._limits import needs_check
from ._nested import CHECK_ABOVE_FLOOR
from .._problems._problem import Problem
from ._starts import _grid_candidates, with_drop_starts
from ._vfit_lanes import (
    _Bucket, _bucket_key, _lane_analysis, _lane_costs, _lane_lengths, _lane_solve, _LogFit,
    _pad_problem,
)


#: Lanes per compiled call of the Levenberg–Marquardt program. One: the LM's Jacobian is
#: then computed only where its lane needs it (module docstring). Measured on 40 paper
#: logs (2 shared cores): CPU per log 146–152 ms at 1 lane, ≈ 440 ms at 6 lanes.
DEFAULT_LANES = 1
#: Lanes per call of the grid's forward-only cost evaluation (cheap, vectorises well).
GRID_LANES = 128
#: Lanes per call of the analysis (one pass per log, no LM control flow).
ANALYSIS_LANES = 8
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
    #: CPU (process) time of each part, all threads: less sensitive to other jobs.
    setup_cpu_s: float = 0.0
    grid_cpu_s: float = 0.0
    solve_cpu_s: float = 0.0
    analyse_cpu_s: float = 0.0
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
                  "setup_cpu_s", "grid_cpu_s", "solve_cpu_s", "analyse_cpu_s", "n_logs", "n_failed", "lane_steps"):
            setattr(self, k, getattr(self, k) + getattr(other, k))
        self.n_buckets = max(self.n_buckets, other.n_buckets)

    def to_dict(self) -> dict[str, Any]:
        keys = ("total_s", "compile_s", "setup_s", "grid_s", "solve_s", "analyse_s",
                "setup_cpu_s", "grid_cpu_s", "solve_cpu_s", "analyse_cpu_s", "n_logs",
                "n_failed", "n_buckets", "lane_steps", "lanes", "threads")
        return {**{k: getattr(self, k) for k in keys}, "run_s": self.run_s}


# ----------------------------------------------------------------------------- driver


_SETUP_OPTIONS = ("model", "inertia", "fix", "free_inertia", "inertia_prior", "release_time",
                  "counts_per_rev", "max_substep", "ratio", "resolution")
_FIT_OPTIONS = (*_SETUP_OPTIONS, "n_starts", "max_steps", "start_from_model", "nested")


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
            # Worker threads do not inherit the caller's thread-local float64: enter it.
            out.extend(self.pool.map(float64(lambda c: fn(*c)), calls))
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
    # One thread by default: a second one issuing calls gains nothing (JAX executes one
    # CPU program at a time per process) and costs ≈ 10 % in contention (measured).
    threads = 1 if threads is None else max(int(threads), 1)
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


def _share_substeps(items, setups: dict, setup_opts: dict) -> None:
    """Logs whose substep (:func:`~hdid._fitting._fit.substep_for`, a power of two of the log's own
    frequency) is twice one that at least as many logs of the batch use are set up again
    with the finer one: same structure, one compiled program instead of two (a 4-run paper
    batch: 1 log in 200 has its frequency estimate just below the octave boundary, and its
    own program cost ~10 s of tracing). Finer never loses accuracy; it costs that log 2×
    the substeps."""
    count: dict[float, int] = {}
    for st in setups.values():
        count[st.problem.max_substep] = count.get(st.problem.max_substep, 0) + 1
    for i, st in list(setups.items()):
        h = st.problem.max_substep
        if count.get(h / 2, 0) >= count[h]:
            setups[i] = _setup(items[i], **{**setup_opts, "max_substep": h / 2})


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
    t, tc = time.perf_counter(), time.process_time()
    fits: dict[int, _LogFit] = {}
    keys: dict = {}
    members: list[list[Problem]] = []
    bucket_keys: list = []
    setups = {}
    for i in idx:
        try:
            setups[i] = _setup(items[i], **setup_opts)
        except LOG_ERRORS as exc:
            fail(i, exc)
    if setup_opts.get("max_substep") is None:
        _share_substeps(items, setups, setup_opts)
    for i, setup in setups.items():
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
    timing.setup_cpu_s += time.process_time() - tc

    # -- grid -----------------------------------------------------------------------------
    t, tc = time.perf_counter(), time.process_time()
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
        order = _ring_order(fits[lane_log[0][0]].setup.problem, U)
        costs = _run_lanes(runner, "grid", _lane_costs, bucket, rows[order], (U[order],),
                           GRID_LANES)
        costs = np.concatenate([np.asarray(c) for c in costs])
        costs = costs[np.argsort(order)]
        pos = 0
        for i, f in fits.items():
            if f.bucket != b:
                continue
            n = len(cand[i][0])
            su = fits[i].setup  # (a pendulum drop's starts from its swings first)
            U0, cost0 = with_drop_starts(su.problem, su.prep, su.model, cand[i][0],
                                         costs[pos : pos + n], cand[i][1], n_starts, from_model)
            pos += n
            f.U = np.array(U0)
            f.costs = np.array(cost0, dtype=float)  # (only orders phase 1's lanes)
            f.steps = np.zeros(len(U0), dtype=int)
            f.ok = np.zeros(len(U0), dtype=bool)
    timing.grid_s += time.perf_counter() - t
    timing.grid_cpu_s += time.process_time() - tc

    # -- phases 1 and 2 (fit()'s _Schedule per log): each round advances every live lane
    # of every log to its log's next check ----------------------------------------------
    for f in fits.values():
        f.sched = _Schedule(len(f.U), max_steps)
        f.lm = {}
    while True:
        tasks = []
        for i, f in fits.items():
            task = f.sched.next()
            if task is None:
                continue
            active, k, fresh = task
            tasks.extend((i, j, k, fresh) for j in np.flatnonzero(active))
        if not tasks:
            break
        results = _solve_tasks(runner, fits, buckets, tasks, lanes, timing, sort=sort_lanes)
        for i, (c2, done2, s2) in results.items():
            f = fits[i]
            f.sched.update(c2, done2, s2)
            f.lm = {j: v for j, v in f.lm.items() if f.sched.active[j]}
    for f in fits.values():
        f.costs, f.ok, f.steps = f.sched.costs, f.sched.ok, f.sched.steps
        f.lm = {}
    timing.solve_s += time.perf_counter() - t
    timing.solve_cpu_s += time.process_time() - tc

    # -- analysis ---------------------------------------------------------------------------
    t, tc = time.perf_counter(), time.process_time()
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
            outs = _run_lanes(runner, "analysis", _lane_analysis, bucket, rows, (U,),
                              ANALYSIS_LANES)
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
                res = _nested(res, items[i], f.setup, options, n_starts, max_steps)
                _check_finite(res)
            except LOG_ERRORS as exc:
                fail(i, exc)
                continue
            outcomes[i] = res
            if on_done is not None:
                on_done(i, res)
    timing.analyse_s += time.perf_counter() - t
    timing.analyse_cpu_s += time.process_time() - tc


def _nested(res, item, setup, options: dict, n_starts: int, max_steps: int):
    """fit()'s check against its model's limits (:mod:`hdid._fitting._limits`: the nested
    Coulomb case, no friction, the linear spring), one log at a time: ``nested="auto"``
    when the residual is above the floor or a term may vanish, ``True`` always,
    ``False`` never. The batch's default (``None``) only
    warns on a residual above ``CHECK_ABOVE_FLOOR`` × the floor: 1000 paper logs took 538 s in one process with the check (6 % of
    them showed a symptom) against 228 s before it existed (load 2.4–3.9); in 200 it
    rescued 2 of the 5 logs above 2× the floor."""
    nested = options.get("nested")
    if nested is None:
        ratio = res.rms_residual_rad / res.quantization_floor_rad
        if needs_check(res, setup.fixed) and not ratio <= CHECK_ABOVE_FLOOR:
            # (a degenerate law at the floor is named by the trust warnings already)
            res.warnings.append(
                f"the RMS residual is {ratio:.3g}× the floor, a symptom of a poorer optimum; "
                "the batch did not check it against its limits (nested Coulomb case, no "
                "friction, linear spring): refit this log "
                "with hdid.fit, or the batch with nested='auto'")
        return res
    if nested is False or nested == "auto" and not needs_check(res, setup.fixed):
        return res
    log = item if isinstance(item, Log) else read_log(
        item, counts_per_rev=options.get("counts_per_rev"), resolution=options.get("resolution"))
    if options.get("resolution") is not None and isinstance(item, Log):
        log = dataclasses.replace(log, resolution=float(options["resolution"]),
                                  resolution_source="given")
    return nested_check(res, log, setup, nested=nested, fix=options.get("fix"),
                        inertia_prior=options.get("inertia_prior"),
                        release_time=options.get("release_time"),
                        max_substep=options.get("max_substep"), n_starts=n_starts,
                        max_steps=max_steps)


def _ring_order(problem: Problem, U: np.ndarray) -> np.ndarray:
    """Lane order by how long each candidate rings (longest first), so that a call's lanes
    run for similar lengths: Coulomb friction stops the swing after ≈ k·θ0/(2·tau_c)
    half-cycles of length ∝ 1/√k, i.e. a time ∝ √k1/tau_c."""
    free = problem.free
    specs = problem.base.parameter_specs()
    if not {"k1", "tau_c"} <= set(free) or any(specs[n].transform != "log" for n in ("k1", "tau_c")):
        return np.arange(len(U))
    key = 0.5 * U[:, free.index("k1")] - U[:, free.index("tau_c")]
    return np.argsort(-key, kind="stable")


def _check_finite(res) -> None:
    from .._errors import FitError

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


def _solve_tasks(runner, fits, buckets, tasks, lanes, timing, sort=True):
    """Advance lanes ``(log, start, iterations, fresh)``; returns, per log, the cost, done
    flag and iterations of every start (only the advanced ones are meaningful)."""
    by_bucket: dict[int, list] = {}
    for task in tasks:
        by_bucket.setdefault(fits[task[0]].bucket, []).append(task)
    out: dict[int, tuple] = {}
    for b, group in by_bucket.items():
        rows = np.array([fits[i].row for i, *_ in group])
        U = np.stack([fits[i].U[j] for i, j, *_ in group])
        if sort and lanes > 1:
            # A vmapped loop runs as long as its slowest lane, and a start that rings for
            # the whole record costs ~10x one that sticks early: lanes of similar
            # simulation length (at their current point, a cheap forward pass) share calls.
            length = np.concatenate(_run_lanes(runner, "lengths", _lane_lengths, buckets[b],
                                               rows, (U,), GRID_LANES))
            order = np.argsort(-length, kind="stable")
            group = [group[k] for k in order]
            rows, U = rows[order], U[order]
        L = len(group)
        m, n = buckets[b].n_residuals, U.shape[1]
        st = LMState.empty(L, m, n)
        for k, (i, j, _, fresh) in enumerate(group):
            prev = fits[i].lm.get(j)
            if prev is not None:
                for field_, v in zip(LMState._fields, prev):
                    getattr(st, field_)[k] = v
            st.fresh[k] = fresh
        active = np.ones(L, dtype=bool)
        steps = np.array([k for _, _, k, _ in group])
        outs = _run_lanes(runner, "solve", _lane_solve, buckets[b], rows,
                          (U, active, steps, *st), lanes)
        U2, c2, done2, s2, *st2 = (np.concatenate(x) for x in zip(*outs))
        timing.lane_steps += int(s2.sum())
        for k, (i, j, _, _) in enumerate(group):
            f = fits[i]
            f.U[j] = U2[k]
            f.lm[j] = tuple(x[k] for x in st2)
            if i not in out:
                nst = len(f.U)
                out[i] = (np.full(nst, np.inf), np.zeros(nst, dtype=bool), np.zeros(nst, dtype=int))
            out[i][0][j], out[i][1][j], out[i][2][j] = c2[k], done2[k], s2[k]
    return out
