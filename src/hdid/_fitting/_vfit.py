"""The batch fit: many logs, each through :func:`hdid.fit`'s own multi-start driver.

Every log runs :func:`hdid.fit`'s steps — the grid of starts
(:func:`hdid._fitting._starts._grid_starts`), Levenberg–Marquardt from every start one at a
time through the one-lane program of its model structure (:mod:`hdid._fitting._one_lane`,
the schedule :class:`hdid._fitting._lm._Schedule`), the restart of an optimum that holds
runs the log shows moving, the analysis at the best start, then :func:`hdid.fit`'s
restarts and substep refit by the same functions (:func:`_settled`: a cubic gone to 0, a
release stuck on its bracket's end, a swing on an alias above the log's Nyquist frequency
folded back, the RK4 substep its fitted swing wants) — so a log gets the fit it gets
alone, up to rounding and, at the floor, the limit checks (:func:`_nested`). There is no
driver of the batch's own. Logs that
:func:`hdid.fit` fits in more than one pass — runs that move from their first samples (both
stories of the first reading), logs on no grid (the search's weights, then the polish in
the likelihood's, :mod:`hdid._fitting._polish`) — go through :func:`hdid.fit` itself.

Programs are shared across logs by *length bucket*: each log's runs are padded (last
sample repeated, weight 0: zero-length intervals and zero residuals) to a multiple of
``PAD_SAMPLES`` samples, so logs of one model structure and nearly equal length call the
same stored programs (:mod:`hdid._problems._programs`: the LM program, the grid's costs, the
trajectory and the derived quantities) — one compile (or store read) per structure and
bucket, none inside a batch. The padding changes sums of squares and ``JᵀJ`` only in the
order of their terms (the added terms are exact zeros), so a log's numbers differ from
:func:`hdid.fit`'s only in the last bits; the analysis of each log (covariance, warnings,
:class:`~hdid.FitResult`) uses its own, unpadded problem with the padded rows cut off.

Why one start at a time, also across logs: the stick-exact simulator takes its event
branch (a ``lax.cond``) only in the substeps that need it; vmapped lanes turn it into a
select that runs every branch in every substep (``LANES`` in :mod:`._one_lane`), and a
one-lane LM computes a Jacobian only when its own trial was accepted. JAX runs one CPU
program at a time per process, so several cores need several processes
(``fit_many(workers=…)``, an executor; :mod:`hdid._fitting._batch`), not threads.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Callable, Sequence
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from typing import Any

import equinox as eqx
import jax
import numpy as np

from .._config import float64
from .._errors import HdidError
from .._log import Log, read_log
from .._problems import _programs
from .._problems._problem import Problem
from .._simulation._prepare import search_weight
from . import _cubic_restart, _first_reading, _log_lanes, _substep
from ._fit import _finish, _setup, _stored_analysis, _untrapped, fit, nested_check
from ._limits import needs_check, reached_floor
from ._one_lane import LANES
from ._one_lane import _local_fits as _one_lane
from ._starts import _grid_starts, log_scales


#: Starts per call of the Levenberg–Marquardt program
#: (:func:`hdid._fitting._one_lane._local_fits`'s ``lanes``): one, as :func:`hdid.fit`.
DEFAULT_LANES = LANES
#: Logs set up together (their substeps shared, :func:`_share_substeps`); bounds the host
#: memory of a batch.
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


_PHASES = ("setup", "grid", "solve", "analyse")


@dataclass
class BatchTiming:
    """Where the time of a batch went (wall seconds).

    ``compile_s`` is the union of JAX's tracing, lowering and XLA compile (or persistent
    cache read) spans and the program store's reads; ``run_s = total_s − compile_s``.
    ``lane_steps``: Levenberg–Marquardt iterations, all starts of all logs.
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

    def to_dict(self) -> dict[str, Any]:
        keys = ("total_s", "compile_s", *(f"{p}_s" for p in _PHASES),
                *(f"{p}_cpu_s" for p in _PHASES), "n_logs", "n_failed", "n_buckets",
                "lane_steps", "lanes", "threads")
        return {**{k: getattr(self, k) for k in keys}, "run_s": self.run_s}


