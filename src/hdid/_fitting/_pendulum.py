"""Log-derived starts for a pendulum drop: release, zero, m·g·l/I and friction from the swings.

A drop test (a pendulum lifted by a servo, torque cut, free swing until it sticks) is read
here by its physics, in the log's own units, before any model is simulated:

- **Release.** The free motion is the swing that carries the arm over most of its range.
  Walking back from it, the readings change monotonically until the instant the arm was
  let go; there the motion turns or stands still. Before it the arm was held by a servo,
  which may flicker by counts, creep, or still be lifting it: those samples are the
  controller's motion, not the free model's, and get weight 0. The "hold" is the stretch
  of readings within the flicker of the release reading just before it.
- **Zero and friction level.** Between two turning points ``a → b`` (speed 0 at both) the
  energy balance of a pendulum with a friction torque ``τ`` is
  ``mgl·(cos φ_b − cos φ_a) = τ·|φ_b − φ_a|`` (``φ = (θ − z)/N`` the output angle from the
  hanging position ``z``). It is homogeneous in ``mgl``: every half-swing gives the ratio
  ``r = τ/mgl``. A wrong ``z`` makes ``r`` alternate with the swing direction (a swing
  towards the side where ``z`` was put too far loses too little), so ``z`` is the zero at
  which the half-swings of both directions agree; ``r`` is then the friction level in
  units of ``mgl`` (for a Coulomb law ``sin`` of the stick band's half-width). The rest
  after the last turning point is a turning point too (the arm stops at speed 0).
- **m·g·l/I.** A half-swing of output amplitude ``A`` lasts ``2·K(sin²(A/2))/ω₀``
  (``K`` the complete elliptic integral of the first kind; ``π/ω₀`` for small swings);
  Coulomb friction shifts the centre of each half-swing but not its duration, and
  ``A = |a − b|/(2N)`` does not depend on the zero. The median of ``ω₀`` over the
  half-swings between turning points gives ``mgl = N²·I·ω₀²`` at the wave generator's
  inertia ``I``.

:func:`pendulum_prepared` applies these to a :class:`~hdid._simulation._prepare.Prepared`
log when the model's spring is a :class:`~hdid.effects.Gravity` pendulum (no stiffness):
the release brackets, holds and weights, the swing frequency that centres the start grid,
and the per-set-up zero that starts the offsets.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize_scalar
from scipy.special import ellipk

from .._simulation._prepare import MAX_SILENT_START, Prepared, _vertex, turning_points

#: Fraction of a run's largest excursion from its first reading beyond which the arm is
#: surely in its free swing (a servo's lift or creep before the release covers less: the
#: drop then swings through the hanging position to the other side).
SWING_FRACTION = 0.5


@dataclass(frozen=True)
class DropRun:
    """One run read as a drop: indices into the run's own samples, readings [log units]."""

    release: int                  # last sample at the release reading (the hold's end)
    hold_start: int               # first sample of the hold window
    hold: float                   # reading at release
    t_release: float              # release instant for timing the first half-swing [s]
    turns_t: np.ndarray           # vertex times of the turning points after release [s]
    turns_a: np.ndarray           # readings at those turning points
    rest: float                   # final reading (the arm stuck)
    at_rest: bool                 # whether the run ends stuck


@dataclass(frozen=True)
class DropSwings:
    """What the swings of a drop log say (output angles relative to each set-up's zero)."""

    zero: np.ndarray              # per set-up reading at the hanging position [log units]
    omega0: float                 # small-swing angular frequency [rad/s] (nan: no timing)
    friction_ratio: float         # τ/mgl, equivalent friction level of the half-swings
    coulomb_ratio: float          # τ_c/mgl: the part of it that does not grow with the swing
    viscous_slope: float          # its growth with the output amplitude [1/rad]: c_v·π·ω₀/(4·mgl)
    rest_ratio: float             # largest |sin φ_rest|: the holding level needed, over mgl
    runs: tuple[DropRun, ...]


def _median3(x: np.ndarray) -> np.ndarray:
    """Three-point running median: a one-sample read dropout does not move a release."""
    if len(x) < 3:
        return x.copy()
    y = x.copy()
    y[1:-1] = np.median(np.stack([x[:-2], x[1:-1], x[2:]]), axis=0)
    return y


