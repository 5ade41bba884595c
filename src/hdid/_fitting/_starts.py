"""Starting points of a fit, from the log in hand: a coarse grid over natural frequency and
Coulomb level around the log's own frequency, scored by cost; the best and the nearest kept."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._models._model import Model
from .._simulation._prepare import Prepared
from ._pendulum import pendulum_candidates
from .._problems._problem import Problem
from .._models._transforms import interval_to_u, to_unconstrained
from ..effects import Scales


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


def _grid_starts(
    problem: Problem, prep: Prepared, model: Model, n_starts: int, from_model: bool = False
):
    """Coarse grid over natural frequency and Coulomb level, release times from the data.

    With ``from_model`` the model's own values are a further candidate, always kept.
    """
    U, keys = _grid_candidates(problem, prep, model, from_model)
    cost = grid_costs(problem, U)
    return with_drop_starts(problem, prep, model, U, cost, keys, n_starts, from_model,
                            lambda Ud: np.asarray(_costs(problem, jnp.asarray(Ud))))


def with_drop_starts(problem, prep, model, U, cost, keys, n_starts: int, from_model: bool,
                     drop_cost=None):
    """:func:`_choose_starts` of the grid ``(U, cost, keys)``, after a pendulum drop's own
    starts read from its swings (:func:`hdid._fitting._pendulum.pendulum_candidates`, one
    per run) when the log is one: the starts of :func:`hdid.fit`, the batch and
    diagnose's refits alike. ``drop_cost(Ud)``: the drop starts' costs (default: below
    the grid's, so they run first)."""
    drop = pendulum_candidates(problem, prep, model, _packer(problem, model.parameter_specs()))
    if not drop:
        return _choose_starts(U, cost, keys, n_starts, from_model)
    Ud = np.array(drop)
    U0, c0 = _choose_starts(U, cost, keys, max(n_starts - len(drop), 1), from_model)
    cd = (drop_cost(Ud) if drop_cost is not None
          else np.full(len(Ud), np.min(np.asarray(c0, dtype=float), initial=0.0)))
    return np.concatenate([Ud, U0]), np.concatenate([np.asarray(cd, dtype=float), c0])


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
    moving = (np.zeros(prep.n_runs, bool) if prep.moving_start is None
              else np.asarray(prep.moving_start, dtype=bool))
    w_moving = np.where(moving, np.asarray(prep.omega_guess, dtype=float), 0.0)
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
        amp_f, dec_f = amp, decrement
        if moving.any():  # a run cut in mid-swing: its swing's amplitude at this frequency
            amp_f, dec_f = _swing_amplitude(theta0, w_moving, wr, rest, moving)
        levels = np.concatenate([
            k_wg * dec_f / (2 * GRID_HALF_CYCLES), GRID_COULOMB_FRACTIONS * k_wg * amp_f
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


def _swing_amplitude(theta0, omega0, wr, rest, moving):
    """``(amplitude, decrement)`` medians over the runs for the grid's friction levels, a
    run that starts moving (``moving``) counted at its swing's amplitude
    ``√(θ0² + (ω0/ω_n)²)`` at the grid's natural frequency ``wr`` (its energy), not at its
    first reading: a log cut in mid-swing reads near the spring's zero at full speed, and
    its first reading put every grid level far below the friction."""
    swing = np.where(moving, np.hypot(theta0, omega0 / wr), np.abs(theta0))
    return float(np.median(swing)), float(np.median(swing - np.minimum(rest, swing)))


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


def _loop_costs(problem: Problem, U):
    # a loop, not a vmap: the simulator's event branch stays a branch (``lanes_vmap``);
    # 120 grid points of the shipped 1 kHz log: 0.03 s, vmapped 0.10 s
    return jax.lax.map(problem.cost, U)


def grid_costs(problem: Problem, U) -> np.ndarray:
    """χ² of each row of ``U`` (grid candidates), one after another in one stored program
    per structure and grid size (:mod:`hdid._problems._programs`): the grids of
    :func:`hdid.fit`, of its limit checks and of diagnose's refits."""
    from .._problems import _programs

    return np.asarray(_programs.call("grid_costs", _loop_costs, problem, jnp.asarray(U)),
                      dtype=float)
