"""Joint least-squares fit of a model to every run of a free-motion log."""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Iterable, Mapping
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import lineax as lx
import optimistix as optx

from . import _config  # noqa: F401
from ._errors import FitError
from ._identifiability import MOVED_COUNTS, _dense, analyse
from ._io import Log, read_log
from ._model import DEFAULT_INERTIA, Model
from ._nested import NESTED_STARTS, against_nested, needs_check, stribeck_pair
from ._prepare import Prepared, offset_guess, prepare
from ._problem import OFFSET_SCALE_REL, Problem, build_problem, with_jacobian
from ._result import FitResult, StartSummary
from ._simulate import DEFAULT_MAX_SUBSTEP
from ._transforms import interval_to_u, to_unconstrained
from .effects import Scales, order_of_magnitude

#: Natural frequency [Hz] at which the default substep (``DEFAULT_MAX_SUBSTEP``) was
#: validated against the event-driven reference (error 0.04 of the 250 Hz quantization
#: floor); other logs scale the substep by powers of two to keep ``h·ω_n`` about the same.
SUBSTEP_REFERENCE_HZ = 60.0

#: Frequencies of the coarse grid that seeds the local fits, relative to the log's own
#: oscillation frequency (from its turning points, ``Prepared.frequency_hz``): the span
#: of the grid validated on CSF-8 logs (15–400 Hz about their ~60 Hz), now centred on
#: each log; a factor 4 below and 6.7 above covers a poor estimate (a 250 Hz log sees a
#: 60 Hz swing in 4 samples).
GRID_FREQUENCY_FACTORS = np.geomspace(0.25, 6.7, 12)
#: Coulomb friction removes 2·tau_c/k of amplitude per half-cycle, so the logged start and
#: rest angles give tau_c ≈ k·(|θ0| − |θ_rest|)/(2n) for n half-cycles to rest.
GRID_HALF_CYCLES = np.array([1, 2, 3, 4, 6])
#: ... and, for designs mixing amplitudes, fixed fractions of the spring torque at release.
GRID_COULOMB_FRACTIONS = np.array([0.02, 0.05, 0.1, 0.18, 0.3])
#: The grid's cost at a few samples per period is dominated by phase errors, so a
#: candidate near the true frequency can score no better than one whose model never
#: leaves the hold; half the starts therefore come from the frequencies within this factor
#: of the log's own (a paper-design log, seed 7001: truth at 1.30× the log's estimate, the
#: cost-ranked starts all stuck at 1.5–6.7× and the fit ended at 14.7× the floor).
GRID_NEAR_FACTOR = 1.6


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
        With a free Stribeck law, also fit its nested Coulomb case (``tau_s = tau_c``)
        and restart from that optimum when the general law ended worse
        (:mod:`hdid._nested`); a warning says when it stays worse. ``"auto"`` (default)
        checks only a fit that shows a symptom — a residual above twice the noise floor,
        a non-finite standard error of the law, ``tau_s ≤ tau_c`` — since the check costs
        a second model structure (~4 s of tracing on a cold start); ``True`` always,
        ``False`` never.
    """
    t_start = time.perf_counter()
    if nested not in (True, False, "auto"):
        raise ValueError(f"nested = {nested!r}: use True, False or 'auto'")
    if not isinstance(log, Log):
        log = read_log(log, counts_per_rev=counts_per_rev, resolution=resolution)
    elif resolution is not None:  # the log carries it (also into the nested refits)
        log = dataclasses.replace(log, resolution=float(resolution), resolution_source="given")
    counts_per_rev = resolution = None
    setup = _setup(
        log, model, inertia=inertia, fix=fix, free_inertia=free_inertia,
        inertia_prior=inertia_prior, release_time=release_time,
        counts_per_rev=counts_per_rev, max_substep=max_substep, ratio=ratio,
        resolution=resolution,
    )
    problem, prep, model = setup.problem, setup.prep, setup.model

    U0, grid_cost = _grid_starts(problem, prep, model, n_starts, start_from_model)
    U, costs, ok, steps = _local_fits(problem, U0, max_steps)
    retry = _untrapped(problem, prep, U[int(np.argmin(np.where(np.isfinite(costs), costs,
                                                                np.inf)))])
    if retry is not None:
        U1, c1, ok1, s1 = _local_fits(problem, retry[None, :], max_steps)
        U, costs = np.concatenate([U, U1]), np.concatenate([costs, c1])
        ok, steps = np.concatenate([ok, ok1]), np.concatenate([steps, s1])
    result = _finish(setup, U, costs, ok, steps, t_start)
    result = nested_check(result, log, setup, nested=nested, fix=fix,
                          inertia_prior=inertia_prior, release_time=release_time,
                          max_substep=max_substep, n_starts=n_starts, max_steps=max_steps)
    result.wall_time_s = time.perf_counter() - t_start
    return result


def nested_check(result: FitResult, log: Log, setup: _Setup, *, nested="auto", fix=None,
                 inertia_prior=None, release_time=None, max_substep=None, n_starts: int = 6,
                 max_steps: int = 300) -> FitResult:
    """:func:`hdid._nested.against_nested` for a fit of ``log`` (options as in :func:`fit`):
    ``nested`` True always, ``"auto"`` on a symptom (:func:`hdid._nested.needs_check`)."""
    if nested not in (True, False, "auto"):
        raise ValueError(f"nested = {nested!r}: use True, False or 'auto'")
    if not (nested is True and stribeck_pair(result.model, setup.fixed) is not None
            or nested == "auto" and needs_check(result, setup.fixed)):
        return result
    options = dict(free_inertia="inertia" not in setup.fixed, inertia_prior=inertia_prior,
                   release_time=release_time, max_substep=max_substep)

    def fixed_in(m: Model):
        names = set(m.parameter_specs())
        if isinstance(fix, Mapping):
            return {n: v for n, v in fix.items() if n in names} or None
        return [n for n in (fix or ()) if n in names] or None

    def optimum(m: Model):
        s = _setup(log, m, fix=fixed_in(m), **options)
        U0, _ = _grid_starts(s.problem, s.prep, s.model, NESTED_STARTS + 1, True)
        Un, cn, _, _ = _local_fits(s.problem, U0, max_steps)
        best = int(np.argmin(np.where(np.isfinite(cn), cn, np.inf)))
        return _data_rms(s.problem, Un[best], cn[best]), s.problem.values_np(Un[best])

    def refit(m: Model) -> FitResult:
        return fit(log, m, fix=fixed_in(m), n_starts=n_starts, max_steps=max_steps,
                   start_from_model=True, nested=False, **options)

    return against_nested(result, setup.fixed, optimum, refit)


def _data_rms(problem: Problem, u, cost: float) -> float:
    """The weighted RMS data residual [log units] at ``u`` from its cost (data χ² plus the
    prior rows), as :func:`analyse` reports it (``rms_residual_rad``)."""
    P = problem.n_physical
    z = (np.asarray(u)[:P] - np.asarray(problem.prior_mean)) / np.asarray(problem.prior_sd)
    chi2 = float(cost) - float(np.sum(np.where(np.asarray(problem.prior_on), z, 0.0) ** 2))
    w2 = float(np.sum(np.asarray(problem.weight) ** 2))
    return float(problem.sigma) * math.sqrt(max(chi2, 0.0) / w2)


def _local_fits(problem: Problem, U0, max_steps: int, solve=None):
    """Levenberg–Marquardt from every row of ``U0``. Phase 1: every start a few
    iterations; phase 2: the best ones to convergence (:class:`_Schedule`). All starts are
    lanes of one program; a call advances the live ones. ``solve`` runs that program
    (default :func:`_solve_lanes`; diagnose passes one from its program store)."""
    solve = _solve_lanes if solve is None else solve
    U = np.array(U0)
    sched = _Schedule(len(U0), max_steps)
    m = int(np.prod(problem.times.shape)) + problem.n_physical
    state = LMState.empty(len(U0), m, U.shape[1])
    while (task := sched.next()) is not None:
        active, k, fresh = task
        state = state._replace(fresh=np.where(active, fresh, np.asarray(state.fresh)))
        U2, c2, done2, s2, state = solve(
            problem, jnp.asarray(U), jnp.asarray(active), jnp.asarray(k), state
        )
        state = LMState(*state)
        U2 = np.asarray(U2)
        U[active] = U2[active]
        sched.update(np.asarray(c2), np.asarray(done2), np.asarray(s2))
    return U, sched.costs, sched.ok, sched.steps


def trapped_runs(problem: Problem, prep: Prepared, u) -> np.ndarray:
    """Runs the model never releases at ``u`` (exact stick: speed 0 at every sample)
    although the log shows them moving (rest ≠ hold by more than ``MOVED_COUNTS``)."""
    # Jitted: an eager call compiled a fresh `while` program on every fit (its loop body
    # is a new closure each time), ~140 memory mappings that were never freed.
    _, omega, _ = map(np.asarray, _dense(problem, jnp.asarray(u), problem.times))
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

    n_data = int(np.sum(prep.weight > 0))
    sub = substep_for(prep.frequency_hz) if max_substep is None else float(max_substep)
    offset0 = offset_guess(prep)
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
    order = np.argsort(np.where(finite, costs, np.inf))
    best = int(order[0])
    u = U[best]
    starts = StartSummary.from_solutions(problem, U, costs, ok, steps, best)
    result = analyse(problem, prep, u, starts, fixed=set(setup.fixed), **analyse_options)
    result.wall_time_s = time.perf_counter() - t_start
    if not ok[best]:
        result.warnings.append(
            f"the best start stopped after {int(steps[best])} iterations without meeting "
            "the convergence tolerance; results may not be at the optimum"
        )
    return result


def substep_for(frequency_hz: float) -> float:
    """Longest RK4 substep [s] for a log whose oscillation frequency is ``frequency_hz``:
    ``DEFAULT_MAX_SUBSTEP`` at ``SUBSTEP_REFERENCE_HZ``, halved per octave above (so
    ``h·ω_n`` stays ≲ 0.26), doubled per octave below; powers of two, so logs of similar
    gears share compiled programs."""
    if not (math.isfinite(frequency_hz) and frequency_hz > 0):
        return DEFAULT_MAX_SUBSTEP
    octaves = math.floor(math.log2(frequency_hz / SUBSTEP_REFERENCE_HZ) + 0.5)
    return DEFAULT_MAX_SUBSTEP * 2.0 ** (-octaves)


def log_scales(prep: Prepared, model: Model, offset0: np.ndarray,
               frequency_hz: float | None = None, torque: float | None = None) -> Scales:
    """The log's magnitudes (:class:`~hdid.effects.Scales`) in its own units, at its own
    oscillation frequency (or ``frequency_hz``) and friction level (or ``torque``)."""
    inertia = float(np.median(float(model.inertia) + prep.added_inertia))
    f = prep.frequency_hz if frequency_hz is None else frequency_hz
    if not (math.isfinite(f) and f > 0):
        f = 0.1 / prep.sample_period
    w = 2 * math.pi * f
    k_wg = inertia * w**2
    offset = np.asarray(offset0)[prep.setup_index]
    theta0 = np.abs(prep.hold - offset)
    excursion = np.array([np.max(np.abs(prep.theta[i, : prep.lengths[i]] - offset[i]))
                          for i in range(prep.n_runs)])
    amp = float(np.max(np.where(prep.moving_start, excursion, theta0))
                if prep.moving_start is not None else np.max(theta0))
    if not amp > 0:
        amp = float(np.max(excursion)) or prep.resolution
    stopped = ~prep.ends_moving if prep.ends_moving is not None else np.ones(prep.n_runs, bool)
    rest = np.abs(prep.rest - offset)
    band = float(np.max(rest[stopped])) if stopped.any() else 0.0
    if torque is None:
        held = ~prep.moving_start if prep.moving_start is not None else np.ones(prep.n_runs, bool)
        sel = held & stopped
        dec = (float(np.median(theta0[sel] - np.minimum(rest[sel], theta0[sel])))
               if sel.any() else 0.0)
        torque = max(k_wg * dec / 4.0, 0.02 * k_wg * amp)
    speed = max(float(prep.speed) if math.isfinite(prep.speed) else 0.0, w * amp)
    return Scales(ratio=float(model.ratio), inertia=inertia, k_wg=k_wg, amplitude=amp,
                  speed=speed, torque=float(torque), band=band)


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


def _grid_starts(
    problem: Problem, prep: Prepared, model: Model, n_starts: int, from_model: bool = False
):
    """Coarse grid over natural frequency and Coulomb level, release times from the data.

    With ``from_model`` the model's own values are a further candidate, always kept.
    """
    U, keys = _grid_candidates(problem, prep, model, from_model)
    cost = np.asarray(_costs(problem, jnp.asarray(U)))
    return _choose_starts(U, cost, keys, n_starts, from_model)


def _grid_candidates(problem: Problem, prep: Prepared, model: Model, from_model: bool = False):
    """Candidate unknown vectors of the grid (rows) and their frequency keys.

    Frequencies around the log's own (``GRID_FREQUENCY_FACTORS``); Coulomb levels from the
    amplitude lost per half-cycle and fractions of the spring torque; every free
    parameter from its effect's ``Parameter.start`` rule at that frequency and level (the
    model's value where an effect declares none); each run's release instant by inverting
    its first half-cycle.
    """
    N = model.ratio
    specs = model.parameter_specs()
    current = model.float_values()
    inertia = current["inertia"] + prep.added_inertia  # per run
    offset = np.asarray(problem.offset0)[prep.setup_index]
    theta0 = prep.hold - offset
    amp = float(np.median(np.abs(theta0)))
    rest = np.abs(prep.rest - offset)
    y1 = prep.theta[np.arange(prep.n_runs), prep.first_moved] - offset
    t1 = prep.times[np.arange(prep.n_runs), prep.first_moved]
    # (loop invariants hoisted: this runs for every log of a batch)
    med_inertia = float(np.median(inertia))
    decrement = float(np.median(np.abs(theta0) - np.minimum(rest, np.abs(theta0))))
    free = problem.free
    pack = _packer(problem, specs)
    base = log_scales(prep, model, np.asarray(problem.offset0))
    ruled = [n for n in free if specs[n].start is not None]
    cands, keys = [], []
    f0 = base.frequency_hz
    freqs = list(f0 * GRID_FREQUENCY_FACTORS)
    if from_model:
        probe = -0.5 * amp  # secant WG stiffness over half the release amplitude
        k_model = float(model.rest_torque(probe)) / -probe
        freqs.insert(0, math.sqrt(max(k_model, 1e-300) / med_inertia) / (2 * math.pi))
    for i_f, f in enumerate(freqs):
        w = 2 * math.pi * f
        k_wg = med_inertia * w**2
        wr = np.sqrt(k_wg / inertia)
        d = -np.sign(theta0)
        if from_model and i_f == 0:
            eq = -d * current.get("tau_c", 0.0) / k_wg
            c = np.clip((y1 - eq) / (theta0 - eq), -1.0, 1.0)
            tr = np.clip(t1 - np.arccos(c) / wr, prep.release_lo, prep.release_hi)
            cands.append(pack(current, tr))
            keys.append(-1.0)
            continue
        levels = np.concatenate([
            k_wg * decrement / (2 * GRID_HALF_CYCLES), GRID_COULOMB_FRACTIONS * k_wg * amp
        ])
        tau_c = np.maximum(levels, 1e-3 * k_wg * amp)  # one candidate per level
        vals = {n: np.empty_like(tau_c) for n in ruled}
        for j, tau in enumerate(tau_c):
            sc = Scales(ratio=N, inertia=med_inertia, k_wg=k_wg, amplitude=base.amplitude,
                        speed=base.speed,
                        torque=float(tau), band=base.band)
            for n in ruled:
                vals[n][j] = specs[n].start(sc)
        full = {**{n: np.full_like(tau_c, v) for n, v in current.items()}, **vals}
        # Release instant: invert the first half-cycle θ = θ_eq + (θ0 − θ_eq)·cos(ω τ).
        eq = -d * full.get("tau_c", tau_c)[:, None] / k_wg
        c = np.clip((y1 - eq) / (theta0 - eq), -1.0, 1.0)
        tr = np.clip(t1 - np.arccos(c) / wr, prep.release_lo, prep.release_hi)
        cands.extend(pack(full, tr))
        keys.extend([f] * len(tau_c))
    return np.array(cands), np.array(keys)


def _choose_starts(U, cost, keys, n_starts: int, from_model: bool = False):
    """The best grid candidate per frequency, then the ``n_starts`` best of those; up to
    half of them from the frequencies within ``GRID_NEAR_FACTOR`` of the log's own."""
    cost = np.where(np.isfinite(cost), cost, np.inf)
    grid = keys > 0
    near = np.zeros(len(keys), bool)
    if grid.any():
        f0 = float(np.min(keys[grid])) / GRID_FREQUENCY_FACTORS[0]
        near[grid] = np.abs(np.log(keys[grid] / f0)) <= math.log(GRID_NEAR_FACTOR)
    chosen = [0] if from_model else []

    def take(candidates, n):
        for i in candidates:
            if len(chosen) >= n:
                return
            if i not in chosen and (keys[i] > 0 or not from_model) and all(
                abs(math.log(keys[i] / keys[j])) > 0.15 for j in chosen if keys[j] > 0
            ):
                chosen.append(i)

    order = np.argsort(cost)
    take([i for i in order if near[i]], len(chosen) + n_starts // 2)
    take(order, n_starts)
    return U[chosen], cost[chosen]


def _packer(problem: Problem, specs):
    """:func:`_pack` for many candidates of one problem (its arrays read once)."""
    free, release_free = problem.free, problem.release_free
    lo, hi = np.asarray(problem.release_lo), np.asarray(problem.release_hi)
    tail = np.zeros(problem.n_runs + problem.n_setups)
    if problem.n_moving:  # runs that start moving: their velocity from the data
        w0 = np.asarray(problem.omega_guess)[np.asarray(problem.moving_index)]
        tail = np.concatenate([tail, w0 / float(problem.vel_scale)])
    spec_list = [specs[n] for n in free]

    def pack(values, t_release):
        """One candidate (scalar values, ``t_release (R,)``) or several (``(L,)`` values,
        ``(L, R)``): the unknown vector(s)."""
        t_release = np.asarray(t_release, dtype=float)
        lead = t_release.shape[:-1]
        # (…, P) physical part; P = 0 when every physical parameter is fixed
        parts = [np.stack([np.broadcast_to(np.asarray(to_unconstrained(sp, values[n]),
                                                      dtype=float), lead)
                           for sp, n in zip(spec_list, free)], axis=-1)
                 if free else np.zeros(lead + (0,))]
        if release_free:
            parts.append(interval_to_u(t_release, lo, hi))
        parts.append(np.broadcast_to(tail, lead + tail.shape))
        return np.concatenate(parts, axis=-1)

    return pack


@eqx.filter_jit
def _costs(problem: Problem, U):
    return jax.vmap(problem.cost)(U)


#: Stop when two consecutive accepted Levenberg–Marquardt steps each lower χ² (residuals
#: in units of the quantization σ) by less than this: the optimum is then within about
#: sqrt(0.01) = 0.1 standard deviations along every direction, and the remaining crawl
#: along flat (prior-dominated) valleys would only cost time.
CHI2_STALL = 0.01


#: Iterations every start gets before only the best ``CONTINUED_STARTS`` go on.
PHASE1_STEPS = 12
CONTINUED_STARTS = 3
#: Phase-2 iterations between checks, and the χ² excess over the best lane at which a
#: lane is abandoned (a different, clearly worse basin: Δχ² = 50 is ~7 standard errors).
PHASE2_CHUNK = 25
DROP_DCHI2 = 50.0


class _Schedule:
    """Which starts of one log run next, and for how long (shared by :func:`fit` and the
    vectorised batch, so that both give every log the same fit).

    Phase 1: every start ``PHASE1_STEPS`` iterations; phase 2: the ``CONTINUED_STARTS``
    best to convergence or ``max_steps``, in chunks of ``PHASE2_CHUNK``; between chunks a
    lane stuck in a basin far worse than the best (Δχ² > ``DROP_DCHI2``) stops. Each call
    (phase 1, every chunk) starts its lanes ``fresh`` (see :class:`LMState`).

    Measured and not kept (``benchmarks/results/batch_speed.md``): checking the Δχ² drop
    every 5 iterations instead of 25 (7 of 40 logs ended in a worse basin), stopping
    phase-1 starts early by their χ² (1 in 80 worse, 7 % fewer iterations), a looser
    stall (0.03: 22 of 80 logs worse by > 0.1).
    """

    def __init__(self, n: int, max_steps: int):
        self.max_steps = int(max_steps)
        self.phase = 1
        self.used = 0
        self.active = np.ones(n, dtype=bool)
        self.costs = np.full(n, np.inf)
        self.ok = np.zeros(n, dtype=bool)
        self.steps = np.zeros(n, dtype=int)
        self._k = 0

    def next(self):
        """``(active lanes, iterations, fresh)`` of the next call, or None when done."""
        if self.phase == 1:
            k = PHASE1_STEPS
        else:
            if not self.active.any() or self.used >= self.max_steps:
                return None
            k = min(PHASE2_CHUNK, self.max_steps - self.used)
        self._k = k
        return self.active.copy(), k, True

    def update(self, costs, done, steps) -> None:
        """Results of the call for its active lanes."""
        a = self.active
        self.costs[a], self.steps[a] = costs[a], self.steps[a] + steps[a]
        self.used += self._k
        finite = np.where(np.isfinite(self.costs), self.costs, np.inf)
        if self.phase == 1:
            self.phase, self.used = 2, 0
            self.active = np.zeros(len(a), dtype=bool)
            self.active[np.argsort(finite, kind="stable")[:CONTINUED_STARTS]] = True
        else:
            self.ok[a] = done[a]
            best = finite.min()  # inf when every lane diverged: none goes on
            self.active = a & ~done & (finite - best < DROP_DCHI2) if np.isfinite(best) else a & False


@eqx.filter_jit
def _solve_many(problem: Problem, U0, active, max_steps):
    return jax.vmap(lambda u0, a: _levenberg_marquardt(problem, u0, a, max_steps))(U0, active)


def _levenberg_marquardt(problem: Problem, u0, active, max_steps):
    """optimistix's Levenberg–Marquardt, stepped by hand to add a statistical stop."""
    residuals = with_jacobian(problem.residuals, problem.residuals_and_jacobian)

    def fn(u, args):
        del args
        return residuals(u), None

    # Normal equations + Cholesky: lineax's QR of the tall (samples × unknowns) matrix
    # costs ~50× more here, and the damping keeps JᵀJ + λI positive definite even where
    # J is rank-deficient (the identifiability report names those directions).
    solver = optx.LevenbergMarquardt(
        rtol=1e-8, atol=1e-8, linear_solver=lx.Normal(lx.Cholesky())
    )
    tags = frozenset()
    f_struct = jax.eval_shape(problem.residuals, u0)
    state = solver.init(fn, u0, None, {}, f_struct, None, tags)
    dynamic0, static = eqx.partition(state, eqx.is_array)
    # (no separate cost evaluations: each would trace the simulator once more, which is
    # what a cold CLI call pays for)
    cost0 = jnp.asarray(jnp.inf)

    def cond(carry):
        _, _, k, _, _, done = carry
        return (~done) & (k < max_steps)

    def body(carry):
        u, dynamic, k, cost, stall, _ = carry
        state = eqx.combine(static, dynamic)
        u, state, _ = solver.step(fn, u, None, {}, state, tags)
        terminate, _ = solver.terminate(fn, u, None, {}, state, tags)
        new_cost = jnp.sum(state.f_info.residual**2)
        improved = new_cost < cost
        small = improved & (cost - new_cost < CHI2_STALL)
        stall = jnp.where(small, stall + 1, jnp.where(improved, 0, stall))
        done = terminate | (stall >= 2) | ~jnp.isfinite(new_cost)
        dynamic, _ = eqx.partition(state, eqx.is_array)
        return u, dynamic, k + 1, jnp.minimum(cost, new_cost), stall, done

    init = (u0, dynamic0, jnp.array(0), cost0, jnp.array(0), ~active)
    u, _, k, cost, stall, done = jax.lax.while_loop(cond, body, init)
    return u, cost, done, k



# ------------------------------------------------------------------ hand-stepped LM

#: optimistix's ClassicalTrustRegion constants (Gould et al.), which :func:`_lm_lanes`
#: reproduces: a trial is accepted when the χ² decrease is at least ``LM_LOW`` of the
#: Gauss–Newton prediction; above ``LM_HIGH`` of it the damping falls by ``LM_GROW``;
#: a rejected trial multiplies the damping by ``LM_SHRINK``.
LM_LOW, LM_HIGH, LM_GROW, LM_SHRINK = 0.01, 0.99, 3.5, 4.0
#: Stop a lane when its step is below this relative to |u| (optimistix's Cauchy test
#: with rtol = atol = 1e-8).
LM_XTOL = 1e-8


class LMState(NamedTuple):
    """Per-lane state of :func:`_lm_lanes` carried from one call to the next.

    ``fresh`` lanes start as optimistix's solver does in a new call — damping 1, stall
    count 0, and the evaluation at the start point counted as one iteration — so that
    the schedule's phases reproduce ``optimistix.LevenbergMarquardt`` (the reference
    since the first release), while a call that continues a lane (``fresh`` false) is
    indistinguishable from a longer one.
    """

    R: jax.Array  # residuals at U        (L, m)
    J: jax.Array  # Jacobian at U         (L, m, n)
    have: jax.Array  # R, J valid          (L,)
    lam: jax.Array  # damping λ            (L,)
    stall: jax.Array  # consecutive small accepted steps
    jfirst: jax.Array  # last trial accepted: evaluate the next with its Jacobian
    fresh: jax.Array  # start as a new optimistix call

    @staticmethod
    def empty(L: int, m: int, n: int) -> "LMState":
        return LMState(
            np.zeros((L, m)), np.zeros((L, m, n)), np.zeros(L, dtype=bool), np.ones(L),
            np.zeros(L, dtype=int), np.zeros(L, dtype=bool), np.ones(L, dtype=bool),
        )


def _lm_lanes(residuals, residuals_and_jacobian, U0, active, max_steps, state: LMState):
    """Levenberg–Marquardt for a batch of lanes; a rejected trial costs one forward pass.

    ``residuals(U) -> R`` and ``residuals_and_jacobian(U) -> (R, J)`` act on all lanes
    ``U (L, n)``. The iteration is optimistix's ``LevenbergMarquardt`` with a normal-
    equations Cholesky solve, ``(JᵀJ + λI) δ = −Jᵀr``, and its ``ClassicalTrustRegion``
    update of ``λ`` — so the path of every lane is the same — but the control flow is
    over the whole batch rather than vmapped, so the forward-mode Jacobian (≈ 3× a
    forward pass) is computed only where it is used: a trial after a rejected one is a
    forward pass, and the Jacobian follows only if it is accepted (with one lane per
    program; a batch computes it when any lane needs it). optimistix evaluates every
    trial with its Jacobian, and about a third of the trials are rejected.

    Stops a lane after two consecutive accepted steps that each lower χ² by less than
    ``CHI2_STALL``, after a negligible step, or with non-finite residuals at its start.
    Returns ``(U, cost, done, iterations, state)``.
    """
    L, n = U0.shape
    # Each function is called at two or three places below; as inner jits they are traced
    # once each (JAX caches the trace per function), not once per call site — the
    # stick-exact simulation is the slow part of tracing a cold `hdid fit`.
    residuals = jax.jit(residuals)
    residuals_and_jacobian = jax.jit(residuals_and_jacobian)
    max_steps = jnp.broadcast_to(jnp.asarray(max_steps), (L,))
    fresh = state.fresh & active
    R0, J0 = jax.lax.cond(
        jnp.all(state.have | ~active),
        lambda: (state.R, state.J),
        lambda: residuals_and_jacobian(U0),
    )
    cost0 = jnp.sum(R0**2, axis=1)
    finite0 = jnp.isfinite(cost0) & jnp.all(jnp.isfinite(J0), axis=(1, 2))
    cost0 = jnp.where(finite0, cost0, jnp.inf)
    init = dict(
        U=U0, R=R0, J=J0, cost=cost0,
        lam=jnp.where(fresh, 1.0, state.lam),
        stall=jnp.where(fresh, 0, state.stall),
        jfirst=jnp.where(fresh, False, state.jfirst),
        done=~active | ~finite0,
        k=jnp.where(fresh, 1, 0),
    )
    eye = jnp.eye(n)

    def cond(c):
        return jnp.any(~c["done"] & (c["k"] < max_steps))

    def body(c):
        live = ~c["done"] & (c["k"] < max_steps)
        U, R, J, cost, lam = c["U"], c["R"], c["J"], c["cost"], c["lam"]
        A = jnp.einsum("lmi,lmj->lij", J, J)
        g = jnp.einsum("lmi,lm->li", J, R)
        chol = jnp.linalg.cholesky(A + lam[:, None, None] * eye)
        delta = -jax.vmap(lambda C, b: jax.scipy.linalg.cho_solve((C, True), b))(chol, g)
        delta = jnp.where(live[:, None], delta, 0.0)
        Ut = U + delta
        # After an accepted trial the next is likely accepted too: evaluate it with its
        # Jacobian at once. After a rejection, the forward pass only.
        with_J = jnp.any(live & c["jfirst"])
        Rt, Jt = jax.lax.cond(
            with_J, lambda: residuals_and_jacobian(Ut), lambda: (residuals(Ut), J)
        )
        cost_t = jnp.sum(Rt**2, axis=1)
        # Gauss–Newton predicted decrease |r|² − |r + Jδ|² (ClassicalTrustRegion).
        pred = -(2.0 * jnp.sum(g * delta, axis=1) + jnp.einsum("li,lij,lj->l", delta, A, delta))
        actual = cost - cost_t
        acc = live & jnp.isfinite(cost_t) & (actual >= LM_LOW * pred)
        good = acc & (actual > LM_HIGH * pred) & (pred > 0)
        U_new = jnp.where(acc[:, None], Ut, U)
        need = acc & ~with_J
        R_new, J_new = jax.lax.cond(
            jnp.any(need), lambda: residuals_and_jacobian(U_new), lambda: (Rt, Jt)
        )
        R_new = jnp.where(acc[:, None], R_new, R)
        J_new = jnp.where(acc[:, None, None], J_new, J)
        cost_new = jnp.where(acc, jnp.sum(R_new**2, axis=1), cost)
        lam_new = jnp.where(good, lam / LM_GROW, jnp.where(acc, lam, LM_SHRINK * lam))
        small = acc & (cost - cost_new < CHI2_STALL)
        stall = jnp.where(small, c["stall"] + 1, jnp.where(acc, 0, c["stall"]))
        tiny = jnp.linalg.norm(delta, axis=1) <= LM_XTOL * (jnp.linalg.norm(U, axis=1) + LM_XTOL)
        done = c["done"] | (live & ((stall >= 2) | tiny))
        return dict(
            U=U_new, R=R_new, J=J_new, cost=cost_new, done=done,
            lam=jnp.where(live, lam_new, lam), stall=stall,
            jfirst=jnp.where(live, acc, c["jfirst"]), k=c["k"] + live.astype(int),
        )

    out = jax.lax.while_loop(cond, body, init)
    new_state = LMState(
        out["R"], out["J"], active & finite0, out["lam"], out["stall"], out["jfirst"],
        jnp.zeros(L, dtype=bool),
    )
    return out["U"], out["cost"], out["done"] & active, out["k"], new_state


def lanes_vmap(fn, *, shared: int = 0):
    """``jax.vmap(fn)`` over a leading lane axis, but a single lane is not vmapped.

    The simulator's event branch is a ``lax.cond`` that runs only in the substeps that
    need it (:func:`hdid._simulate.simulate_runs`); under ``vmap`` it becomes a select
    that runs every branch. One-lane programs (the batch fit's) keep the ``cond``.
    The first ``shared`` arguments are not batched.
    """

    def mapped(*args):
        lanes = jax.tree_util.tree_leaves(args[shared:])[0].shape[0]
        if lanes == 1:
            one = [jax.tree_util.tree_map(lambda x: x[0], a) for a in args[shared:]]
            out = fn(*args[:shared], *one)
            return jax.tree_util.tree_map(lambda x: x[None], out)
        axes = (None,) * shared + (0,) * (len(args) - shared)
        return jax.vmap(fn, in_axes=axes)(*args)

    return mapped


@eqx.filter_jit
def _solve_lanes(problem: Problem, U0, active, max_steps, state: LMState):
    """:func:`_lm_lanes` for the starts of one log."""
    return _lm_lanes(
        lanes_vmap(problem.residuals), lanes_vmap(problem.residuals_and_jacobian), U0, active,
        max_steps, state,
    )