def _turn_time(t: np.ndarray, x: np.ndarray, i: int, depth: float) -> float:
    """Time of the turning point at sample ``i``: the vertex of a least-squares parabola
    through the samples around it within ``depth`` of its reading (the top tenth of the
    half-swing: ``1 − cos ωτ ≤ 0.1``, where a parabola is the swing to 0.3 %). A slow
    turn reads the same count for several samples; three points would time the flat's
    edge, not its middle."""
    lo = i
    while lo > 0 and abs(x[lo - 1] - x[i]) <= depth:
        lo -= 1
    hi = i
    while hi < len(x) - 1 and abs(x[hi + 1] - x[i]) <= depth:
        hi += 1
    if hi - lo < 2:
        return _vertex(t, x, i)
    c2, c1, _ = np.polyfit(t[lo: hi + 1] - t[i], x[lo: hi + 1], 2)
    if c2 == 0.0:
        return float(t[i])
    tv = -c1 / (2.0 * c2)
    return float(t[i] + tv) if t[lo] - t[i] <= tv <= t[hi] - t[i] else float(t[i])


def drop_run(t: np.ndarray, th: np.ndarray, still: float) -> DropRun | None:
    """Release, hold and turning points of one run (``still``: the flicker of a reading
    that does not move, in log units), or ``None`` when no free swing is seen."""
    n = len(th)
    if n < 5:
        return None
    x = _median3(np.asarray(th, dtype=float))
    dev = np.abs(x - x[0])
    span = float(dev.max())
    if not span > 4.0 * still:
        return None
    j = int(np.argmax(dev > SWING_FRACTION * span))
    d = np.sign(x[j] - x[j - 1]) if j > 0 else 0.0
    if d == 0.0:
        return None
    k = j
    while k > 0:
        if d * (x[k] - x[k - 1]) > 0.0:
            k -= 1
        elif k >= 2 and x[k] == x[k - 1] and d * (x[k - 1] - x[k - 2]) > still:
            k -= 1  # one repeated reading inside the swing (a logger's stale sample)
        else:
            break
    if k == 0 and abs(x[1] - x[0]) > still:
        return None  # in motion from the first sample: no hold in this log
    h = k
    while h > 0 and abs(x[h - 1] - x[k]) <= still:
        h -= 1
    hold = float(np.median(x[h: k + 1]))
    # Release instant for timing the first half-swing: the middle of the sample interval
    # after the last sample at the release reading (a servo's lift that turns into the
    # swing starts it a little earlier: this half-swing times ω₀ only where no later one
    # does, see read_swings).
    t_release = 0.5 * (t[k] + t[min(k + 1, n - 1)])
    # the stuck tail: trailing readings within the flicker of the last one
    off = np.flatnonzero(np.abs(x - x[-1]) > still)
    tail = int(off[-1]) + 1 if off.size else n
    at_rest = tail < n - 2
    seg = slice(k, max(tail, k + 2))
    tp = turning_points(x[seg], max(2.0 * still, 1e-300))
    turns_a = np.array([float(x[seg][int(i)]) for i in tp])
    prev = np.concatenate([[hold], turns_a[:-1]])
    turns_t = np.array([_turn_time(t[seg], x[seg], int(i), max(0.1 * abs(a - b), 3.0 * still))
                        for i, a, b in zip(tp, turns_a, prev)])
    return DropRun(release=k, hold_start=h, hold=hold, t_release=float(t_release),
                   turns_t=turns_t, turns_a=turns_a,
                   rest=float(np.median(x[tail:])) if at_rest else float(x[-1]),
                   at_rest=at_rest)


def _weighted_median(x: np.ndarray, w: np.ndarray) -> float:
    order = np.argsort(x)
    c = np.cumsum(w[order])
    return float(x[order][int(np.searchsorted(c, 0.5 * c[-1]))])


def _half_swings(run: DropRun):
    """Consecutive speed-0 readings of a run: the release, the turning points, the rest."""
    a = [run.hold, *run.turns_a.tolist()]
    if run.at_rest and abs(run.rest - a[-1]) > 0.0:
        a.append(run.rest)
    return list(zip(a[:-1], a[1:]))


def _ratios(pairs, z: float, ratio: float) -> np.ndarray:
    """``r = (cos φ_b − cos φ_a)/|φ_b − φ_a|`` of each half-swing ``(a, b)`` for zero ``z``."""
    a = (np.array([p[0] for p in pairs]) - z) / ratio
    b = (np.array([p[1] for p in pairs]) - z) / ratio
    return (np.cos(b) - np.cos(a)) / np.maximum(np.abs(b - a), 1e-300)


