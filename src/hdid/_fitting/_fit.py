"""Joint least-squares fit of a model to every run of a free-motion log."""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Iterable, Mapping
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from .._errors import FitError
from .._problems._evaluate import dense as _dense
from .._problems import _programs
from ._identifiability import MOVED_COUNTS, analyse, analyse_first_finite
from .._log import Log, read_log
from .._models._model import Model
from . import _cubic_restart, _first_reading, _limits, _polish, _substep
from ._substep import substep_for  # (the substep rule; hdid._design asks it here too)
from .._simulation._prepare import Prepared, offset_guess, prepare
from .._problems._problem import OFFSET_SCALE_REL, Problem, build_problem
from .._results._result import FitResult
from .._results._summaries import StartSummary
from .._models._transforms import interval_to_u, to_unconstrained
from ..effects import order_of_magnitude
from ._lm import PHASE1_STEPS, LMState
from ._one_lane import LANES, _call_args, _solve_lanes, _stored_solve
from ._one_lane import _local_fits as _one_lane
from ._pendulum import pendulum_prepared
from ._starts import (_choose_starts, _costs, _grid_candidates, _grid_starts, grid_costs,
                      log_scales)


def fit(
    log: Log | str | os.PathLike | object,
    model: Model | None = None,
    *,
    inertia: float | None = None,
    fix: Mapping[str, float] | Iterable[str] | None = None,
    free_inertia: bool | None = None,
    inertia_prior: tuple[float, float] | None = None,
    release_time: float | None = None,
    counts_per_rev: float | None = None,
    ratio: float | None = None,
    resolution: float | None = None,
    n_starts: int = 6,
    max_substep: float | None = None,
    max_steps: int = 300,
    start_from_model: bool = False,
    nested: bool | str = "auto",
) -> FitResult:
    """Fit stiffness, friction (and optionally inertia) to all runs of a log jointly.

    Parameters
    ----------
    log:
        A :class:`~hdid.Log`, a CSV path or a pandas DataFrame (see :func:`hdid.read_log`).
    model:
        Structure and starting/fixed values; default :meth:`Model.default`.
    inertia:
        Total inertia at the wave generator [kg m²] (default: the model's, i.e. the
        CSF-8 + small-motor datasheet value 7e-7). Free motion fixes only torques
        *relative to* the inertia, so this sets the absolute scale.
    fix:
        Parameters held fixed: names (at the model's value) or ``{name: value}``.
    free_inertia:
        Fit the inertia too. Only meaningful with runs of different known
        ``added_inertia`` or with ``inertia_prior``; default: free exactly when the
        runs' added inertias differ.
    inertia_prior:
        ``(mean, relative_sd)`` — a log-normal prior on the inertia (e.g. a datasheet
        value ±30 %).
    release_time:
        Known release instant [s] in each run's time axis (otherwise fitted per run).
    counts_per_rev:
        Convert a log of raw encoder counts.
    ratio:
        Gear ratio N between the logged axis and the output (default: the model's, 100;
        1 when the logged angle is the output's).
    resolution:
        Sensor step of ``theta`` in the log's units (default: from the readings' grid,
        else the noise is estimated from the log and the report says so).
    n_starts:
        Local fits started from the best points of a coarse data-driven grid.
    max_substep:
        Longest RK4 substep [s] (default 0.5 ms).
    max_steps:
        Levenberg–Marquardt iteration limit per start.
    start_from_model:
        Also start from the model's own values (a warm start, e.g. a fitted model with
        an effect added, as :func:`hdid.diagnose` does); that start is always run.
    nested:
        Check the model's nested limits (:mod:`hdid._fitting._limits`: Coulomb friction
        ``tau_s = tau_c``, no dry friction, the linear spring ``k2 = 0``): fit each, restart
        the full model next to its optimum (and, still above the floor, from regular
        Stribeck laws at its sliding level), keep the best; ``result.limits`` records each
        limit's χ² and whether it fits as well (then a warning names it, e.g. "friction
        not supported: the viscous-only model fits as well"). ``"auto"`` (default) checks
        every limit when the residual is above the floor
        (:func:`hdid._fitting._limits.above_floor`) and, at the floor, the limits whose
        term may vanish (relative sd above ``VANISH_REL_SD``, or ``tau_s ≤ tau_c``); the
        limits are prior rows on the fit's own problem (one-lane programs of its
        structure, no model of their own). ``True`` always, ``False`` never.
    """
    t_start = time.perf_counter()
    if nested not in (True, False, "auto"):
        raise ValueError(f"nested = {nested!r}: use True, False or 'auto'")
    if not isinstance(log, Log):
        log = read_log(log, counts_per_rev=counts_per_rev, resolution=resolution)
    elif resolution is not None:  # the log carries it (also into the nested refits)
        log = dataclasses.replace(log, resolution=float(resolution), resolution_source="given")
    counts_per_rev = resolution = None
    given = dict(model=model, inertia=inertia, fix=fix, free_inertia=free_inertia,
                 inertia_prior=inertia_prior, release_time=release_time, ratio=ratio,
                 n_starts=n_starts, max_substep=max_substep, max_steps=max_steps,
                 start_from_model=start_from_model, nested=nested)
    setup = _setup(
        log, model, inertia=inertia, fix=fix, free_inertia=free_inertia,
        inertia_prior=inertia_prior, release_time=release_time,
        counts_per_rev=counts_per_rev, max_substep=max_substep, ratio=ratio,
        resolution=resolution,
    )
    # the search's weights (a noisy log's stuck tails as one observation each), then the
    # optimum polished in the likelihood's own (:mod:`._polish`)
    search = _polish.searching(setup)
    problem, prep, model = search.problem, search.prep, search.model
    _prefetch(problem)

    U0, grid_cost = _grid_starts(problem, prep, model, n_starts, start_from_model)
    U, costs, ok, steps = _local_fits(problem, U0, max_steps)
    retry = _untrapped(problem, prep, U[int(np.argmin(np.where(np.isfinite(costs), costs,
                                                                np.inf)))])
    if retry is not None:
        U, costs, ok, steps = (np.concatenate(p) for p in zip(
            (U, costs, ok, steps), _local_fits(problem, retry[None, :], max_steps)))
    result = _finish(search, U, costs, ok, steps, t_start)
    checks = dict(nested=nested, fix=fix, inertia_prior=inertia_prior,
                  release_time=release_time, max_substep=max_substep, n_starts=n_starts,
                  max_steps=max_steps, lanes=len(U0))
    result = nested_check(result, log, search, solutions=(U, costs, ok, steps), **checks)
    result, (U, costs, ok, steps) = _cubic_restart.restarted(
        result, problem, model, log_scales(prep, model, np.asarray(problem.offset0)),
        (U, costs, ok, steps), lambda U0: _local_fits(problem, U0, max_steps), lambda sol:
        nested_check(_finish(search, *sol, t_start), log, search, solutions=sol, **checks),
        log_hz=prep.frequency_hz, start=np.asarray(U0)[0])
    if search is not setup:
        result = _polish.polished(
            result, setup.problem, (U, costs, ok, steps), lambda U0: _local_fits(
                setup.problem, U0, max_steps), lambda *sol: _finish(setup, *sol, t_start),
            lambda res, sol: nested_check(res, log, setup, solutions=sol, **checks))
    # runs that move from their second sample: is their first reading the hold?
    held = _first_reading.candidates(log, prep, release_time)
    if held:
        result = _first_reading.choose(
            result, fit(dataclasses.replace(log, first_reading_held=held), **given), held)
    result = _substep.refined(result, log, given, fit)  # a substep the fitted swing wants
    result.wall_time_s = time.perf_counter() - t_start
    return result