class _Phase:
    """Adds the wall and process time of a ``with`` block to ``timing.<name>_s`` and
    ``<name>_cpu_s``."""

    def __init__(self, timing: BatchTiming, name: str):
        self.timing, self.name = timing, name

    def __enter__(self):
        self.t, self.c = time.perf_counter(), time.process_time()

    def __exit__(self, *exc):
        tm, n = self.timing, self.name
        setattr(tm, f"{n}_s", getattr(tm, f"{n}_s") + time.perf_counter() - self.t)
        setattr(tm, f"{n}_cpu_s", getattr(tm, f"{n}_cpu_s") + time.process_time() - self.c)


_SETUP_OPTIONS = ("model", "inertia", "fix", "free_inertia", "inertia_prior", "release_time",
                  "counts_per_rev", "max_substep", "ratio", "resolution")
_FIT_OPTIONS = (*_SETUP_OPTIONS, "n_starts", "max_steps", "start_from_model", "nested")
#: Options of the batch alone: ``lane_width``, lanes per call with ``lanes="logs"``
#: (default :func:`hdid._fitting._log_lanes.default_width`).
_BATCH_OPTIONS = ("lane_width",)


def fit_batch(
    items: Sequence[Any],
    *,
    lanes: int | str | None = DEFAULT_LANES,
    threads: int | None = None,
    wave: int = DEFAULT_WAVE,
    bracket: bool = False,
    on_done: Callable[[int, Any], None] | None = None,
    **options,
) -> tuple[list[Any], BatchTiming]:
    """Fit every log of ``items`` (each as :func:`hdid.fit` does, programs shared by
    length bucket).

    Returns the per-log outcomes (a :class:`~hdid.FitResult` or the exception that
    stopped that log), in input order, and a :class:`BatchTiming`. ``on_done(i, outcome)``
    is called as each log finishes. ``options`` are those of :func:`hdid.fit`; ``lanes``:
    starts per call of the LM program; ``threads``: threads fitting logs (default 1: JAX
    runs one CPU program at a time per process).
    """
    unknown = set(options) - set(_FIT_OPTIONS) - set(_BATCH_OPTIONS)
    if unknown:
        raise TypeError(f"fit_many: unknown option(s) {sorted(unknown)}; choose from "
                        f"{list(_FIT_OPTIONS)}")
    lane_width = options.pop("lane_width", None)
    if lanes is None:
        lanes = _log_lanes.default_lanes()
    if lanes != "logs" and (isinstance(lanes, str) or lanes < 1):
        raise ValueError(f"lanes = {lanes!r}: must be >= 1 (starts per call), or 'logs' "
                         "(the logs of a bucket as lanes, for a GPU)")
    threads = 1 if threads is None else max(int(threads), 1)
    timing = BatchTiming(lanes=lanes, threads=threads)
    outcomes: list[Any] = [None] * len(items)
    _, clock = _programs.phase_reporter(None)
    t0 = time.perf_counter()
    pool = ThreadPoolExecutor(threads) if threads > 1 else None
    buckets: set = set()
    try:
        for start in range(0, len(items), max(int(wave), 1)):
            idx = list(range(start, min(start + wave, len(items))))
            _fit_wave(items, idx, outcomes, pool, buckets, timing, lanes, bracket, on_done,
                      options, lane_width)
    finally:
        if pool is not None:
            pool.shutdown()
    timing.total_s = time.perf_counter() - t0
    timing.compile_s = min(clock()["compile_s"], timing.total_s)
    timing.n_logs = len(items)
    timing.n_failed = sum(isinstance(o, BaseException) for o in outcomes)
    timing.n_buckets = len(buckets)
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