def swing_zero(pairs, ratio: float, lo: float, hi: float) -> tuple[float, float]:
    """Zero ``z`` in ``[lo, hi]`` at which the half-swings of both directions lose the same
    ``r = τ/mgl`` (least squares over ``z``, ``r`` their mean), and that ``r``."""
    if not pairs:
        return 0.5 * (lo + hi), 0.0

    def spread(z):
        r = _ratios(pairs, z, ratio)
        return float(np.sum((r - r.mean()) ** 2))

    grid = np.linspace(lo, hi, 201)
    s = np.array([spread(z) for z in grid])
    i = int(np.argmin(s))
    a, b = grid[max(i - 1, 0)], grid[min(i + 1, len(grid) - 1)]
    z = grid[i]
    if b > a:
        z = float(minimize_scalar(spread, bounds=(a, b), method="bounded",
                                  options={"xatol": 1e-9 * max(hi - lo, 1e-300)}).x)
    return z, max(float(np.mean(_ratios(pairs, z, ratio))), 0.0)


def drop_swings(prep: Prepared, ratio: float, still: float) -> DropSwings | None:
    """Release, zero, ``ω₀`` and friction level of a drop log (``None`` if no run drops)."""
    runs = [(prep.times[i, : int(prep.lengths[i])], prep.theta[i, : int(prep.lengths[i])])
            for i in range(prep.n_runs)]
    return read_swings(runs, prep.setup_index, ratio, still)


def read_swings(runs, setup_index, ratio: float, still: float) -> DropSwings | None:
    """:func:`drop_swings` for ``runs``, a list of ``(time, theta)`` arrays (any time
    steps: jittered or gapped logs too), ``setup_index`` each run's set-up (0, 1, …)."""
    setup_index = np.asarray(setup_index, dtype=int)
    runs = [drop_run(np.asarray(t, float), np.asarray(th, float), still) for t, th in runs]
    if all(r is None for r in runs):
        return None
    n_setups = int(setup_index.max()) + 1
    rest_all = np.array([r.rest if r is not None else np.nan for r in runs])
    zero = np.zeros(n_setups)
    r_all = []
    for s in range(n_setups):
        mine = [r for r, si in zip(runs, setup_index) if r is not None and si == s]
        pairs = [p for r in mine for p in _half_swings(r)]
        if not pairs:
            zero[s] = float(np.nanmean(rest_all[setup_index == s])) if mine else 0.0
            continue
        # the zero lies between the extreme turning points (a swing passes through it)
        ext = [v for p in pairs for v in p]
        lo, hi = min(ext), max(ext)
        rests = [r.rest for r in mine if r.at_rest]
        z, r = swing_zero(pairs, ratio, lo, hi)
        both = any(b > a for a, b in pairs) and any(b < a for a, b in pairs)
        if not both and rests:  # one direction only: z and r blur; the rests bound z
            z = float(np.mean(rests))
            r = max(float(np.mean(_ratios(pairs, z, ratio))), 0.0)
        zero[s] = z
        r_all.append(r)
    friction_ratio = float(np.median(r_all)) if r_all else 0.0
    # ω₀ from the half-swings between turning points (or, in a log whose runs turn only
    # once, from release to turn), a median weighted by the swing's length: long swings
    # time best, and the short last ones (creep into the rest, set by friction rather
    # than gravity) count least
    w0, wt = [], []
    for first in (False, True):
        for r, si in zip(runs, setup_index):
            if r is None:
                continue
            ts = [r.t_release, *r.turns_t.tolist()][0 if first else 1:]
            az = [r.hold, *r.turns_a.tolist()][0 if first else 1:]
            for ta, tb, a, b in list(zip(ts[:-1], ts[1:], az[:-1], az[1:]))[:1 if first else None]:
                if abs(b - a) < 4.0 * still or not tb > ta:
                    continue
                amp = min(abs(b - a) / (2.0 * ratio), 0.99 * math.pi)
                # friction r = τ/mgl moves the half-swing's centre to asin(r), where
                # gravity's stiffness is mgl·cos(asin r): the swing is slower by (1 − r²)^¼
                rk = min(max(float(_ratios([(a, b)], zero[si], ratio)[0]), 0.0), 0.9)
                w0.append(2.0 * float(ellipk(math.sin(amp / 2.0) ** 2)) / (tb - ta)
                          / (1.0 - rk**2) ** 0.25)
                wt.append(abs(b - a))
        if w0:
            break
    omega0 = _weighted_median(np.array(w0), np.array(wt)) if w0 else float("nan")
    rest_ratio = 0.0
    for r, si in zip(runs, setup_index):
        if r is not None and r.at_rest:
            rest_ratio = max(rest_ratio, abs(math.sin((r.rest - zero[si]) / ratio)))
    # Coulomb and viscous parts: a viscous torque c·θ̇ takes c·(π/2)·ω₀·A² of energy from
    # a half-swing of output amplitude A, Coulomb τ·2A, so r = τ/mgl + (c·π·ω₀/(4·mgl))·A
    # over the half-swings (each at its own set-up's zero); a line through (A, r)
    amp, rr = [], []
    for r, si in zip(runs, setup_index):
        if r is None:
            continue
        for a, b in _half_swings(r):
            if abs(b - a) >= 4.0 * still:
                amp.append(abs(b - a) / (2.0 * ratio))
                rr.append(float(_ratios([(a, b)], zero[si], ratio)[0]))
    coulomb, slope = friction_ratio, 0.0
    if len(amp) >= 3 and np.ptp(amp) > 0:
        slope, coulomb = np.polyfit(amp, rr, 1, w=np.sqrt(amp))
        if slope < 0:
            coulomb, slope = friction_ratio, 0.0
        elif coulomb < 0:
            coulomb, slope = 0.0, float(np.sum(np.multiply(amp, rr)) / np.sum(np.square(amp)))
    return DropSwings(zero=zero, omega0=omega0, friction_ratio=friction_ratio,
                      coulomb_ratio=float(coulomb), viscous_slope=float(slope),
                      rest_ratio=rest_ratio, runs=tuple(runs))