def nested_check(result: FitResult, log: Log, setup: _Setup, *, nested="auto", fix=None,
                 inertia_prior=None, release_time=None, max_substep=None, n_starts: int = 6,
                 max_steps: int = 300, solutions=None, lanes: int | None = None) -> FitResult:
    """The fit of ``log`` checked against its model's limits (:mod:`hdid._fitting._limits`:
    Coulomb, no dry friction, linear spring): each wanted limit fitted, the full model
    restarted next to its optimum, the best kept, every limit recorded in
    ``result.limits``. ``nested`` True: every limit; ``"auto"``: every limit when the
    residual has not reached the floor, else those whose term may vanish; False: none.
    ``solutions`` ``(U, costs, ok, steps)``: the full model's local fits (default: the
    result's optimum alone); ``lanes``: the number of the fit's starts — each limit then
    gets ``lanes − 1`` grid starts beside the fit's optimum and its rows are scheduled
    ``lanes`` at a time (what the fit's former ``lanes``-wide program did), else
    ``_limits.LIMIT_GRID_STARTS`` grid starts in one schedule (diagnose, the batch, the
    posterior, and every fit at the floor, where a limit is a verdict only and its schedule
    also stops the starts far above its verdict line: :class:`hdid._fitting._lm._Schedule`).
    Either way every start runs through the one-lane program of the model's structure
    (:mod:`hdid._fitting._one_lane`), as the fit's own. Options as in :func:`fit`."""
    if nested not in (True, False, "auto"):
        raise ValueError(f"nested = {nested!r}: use True, False or 'auto'")
    del n_starts  # (the limits' own grids are ``_limits.LIMIT_GRID_STARTS`` wide)
    wanted = _limits.wanted(result, setup.fixed, nested)
    if not hasattr(result, "limits"):
        result.limits, result.restarted_from = [], None
    if not wanted:
        return result
    problem = setup.problem
    t_start = time.perf_counter() - (result.wall_time_s if math.isfinite(result.wall_time_s)
                                     else 0.0)
    if solutions is None:
        u = np.asarray(result.u, dtype=float)[None, :]
        c = np.asarray(_costs(problem, jnp.asarray(u)), dtype=float)
        solutions = (u, c, np.ones(1, dtype=bool), np.zeros(1, dtype=int))
    del log, fix, inertia_prior, release_time, max_substep  # the limits live in ``setup``
    # The limits are prior rows on the fit's own problem: they share its programs (the
    # one-lane LM program, one compile per model structure, kept in the program store).

    switch = _limits.KEEP_BETTER_AT_FLOOR or not _limits.reached_floor(result)
    # at the floor a limit is a verdict: its fit stops once an optimum decides it, or once
    # every start lies a clearly worse basin above its verdict line (_lm._Schedule)
    stop = -np.inf if switch else _limits.verdict_cost(result, solutions)
    fit_cost = _limits._cost_of(result, *solutions[:2])

    def local_fits(p, U0, stop=-np.inf, line=np.inf):
        # ``lanes`` rows a schedule (the fit's former ``lanes``-wide program: a short group
        # padded with copies of its first row, computed once), else one schedule for all
        return _one_lane(p, np.asarray(U0, dtype=float), max_steps,
                         group=(lanes or None) if switch else None, stop_below=stop,
                         verdict_line=line)[:4]

    model, prep = setup.model, setup.prep
    scales = log_scales(prep, model, np.asarray(problem.offset0))
    u_fit = np.asarray(result.u, dtype=float)
    grid_U, grid_keys = _grid_candidates(problem, prep, model, False)

    def fit_limit(limit):
        pins = limit.pins(result.values, scales)
        p = _limits.pinned(problem, model, pins)
        # the limit's starts: the fit's optimum and the best of the grid, held at the limit
        U = _limits.with_values_rows(problem, model, np.concatenate([u_fit[None, :], grid_U]),
                                     lambda v: limit.start(v, scales), pins)
        cost = grid_costs(p, U[1:])
        # at the floor (a verdict only) the batch's few grid starts beside the fit's optimum
        n_grid = max(lanes - 1, 1) if lanes and switch else _limits.LIMIT_GRID_STARTS
        U0, _ = _choose_starts(U[1:], cost, grid_keys, n_grid, False)
        U0 = np.concatenate([U[:1], np.asarray(U0)])
        line = np.inf if switch else fit_cost + _limits._chi2_ppf(_limits.LIMIT_LEVEL,
                                                                   len(limit.removed))
        Un, cn, _, _ = local_fits(p, U0, stop, line)
        cn = np.where(np.isfinite(cn), cn, np.inf)
        b = int(np.argmin(cn))
        retry = _untrapped(p, prep, Un[b]) if np.isfinite(cn[b]) else None
        if retry is not None:  # a limit that never releases runs the log shows moving
            Ur, cr, _, _ = local_fits(p, retry[None, :])
            Un, cn = np.concatenate([Un, Ur]), np.concatenate([cn, np.where(
                np.isfinite(cr), cr, np.inf)])
            b = int(np.argmin(cn))
        if not np.isfinite(cn[b]):
            return None
        values = {**model.float_values(), **problem.values_np(Un[b])}
        return _limits.LimitOutcome(limit, _limits.data_chi2(p, Un[b], cn[b]), values,
                                    np.asarray(Un[b]))

    def restart(limit, out):
        rows = [_limits.with_values(problem, model, out.u, nudge)
                for nudge in limit.restarts(out.values, scales)]
        return local_fits(problem, np.asarray(rows))

    def finish(U, costs, ok, steps):
        return _finish(setup, U, costs, ok, steps, t_start)

    floor = (_limits.above_floor(result.n_effective, result.n_unknowns)
             * result.quantization_floor_rad)

    def again(u, cost):  # still above the floor (or c_v → 0): regular Stribeck restarts
        v = {**model.float_values(), **problem.values_np(u)}
        if not (_data_rms(problem, u, cost) > floor
                or _limits.viscous_gone(v, scales, setup.fixed)):
            return None
        rows = [_limits.with_values(problem, model, u, r)
                for r in _limits.stribeck_restarts(v, scales, setup.fixed)]
        return local_fits(problem, np.asarray(rows)) if rows else None

    return _limits.check(result, solutions, wanted, fit_limit, restart, finish, switch, again)