def _fit_wave(items, idx, outcomes, pool, buckets: set, timing, lanes, bracket, on_done,
              options, lane_width=None):
    """Set up the logs ``idx`` (substeps shared), then fit each; the first log of every new
    length bucket runs alone (it compiles or reads that bucket's programs), the others on
    ``pool``'s threads where there is one."""
    setup_opts = {k: options[k] for k in _SETUP_OPTIONS if k in options}

    def done(i, outcome):
        outcomes[i] = outcome
        if on_done is not None:
            on_done(i, outcome)

    setups = {}
    with _Phase(timing, "setup"):
        for i in idx:
            try:
                setups[i] = _setup(items[i], **setup_opts)
            except LOG_ERRORS as exc:
                done(i, exc)
                continue
            # runs that move from their first samples: hdid.fit weighs both stories of
            # their first readings (:mod:`hdid._fitting._first_reading`); logs on no grid
            # (noise): hdid.fit searches in other weights than the likelihood's and
            # polishes (:mod:`hdid._fitting._polish`) — both through hdid.fit itself
            if (search_weight(setups[i].prep) is not setups[i].prep.weight
                    or _first_reading.candidates(items[i], setups[i].prep,
                                                 setup_opts.get("release_time"))):
                del setups[i]
                nested = options.get("nested")
                fit_opts = {**options, "nested": "auto" if nested is None else nested}
                try:
                    done(i, fit(items[i], **fit_opts))
                except LOG_ERRORS as exc:
                    done(i, exc)
        if setup_opts.get("max_substep") is None:
            _share_substeps(items, setups, setup_opts)
        padded = {i: pad_to_bucket(s.problem) for i, s in setups.items()}
    if lanes == "logs":
        with _Phase(timing, "setup"):
            # NumPy arrays: the host's work on each log (starts, analysis) reads them
            # without a device transfer each (on a GPU, ~20 µs a read)
            for i, st in setups.items():
                setups[i] = st._replace(problem=jax.tree_util.tree_map(np.asarray, st.problem))
                padded[i] = pad_to_bucket(setups[i].problem)
        _fit_lanes(items, setups, padded, buckets, timing, bracket, done, options, lane_width)
        return
    first, rest = [], []
    for i in setups:
        key = _bucket_key(padded[i])
        (rest if key in buckets else first).append(i)
        buckets.add(key)

    def one(i):
        done(i, _fit_log(items[i], setups[i], padded[i], options, lanes, bracket, timing))

    for i in first:
        one(i)
    if pool is None or len(rest) < 2:
        for i in rest:
            one(i)
    else:
        # worker threads do not inherit the caller's thread-local float64: enter it
        list(pool.map(float64(one), rest))


def _fit_log(item, setup, padded: Problem, options: dict, lanes: int, bracket: bool,
             timing: BatchTiming):
    """One log: :func:`hdid.fit`'s starts, local fits, restart and analysis on the padded
    problem ``padded``; the batch's limit check (:func:`_nested`). Returns the
    :class:`~hdid.FitResult`, or the exception that stopped it."""
    n_starts = int(options.get("n_starts", 6))
    max_steps = int(options.get("max_steps", 300))
    t_start = time.perf_counter()
    prep, model = setup.prep, setup.model
    try:
        with _Phase(timing, "grid"):
            U0, _ = _grid_starts(padded, prep, model, n_starts,
                                 bool(options.get("start_from_model", False)))
        with _Phase(timing, "solve"):
            U, costs, ok, steps = _local_fits(padded, U0, max_steps, lanes)
            retry = _untrapped(padded, prep, U[int(np.argmin(np.where(
                np.isfinite(costs), costs, np.inf)))])
            if retry is not None:
                U1, c1, ok1, s1 = _local_fits(padded, retry[None, :], max_steps, lanes)
                U, costs = np.concatenate([U, U1]), np.concatenate([costs, c1])
                ok, steps = np.concatenate([ok, ok1]), np.concatenate([steps, s1])
            timing.lane_steps += int(np.sum(steps))
        with _Phase(timing, "analyse"):
            res = _analysed(item, setup, padded, (U, costs, ok, steps), options, bracket,
                            t_start, n_first=len(U0))
        res = _settled(res, item, setup, padded, (U, costs, ok, steps), U0[0], options,
                       bracket, timing, t_start, lanes, len(U0))
        _check_finite(res)
    except LOG_ERRORS as exc:
        return exc
    return res