def _still(prep: Prepared) -> float:
    """How far a reading may flicker without moving [log units], as :func:`prepare` has
    it: one encoder step plus 3 σ of its quantization, or 5 σ of an estimated noise."""
    sigma = float(prep.resolution) / math.sqrt(12.0)
    return float(prep.resolution) + 3.0 * sigma if prep.quantized else 5.0 * sigma


def is_pendulum(model) -> bool:
    """Whether ``model`` is a pendulum drop's: a :class:`~hdid.effects.Gravity` effect and
    no spring law (``--remove stiffness --add gravity``)."""
    from ..effects.gravity import Gravity

    return model.spring is None and any(isinstance(e, Gravity) for e in model.effects)


def pendulum_prepared(prep: Prepared, model, offset0: np.ndarray, release_known: bool = False):
    """``(prep, offset0)`` read as a pendulum drop when ``model`` is one (else unchanged).

    Held runs get the release found from their swing (bracket from a quarter period
    before the last sample at the release reading, never before the hold window, to the
    first sample that moved), the hold reading at release, zero weight on the samples
    before the hold window (a servo's lift, creep or flicker; a read dropout) and one
    observation's weight on the hold on an encoder grid. ``frequency_hz`` becomes the
    small-swing frequency ``ω₀/2π`` of the swings, ``offset0`` the swings' zero. With
    ``release_known`` (a release time given) the brackets stay as they are.
    """
    if not is_pendulum(model):
        return prep, offset0
    still = _still(prep)
    ratio = float(model.ratio)
    sw = drop_swings(prep, ratio, still)
    if sw is None:
        return prep, offset0
    f = sw.omega0 / (2.0 * math.pi) if math.isfinite(sw.omega0) else prep.frequency_hz
    dt = prep.sample_period
    silent = max(MAX_SILENT_START, 3.0 * dt, 0.25 / f)
    fixed = bool(release_known)
    hold, lo, hi, guess = (prep.hold.copy(), prep.release_lo.copy(), prep.release_hi.copy(),
                           prep.release_guess.copy())
    first, moving = prep.first_moved.copy(), np.array(prep.moving_start, dtype=bool).copy()
    weight, omega = prep.weight.copy(), np.array(prep.omega_guess, dtype=float).copy()
    for i, r in enumerate(sw.runs):
        if r is None or (fixed and moving[i]):
            continue
        n = int(prep.lengths[i])
        t = prep.times[i]
        k, h = r.release, r.hold_start
        hold[i], first[i], moving[i], omega[i] = r.hold, min(k + 1, n - 1), False, 0.0
        w = weight[i, :n]
        w[:h] = 0.0
        w[h: k + 1] = 1.0 / math.sqrt(k + 1 - h) if prep.quantized else 1.0
        if not fixed:
            hi[i] = t[min(k + 1, n - 1)]
            lo[i] = max(t[k] - silent, t[max(h - 1, 0)])
            guess[i] = 0.5 * (t[k] + hi[i])
    out = dataclasses.replace(
        prep, hold=hold, release_lo=lo, release_hi=hi, release_guess=guess,
        first_moved=first, moving_start=moving, weight=weight, omega_guess=omega,
        frequency_hz=float(f))
    return out, np.asarray(sw.zero, dtype=float)