def _local_fits(problem: Problem, U0, max_steps: int):
    """Levenberg–Marquardt from every row of ``U0``, one start at a time through the one-lane
    program of the problem's structure (:mod:`._one_lane`): ``(U, costs, ok, steps)``."""
    return _one_lane(problem, U0, max_steps)[:4]


def _data_rms(problem: Problem, u, cost: float) -> float:
    """The weighted RMS data residual [log units] at ``u`` from its cost (data χ² plus the
    prior rows), as :func:`analyse` reports it (``rms_residual_rad``)."""
    P = problem.n_physical
    z = (np.asarray(u)[:P] - np.asarray(problem.prior_mean)) / np.asarray(problem.prior_sd)
    chi2 = float(cost) - float(np.sum(np.where(np.asarray(problem.prior_on), z, 0.0) ** 2))
    w2 = float(np.sum(np.asarray(problem.weight) ** 2))
    return float(problem.sigma) * math.sqrt(max(chi2, 0.0) / w2)


def trapped_runs(problem: Problem, prep: Prepared, u) -> np.ndarray:
    """Runs the model never releases at ``u`` (exact stick: speed 0 at every sample)
    although the log shows them moving (rest ≠ hold by more than ``MOVED_COUNTS``)."""
    # jitted (an eager call compiled a fresh `while` program every fit and leaked its maps)
    _, omega, _ = _stored_dense(problem, u)
    moved = np.abs(prep.rest - prep.hold) > MOVED_COUNTS * prep.resolution
    return np.flatnonzero(moved & (np.max(np.abs(omega), axis=1) == 0.0))