def _analysed(item, setup, padded: Problem, solutions, options: dict, bracket: bool,
              t_start: float, pre=None, n_first: int | None = None):
    """The :class:`~hdid.FitResult` of the local fits ``solutions`` ``(U, costs, ok,
    steps)``: the analysis' JAX parts at the best row on the padded problem (``pre``
    where already computed), the rest on the log's own (:func:`_finish`), then the
    batch's limit check (:func:`_nested`; ``n_first``: the log's number of grid starts)."""
    U, costs, ok, steps = solutions
    finite = np.isfinite(costs)
    if pre is None and finite.any():
        pre = _unpad(_stored_analysis(padded, U[int(np.argmin(np.where(
            finite, costs, np.inf)))]), setup.problem)
    res = _finish(setup, U, costs, ok, steps, t_start, bracket=bracket, precomputed=pre)
    return _nested(res, item, setup, options, int(options.get("n_starts", 6)),
                   int(options.get("max_steps", 300)), solutions, n_first)


def _settled(res, item, setup, padded: Problem, solutions, start, options: dict,
             bracket: bool, timing: BatchTiming, t_start: float, lanes: int = LANES,
             n_first: int | None = None):
    """:func:`hdid.fit`'s steps after its local fits, by the same functions: the restarts
    of an optimum whose cubic went to 0, whose release stuck on its bracket's end or whose
    swing sits on an alias above the log's Nyquist frequency
    (:func:`hdid._fitting._cubic_restart.restarted`, one start at a time on the padded
    problem, the lower kept), then the refit at the RK4 substep the fitted swing wants
    where the log's substep clearly under-resolves it
    (:func:`hdid._fitting._substep.refined`: this batch's own steps again, warm from the
    fitted model, at that substep). A log that needs none of them costs a few NumPy
    checks. ``start``: the first start (the data's release guesses); ``lanes``: starts per
    call of the restarts' Levenberg–Marquardt program; ``n_first``: the log's number of
    grid starts (the limit checks' schedule, :func:`_nested`)."""
    max_steps = int(options.get("max_steps", 300))
    prob, prep, model = setup.problem, setup.prep, setup.model
    with _Phase(timing, "solve"):
        res, _ = _cubic_restart.restarted(
            res, prob, model, log_scales(prep, model, np.asarray(prob.offset0)), solutions,
            lambda U0: _local_fits(padded, U0, max_steps, lanes),
            lambda sol: _analysed(item, setup, padded, sol, options, bracket, t_start,
                                  n_first=n_first),
            log_hz=prep.frequency_hz, start=np.asarray(start))

    def again(log, **opts):  # this log through the batch's own steps at another substep
        s = _setup(log, **{k: opts[k] for k in _SETUP_OPTIONS if k in opts})
        out = _fit_log(log, s, pad_to_bucket(s.problem), opts, lanes, bracket, timing)
        if isinstance(out, BaseException):
            raise out
        return out

    return _substep.refined(res, item, options, again)


def _fit_lanes(items, setups: dict, padded: dict, buckets: set, timing, bracket, done,
               options, lane_width=None):
    """``lanes="logs"``: each bucket's logs fitted together (:mod:`._log_lanes`), then
    each log's analysis and the batch's limit check (:func:`_nested`) on the host."""
    groups: dict = {}
    for i in setups:
        key = _bucket_key(padded[i])
        buckets.add(key)
        groups.setdefault(key, []).append(i)
    for idx in groups.values():
        t_start = time.perf_counter()
        width = int(lane_width or _log_lanes.default_width(padded[idx[0]]))
        fitted = _log_lanes.fit_bucket([setups[i] for i in idx], [padded[i] for i in idx],
                                       options, width, timing, lambda n: _Phase(timing, n))
        for i, f in zip(idx, fitted):
            if isinstance(f, BaseException):
                if not isinstance(f, LOG_ERRORS):
                    raise f
                done(i, f)
                continue
            try:
                U, costs, ok, steps, pre, start, n_first = f
                sol = (U, costs, ok, steps)
                with _Phase(timing, "analyse"):
                    res = _analysed(items[i], setups[i], padded[i], sol, options, bracket,
                                    t_start, None if pre is None else _unpad(
                                        pre, setups[i].problem), n_first)
                res = _settled(res, items[i], setups[i], padded[i], sol, start, options,
                               bracket, timing, t_start, n_first=n_first)
                _check_finite(res)
            except LOG_ERRORS as exc:
                res = exc
            done(i, res)


