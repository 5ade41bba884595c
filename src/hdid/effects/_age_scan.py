"""Finding a sample-and-hold device's clock (period ``P``, per-run phase ``φ_r``) from a fitted
model's residuals, for :class:`~hdid.effects.reading_age.ReadingAge`.

A reading ``a`` seconds old differs from the model's state at its timestamp by ``−ω·a`` (to
first order in ``a``), so the residual (measured − model) of a model that already ages its
readings by ``a_m`` is ``r ≈ −ω·(a − a_m)`` plus what the physics leaves. The scan tries every
clock ``(P, φ)`` on a grid and keeps, per run, the phase whose ``−ω·(a − a_m)`` best matches
the residual's *sample-to-sample* part (both minus their running mean over ``SMOOTH``
samples): the age is a sawtooth that changes from one sample to the next, a torque misfit is
smooth, so the comparison is not misled by the physics the model still lacks.

Grid: uniform in frequency ``1/P`` (a clock error ``dP`` drifts the phase by ``D·dP/P`` over
``D`` seconds of motion, so the grid step that keeps the drift below ``P/STEP_FRACTION``
is one in ``1/P`` of ``1/(STEP_FRACTION·D)``), over periods from ``1/PERIOD_RANGE[0]`` to
``PERIOD_RANGE[1]`` times the host's median interval (a device faster than the host, or up
to twice slower); ``PHASES`` phases per period. The grid's best is refined on a 10× finer
one around it. Everything is in the log's own time unit.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import jax.numpy as jnp
import numpy as np

#: Residual and prediction minus their running mean over this many samples: what is left is
#: the sample-to-sample part (a smooth torque misfit has next to none).
SMOOTH = 5
#: Periods scanned: from the host's median interval / first to × second.
PERIOD_RANGE = (8.0, 2.0)
#: The frequency grid's step keeps the phase drift over the motion below P / this.
STEP_FRACTION = 8.0
#: Phases tried per period (resolution P / PHASES; the host's timestamp jitter is coarser).
PHASES = 16
#: At most this many periods on the coarse grid (a long, fast log: the frequency step grows,
#: and a clock's narrow optimum may fall between two; the refinement starts from the best).
MAX_PERIODS = 20000
#: Periods evaluated at once (memory: BLOCK × PHASES × samples of one run).
BLOCK = 256


@dataclass
class AgeScan:
    """The best clock: ``period`` [s] (shared by the runs), ``phases`` [s] per run (log
    order, each within a period of its run's moving middle), ``run_periods`` [s] (each
    run's own best period on the same grid: one device, one clock, if the story holds),
    ``sse``/``sse_none``: the high-passed residual's weighted sum of squares [rad²] with
    this clock and with the model's own (``a − a_m = 0``), and ``significant``: whether the
    gain exceeds what a scan of this many settings finds in noise of the floor."""

    period: float
    phases: np.ndarray
    run_periods: np.ndarray
    runs: list
    sse: float
    sse_none: float
    significant: bool
    #: ``j`` [s]: the request jitter chosen with ``jitters`` (0 without), shared by the runs
    jitter: float = 0.0
    #: ``sse`` at ``j = 0`` with each run's phase re-chosen on the same grid (``nan`` without)
    sse_no_jitter: float = float("nan")



def expected_floor(u, w):
    """``E⌊u + D⌋`` for ``D`` uniform on ``[−w/2, w/2]`` (``0 ≤ w ≤ 1``, in periods): ``⌊u⌋``
    plus the chance of passing the next step minus that of falling below the last, with
    ``f = u − ⌊u⌋``: ``clip((f + w/2 − 1)/w, 0, 1) − clip((w/2 − f)/w, 0, 1)``; exactly
    ``⌊u⌋`` where ``w = 0``. numpy in, numpy out; JAX in, JAX out."""
    xp = jnp if isinstance(u, jnp.ndarray) or isinstance(w, jnp.ndarray) else np
    n = xp.floor(u)
    f, w = u - n, xp.clip(w, 0.0, 1.0)
    safe = xp.where(w > 0, w, 1.0)
    ramp = xp.clip((f + w / 2 - 1) / safe, 0.0, 1.0) - xp.clip((w / 2 - f) / safe, 0.0, 1.0)
    return n + xp.where(w > 0, ramp, 0.0)


def _highpass(x: np.ndarray) -> np.ndarray:
    """``x`` minus its centred running mean over ``SMOOTH`` samples along the last axis
    (the window shrinks at the ends)."""
    n = x.shape[-1]
    c = np.concatenate([np.zeros(x.shape[:-1] + (1,)), np.cumsum(x, axis=-1)], axis=-1)
    h = SMOOTH // 2
    lo = np.clip(np.arange(n) - h, 0, n)
    hi = np.clip(np.arange(n) + h + 1, 0, n)
    return x - (c[..., hi] - c[..., lo]) / (hi - lo)


def _run_sse(t, w, r_hp, omega, a_model, periods, fracs, jitter=0.0):
    """Weighted SSE ``(len(periods), len(fracs))`` of ``hp(r) − hp(−ω·(a − a_m))``, the
    age ``a = t − s̄`` of :class:`ReadingAge` with request jitter ``jitter`` [s]."""
    out = np.empty((len(periods), len(fracs)))
    for i in range(0, len(periods), BLOCK):
        p = periods[i:i + BLOCK, None, None]
        phi = fracs[None, :, None] * p
        if jitter:
            u = (t[None, None, :] - phi) / p
            age = p * (u - expected_floor(u, jitter / p))
        else:
            age = np.mod(t[None, None, :] - phi, p)
        x = _highpass(-omega * (age - a_model))
        out[i:i + BLOCK] = np.sum(w * (r_hp - x) ** 2, axis=-1)
    return out


def scan(frame, *, floor: float | None = None, current=None, periods=None,
         exclude: tuple[float, float] | None = None, jitters=None) -> AgeScan | None:
    """The clock that best explains ``frame``'s residuals (:func:`hdid.FitResult.residuals`:
    columns ``run``, ``t``, ``residual_rad``, ``omega``, ``phase``, ``weight``), the model's
    own age ``current`` (a :class:`ReadingAge`, or ``None``) taken off; ``periods`` [s]
    replaces the grid; ``exclude`` ``(lo, hi)`` [s] leaves those periods out (the runner-up
    clock: an alias of the best against the host's rate gives the same sawtooth up to its
    height); ``jitters`` [fractions of ``P``]: request jitters tried at the chosen period, each
    run's phase chosen again with each (the best is kept where it beats ``j = 0`` by more than
    ``ln n``, the BIC's charge for one more setting). ``None`` when no run has moving samples."""
    runs = []
    for name, d in frame.groupby("run", sort=False):
        m = (d["phase"] == "moving").to_numpy() & (d["weight"].to_numpy() > 0)
        runs.append((name, d["t"].to_numpy()[m], d["weight"].to_numpy()[m],
                     d["residual_rad"].to_numpy()[m], d["omega"].to_numpy()[m]))
    live = [r for r in runs if len(r[1]) > 2 * SMOOTH]
    if not live:
        return None
    dt = float(np.median(np.concatenate([np.diff(r[1]) for r in live])))
    span = max(float(r[1][-1] - r[1][0]) for r in live)
    fracs = np.arange(PHASES) / PHASES
    if periods is None:
        f_lo, f_hi = 1.0 / (PERIOD_RANGE[1] * dt), PERIOD_RANGE[0] / dt
        df = max(1.0 / (STEP_FRACTION * span), (f_hi - f_lo) / MAX_PERIODS)
        periods = 1.0 / np.arange(f_lo, f_hi + df, df)
    periods = np.asarray(periods, dtype=float)
    if exclude is not None:
        periods = periods[(periods < exclude[0]) | (periods > exclude[1])]
    if not len(periods):
        return None

    def model_age(i, t):
        if current is None or current.phases is None:
            return np.zeros_like(t)
        p, phi = float(current.sample_period), float(np.asarray(current.phases)[i])
        return np.mod(t - phi, p)

    index = {name: i for i, (name, *_rest) in enumerate(runs)}

    def table(periods, fracs):
        total = np.zeros(len(periods))
        per_run, best_frac = [], []
        for name, t, w, r, om in live:
            s = _run_sse(t, w, _highpass(r), om, model_age(index[name], t), periods, fracs)
            total += s.min(axis=1)
            per_run.append(s.min(axis=1))
            best_frac.append(s.argmin(axis=1))
        return total, per_run, best_frac

    total, per_run, _ = table(periods, fracs)
    # each run's own best period on the coarse grid (one device, one clock: they agree)
    run_periods = np.array([float(periods[int(np.argmin(s))]) for s in per_run])
    k = int(np.argmin(total))
    if len(periods) > 2:  # refine: 10× finer in frequency and phase around the best
        f = 1.0 / periods
        lo, hi = f[min(k + 1, len(f) - 1)], f[max(k - 1, 0)]
        periods = 1.0 / np.linspace(min(lo, hi), max(lo, hi), 41)
        fracs = np.arange(10 * PHASES) / (10 * PHASES)
    total, _, best_frac = table(periods, fracs)
    k = int(np.argmin(total))
    period = float(periods[k])
    phases = np.full(len(runs), np.nan)
    sse_none = 0.0
    for j, (name, t, w, r, om) in enumerate(live):
        phi = fracs[best_frac[j][k]] * period
        centre = float(np.sum(w * om**2 * t) / max(np.sum(w * om**2), 1e-300))
        phases[index[name]] = centre - np.mod(centre - phi, period)
        sse_none += float(np.sum(w * _highpass(r) ** 2))
    sse = float(total[k])
    n = sum(len(r[1]) for r in live)
    jitter, sse_j0 = 0.0, float("nan")
    if jitters is not None:  # the request jitter, at the chosen period, the phases re-chosen
        one = np.array([period])
        costs = []
        for frac in (0.0, *(float(x) for x in jitters if x > 0)):
            per = [_run_sse(t, w, _highpass(r), om, model_age(index[name], t), one, fracs,
                            jitter=frac * period)[0] for name, t, w, r, om in live]
            costs.append((float(sum(c.min() for c in per)), frac * period,
                          [int(np.argmin(c)) for c in per]))
        sse_j0 = costs[0][0]
        best = min(costs, key=lambda c: c[0])
        s2 = (floor if floor and math.isfinite(floor) else math.sqrt(sse_none / n)) ** 2
        if (sse_j0 - best[0]) / s2 > math.log(max(n, 2)):
            sse, jitter = best[0], best[1]
            for j, (name, t, w, r, om) in enumerate(live):
                centre = float(np.sum(w * om**2 * t) / max(np.sum(w * om**2), 1e-300))
                phases[index[name]] = centre - np.mod(centre - fracs[best[2][j]] * period, period)
    sigma2 = (floor if floor and math.isfinite(floor) else math.sqrt(sse_none / n)) ** 2
    # the scan chooses a period and one phase per run: charge ln n per choice (BIC)
    significant = (sse_none - sse) / sigma2 > (1 + len(live)) * math.log(max(n, 2))
    return AgeScan(period=period, phases=np.where(np.isnan(phases), period / 2, phases),
                   run_periods=run_periods, runs=[r[0] for r in runs], sse=sse,
                   sse_none=sse_none, significant=bool(significant), jitter=jitter,
                   sse_no_jitter=sse_j0)