def _untrapped(problem: Problem, prep: Prepared, u):
    """A restart for an optimum that holds runs the log shows moving, or ``None``.

    Such a run has a zero gradient in its release and start angle: once a stick band tried
    on the way exceeds its start angle, the fit moves the start angle to a compromise
    between the hold and the rest readings, deep in the band, and cannot come back (seen
    with ±0.05 rad releases just outside a 0.048 rad band). The restart puts those runs'
    start angles back at their hold readings, from the other parameters of ``u``."""
    trapped = trapped_runs(problem, prep, u)
    if trapped.size == 0:
        return None
    v = np.array(u, dtype=float)
    i = problem.n_physical
    if problem.release_free:  # the release instant drifted too: back to the data's guess
        lo, hi = np.asarray(problem.release_lo), np.asarray(problem.release_hi)
        guess = interval_to_u(prep.release_guess, lo, hi)
        v[i + trapped] = np.asarray(guess)[trapped]
        i += problem.n_runs
    v[i + trapped] = 0.0  # θ0 = hold − offset
    return v


class _Setup(NamedTuple):
    """A log made ready to fit: its arrays, the model and the least-squares problem."""

    prep: Prepared
    model: Model
    problem: Problem
    fixed: frozenset


def _setup(
    log, model=None, *, inertia=None, fix=None, free_inertia=None, inertia_prior=None,
    release_time=None, counts_per_rev=None, max_substep=None, ratio=None, resolution=None,
) -> _Setup:
    """Read and prepare a log and build its :class:`Problem` (options as in :func:`fit`)."""
    if not isinstance(log, Log):
        log = read_log(log, counts_per_rev=counts_per_rev, resolution=resolution)
    elif resolution is not None:
        log = dataclasses.replace(log, resolution=float(resolution), resolution_source="given")
    prep = prepare(log, release_time=release_time)

    model = Model.default() if model is None else model
    if ratio is not None:
        model = model.with_ratio(ratio)
    if inertia is not None:
        if not inertia > 0:
            raise ValueError(f"inertia = {inertia!r}: must be > 0 kg m^2")
        model = model.replace(inertia=float(inertia))
    fixed_values = _fixed_values(model, fix)
    if fixed_values:
        model = model.replace(**fixed_values)
    specs = model.parameter_specs()
    added_varies = np.ptp(prep.added_inertia) > 0
    if free_inertia is None:
        free_inertia = bool(added_varies) and inertia is None and "inertia" not in fixed_values
    free = tuple(
        n for n in specs if n not in fixed_values and (n != "inertia" or free_inertia)
    )
    priors = {n: specs[n].prior for n in free if specs[n].prior is not None}
    if inertia_prior is not None and "inertia" in free:
        mean, rel = inertia_prior
        priors["inertia"] = (math.log(mean), rel)

    # a pendulum drop: release, zero and swing frequency from its swings (_pendulum.py)
    prep, offset0 = pendulum_prepared(prep, model, offset_guess(prep), release_time is not None)
    n_data = int(np.sum(prep.weight > 0))
    sub = substep_for(prep.frequency_hz) if max_substep is None else float(max_substep)
    scales = log_scales(prep, model, offset0)
    model = model.with_scales(scales)
    specs = model.parameter_specs()
    for n, (mean, sd) in list(priors.items()):  # centred on the log's own scale
        if mean is None:
            start = specs[n].start(scales) if specs[n].start else model.float_values()[n]
            priors[n] = (float(to_unconstrained(specs[n], start)), sd)
    all_moving = prep.moving_start is not None and bool(np.all(prep.moving_start))
    problem = build_problem(
        prep, model, free, offset0, sub, release_time is not None or all_moving, priors,
        offset_scale=order_of_magnitude(OFFSET_SCALE_REL * scales.amplitude),
        vel_scale=order_of_magnitude(scales.speed),
    )
    if n_data <= problem.n_unknowns:
        raise FitError(
            f"{prep.source}: {n_data} samples but {problem.n_unknowns} unknowns; "
            "log more samples per run, add runs, or fix parameters (fix=/--fix)"
        )
    return _Setup(prep, model, problem, frozenset(set(specs) - set(free)))