def pendulum_values(prep: Prepared, model) -> list[dict[str, float]]:
    """Starting values that a drop's swings give (empty for a model that is not a
    pendulum), at the wave generator: ``mgl = N²·I·ω₀²``; the friction from the energy
    balance — Coulomb ``tau_c`` and viscous ``c_v`` from the line ``r(A)`` of the
    half-swings, ``tau_s`` at least what holds the farthest rest point. Three starts:
    Coulomb + viscous from that line; all the loss as the Coulomb level (viscous and
    Stribeck shape from their effects' rules); and a Stribeck law whose sliding and
    breakaway levels straddle the line's Coulomb level (½ and 1.5×) and give way at
    30 % of the peak speed (Armstrong-Hélouvry's Gaussian shape, ``delta = 2``)."""
    if not is_pendulum(model):
        return []
    N = float(model.ratio)
    sw = drop_swings(prep, N, _still(prep))
    if sw is None or not (math.isfinite(sw.omega0) and sw.omega0 > 0):
        return []
    inertia = float(np.median(float(model.inertia) + prep.added_inertia))
    mgl = N**2 * inertia * sw.omega0**2
    floor_cv = 1e-3 * 2.0 * math.sqrt(mgl * inertia * N**2) / N**2  # 0.1 % of critical
    c_v = max(sw.viscous_slope * 4.0 * mgl / (math.pi * sw.omega0) / N**2, floor_cv)
    hold = 1.05 * sw.rest_ratio * mgl / N
    tau_c = max(sw.coulomb_ratio * mgl / N, 1e-3 * sw.friction_ratio * mgl / N)
    amp = float(np.median([abs(r.hold - sw.zero[si]) for r, si in zip(sw.runs, prep.setup_index)
                           if r is not None])) / N
    peak = N * sw.omega0 * 2.0 * math.sin(amp / 2.0)  # a pendulum's speed through the zero
    whole = sw.friction_ratio * mgl / N
    return [
        {"mgl": mgl, "tau_c": whole, "tau_s": max(1.3 * whole, hold)},
        {"mgl": mgl, "tau_c": tau_c, "c_v": c_v, "tau_s": max(1.3 * tau_c, hold)},
        {"mgl": mgl, "tau_c": 0.5 * tau_c, "c_v": c_v, "tau_s": max(1.5 * tau_c, hold),
         "v_s": 0.3 * peak, "delta": 2.0},
    ]


def pendulum_candidates(problem, prep: Prepared, model, pack) -> list[np.ndarray]:
    """The start grid's candidates of a drop (:func:`pendulum_values`), packed by the
    grid's ``pack`` (``hdid._fitting._starts``): each free parameter of the model from
    those values where they name it, else from its ``start`` rule at the drop's scales;
    each release at the instant read from its swing, within its bracket."""
    values = pendulum_values(prep, model)
    if not values:
        return []
    from ..effects import Scales

    specs = model.parameter_specs()
    current = model.float_values()
    N = float(model.ratio)
    sw = drop_swings(prep, N, _still(prep))
    inertia = float(np.median(float(model.inertia) + prep.added_inertia))
    lo, hi = np.asarray(problem.release_lo), np.asarray(problem.release_hi)
    tr = np.array([r.t_release if r is not None else 0.5 * (a + b)
                   for r, a, b in zip(sw.runs, lo, hi)])
    tr = np.clip(tr, lo, hi)
    amp = float(np.median(np.abs(prep.hold - np.asarray(problem.offset0)[prep.setup_index])))
    out = []
    for v in values:
        k_wg = v["mgl"] / N**2
        sc = Scales(ratio=N, inertia=inertia, k_wg=k_wg, amplitude=amp,
                    speed=max(float(prep.speed) if math.isfinite(prep.speed) else 0.0,
                              sw.omega0 * amp),
                    torque=v["tau_c"], band=N * math.asin(min(sw.rest_ratio, 1.0)))
        full = dict(current)
        for n in problem.free:
            if n in v:
                full[n] = v[n]
            elif specs[n].start is not None:
                full[n] = specs[n].start(sc)
        out.append(pack(full, tr))
    return out