def _local_fits(problem: Problem, U0, max_steps: int, lanes: int):
    """:func:`hdid._fitting._one_lane._local_fits`: ``(U, costs, ok, steps)``."""
    return _one_lane(problem, U0, max_steps, lanes)[:4]


def _nested(res, item, setup, options: dict, n_starts: int, max_steps: int, solutions=None,
            n_first: int | None = None):
    """fit()'s check against its model's limits (:mod:`hdid._fitting._limits`: the nested
    Coulomb case, no friction, the linear spring) by :func:`hdid._fitting._fit.nested_check`,
    one log at a time, as :func:`hdid.fit` calls it (with the local fits ``solutions`` on
    the padded problem, whose costs are the log's own up to rounding, and ``n_first``, the
    log's number of grid starts, as hdid.fit's ``lanes``: above the floor each limit then
    gets ``n_first − 1`` grid starts, its rows scheduled ``n_first`` at a time — without
    it the batch's checks had 2 grid starts a limit in one schedule, other starts and other
    optima than hdid.fit's on the same log):
    ``nested="auto"`` when the residual is above the floor or a term may vanish, ``True``
    always, ``False`` never. The batch's default (``None``) runs it, as ``"auto"`` does,
    exactly where the residual has not reached the floor
    (:func:`hdid._fitting._limits.reached_floor`, the 99.9 % point of the floor's χ²_ν, at
    least 1.2×: every limit and the restarts next to their optima), and leaves a fit at the
    floor as it is (its verdicts on a vanishing term only, which cost most logs of a batch
    their time: 1000 paper logs took 538 s in one process with ``"auto"`` against 228 s
    without it, load 2.4–3.9). Without the check 20 stiff-gear paper logs reached the floor
    in 0 (hdid.fit: 13)."""
    nested = options.get("nested")
    if nested is None:
        if reached_floor(res) or not needs_check(res, setup.fixed):
            return res
        nested = "auto"
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
                        max_steps=max_steps, solutions=solutions, lanes=n_first)


def _check_finite(res) -> None:
    from .._errors import FitError

    bad = [n for n, p in res.parameters.items() if not math.isfinite(p.value)]
    if bad or not math.isfinite(res.rms_residual_rad):
        raise FitError(
            f"{res.source}: the fit ended at non-finite values ({', '.join(bad) or 'RMS'}); "
            "check units (rad vs counts) and --inertia, or fix some parameters"
        )


# ----------------------------------------------------------------------------- buckets


def pad_to_bucket(problem: Problem) -> Problem:
    """``problem`` with every run padded to the next multiple of ``PAD_SAMPLES`` samples:
    the last sample repeated (a zero-length interval), weight 0 (a zero residual)."""
    n = problem.times.shape[1]
    T = PAD_SAMPLES * math.ceil(n / PAD_SAMPLES)
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
    """What decides a problem's programs besides its arrays' values: its tree (model
    structure, free parameters, static fields) and its arrays' shapes and dtypes."""
    leaves, treedef = jax.tree_util.tree_flatten(problem)
    return treedef, tuple((np.shape(x), np.asarray(x).dtype.str) for x in leaves)


def _unpad(pre: dict, problem: Problem) -> dict:
    """The analysis parts computed on the padded problem
    (:func:`hdid._fitting._fit._stored_analysis`), cut back to the log's own samples."""
    J, r = pre["jacobian"]
    R, T = problem.times.shape
    Tp = J.shape[0] // R
    J = J.reshape(R, Tp, -1)[:, :T].reshape(R * T, -1)
    r = r.reshape(R, Tp)[:, :T].reshape(-1)
    dense = tuple(np.asarray(x)[:, :T] for x in pre["dense"])
    return {"jacobian": (J, r), "dense": dense, "derived": pre["derived"]}