def _finish(setup: _Setup, U, costs, ok, steps, t_start: float, **analyse_options) -> FitResult:
    """Analyse the best of the local fits (``analyse_options`` go to :func:`analyse`)."""
    problem, prep = setup.problem, setup.prep
    finite = np.isfinite(costs)
    if not finite.any():
        raise FitError(
            f"{prep.source}: every start diverged (non-finite residuals); check units "
            "(rad vs counts) and --inertia, or fix some parameters"
        )
    order = np.argsort(np.where(finite, costs, np.inf))[: int(finite.sum())]
    result, best = analyse_first_finite(
        problem, prep, U, order, lambda i: StartSummary.from_solutions(
            problem, U, costs, ok, steps, i), lambda u: _stored_analysis(problem, u),
        set(setup.fixed), **analyse_options)
    result.wall_time_s = time.perf_counter() - t_start
    if not ok[best]:
        result.warnings.append(
            f"the best start stopped after {int(steps[best])} iterations without meeting "
            "the convergence tolerance; results may not be at the optimum"
        )
    return result


def _prefetch(problem: Problem) -> None:
    """Start reading the stored programs the fit calls after its grid (the one-lane
    Levenberg–Marquardt program, then :func:`_stored_dense`'s and the derived
    quantities') in the program store's background thread
    (:func:`hdid._problems._programs.prefetch`: the XLA cache reads release the GIL), while
    this thread computes the grid's costs and the first starts; nothing where they are
    loaded already or not stored."""
    n = int(problem.n_unknowns)
    m = int(np.prod(problem.times.shape)) + problem.n_physical
    state = LMState(*(np.asarray(f) for f in LMState.empty(LANES, m, n)))
    _programs.prefetch("solve_lanes", _solve_lanes, problem, *_call_args(
        np.zeros((LANES, n)), np.ones(LANES, dtype=bool), PHASE1_STEPS, state))
    u = jnp.zeros(n)
    _programs.prefetch("dense", _dense, problem, u, problem.times)
    _programs.prefetch("derived", _derived_and_jacobian, problem, u)


def _stored_dense(problem: Problem, u):
    """``(theta, omega, stuck)`` at ``u`` on the log's samples, NumPy, through the
    program store's ``dense`` program (:mod:`hdid._problems._programs`: a later process
    reads it instead of tracing; the residual frame shares it)."""
    out = _programs.call("dense", _dense, problem, jnp.asarray(u), problem.times)
    return tuple(np.asarray(a) for a in out)


def _derived_and_jacobian(problem: Problem, u):
    """The derived quantities at ``u`` and their Jacobian in the physical unknowns."""
    return problem.derived_and_jacobian(u)


def _lm_residuals_and_jacobian(problem: Problem, u):
    """The data residuals ``r`` and their Jacobian ``J`` at ``u`` from the fit's own
    one-lane Levenberg–Marquardt program (a fresh lane evaluates both at its start and,
    with an iteration budget of one, stops there): no program of their own to trace,
    compile or read (the same function, :meth:`Problem.data_residuals_and_jacobian`,
    inside it; the prior rows after the data rows are dropped)."""
    n = int(problem.n_unknowns)
    m_data = int(np.prod(problem.times.shape))
    state = LMState(*(np.asarray(f) for f in LMState.empty(LANES, m_data + problem.n_physical, n)))
    *_, state = _stored_solve(problem, *_call_args(np.asarray(u, dtype=float)[None, :],
                                                   np.ones(LANES, dtype=bool), 1, state))
    return np.asarray(state[1])[0][:m_data], np.asarray(state[0])[0][:m_data]


def _stored_analysis(problem: Problem, u) -> dict:
    """:func:`analyse`'s ``precomputed`` parts at ``u`` without a program of the analysis'
    own to trace or compile in a new process: the Jacobian from the fit's LM program
    (:func:`_lm_residuals_and_jacobian`), the trajectory from :func:`_stored_dense`'s
    (already loaded by :func:`trapped_runs`), the derived quantities from a small stored
    program (``derived``)."""
    derived = _programs.call("derived", _derived_and_jacobian, problem, jnp.asarray(u))
    return {"jacobian": _lm_residuals_and_jacobian(problem, u),
            "dense": _stored_dense(problem, u),
            "derived": jax.tree_util.tree_map(np.asarray, derived)}


def _fixed_values(model: Model, fix) -> dict[str, float]:
    if fix is None:
        return {}
    specs = model.parameter_specs()
    current = model.float_values()
    items = fix.items() if isinstance(fix, Mapping) else ((n, None) for n in fix)
    out = {}
    for name, value in items:
        if name not in specs:
            raise KeyError(f"fix: unknown parameter {name!r}; choose from {list(specs)}")
        out[name] = current[name] if value is None else float(value)
    return out


def first_reading_story(log, model, options: dict):
    """``log`` carrying :func:`fit`'s story of its runs' first readings (and its note),
    for callers that fit it in their own way (:func:`hdid.diagnose`): two full fits, only
    where a run's first reading could be a hold; ``log`` itself otherwise."""
    if not _first_reading.candidates(log, prepare(log), options.get("release_time")):
        return log
    res = fit(log, model, **{k: v for k, v in options.items() if k in _STORY_KEYS})
    if not res.first_reading_held:
        return log
    note = next(w for w in res.warnings if _first_reading.NOTE_MARK in w)
    return dataclasses.replace(log, first_reading_held=tuple(res.first_reading_held),
                               notes=log.notes + (note,))


_STORY_KEYS = ("inertia", "fix", "free_inertia", "inertia_prior", "release_time",
               "max_substep", "ratio", "n_starts", "max_steps")
