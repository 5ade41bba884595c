"""The posterior's default priors: weakly informative, from the log's own physics.

Decision (a) of issue 34. Every positive physical scale the effects declare
(``AbstractEffect.posterior_prior``: a :class:`~hdid.effects.ScalePrior` per parameter —
``k1``, ``k2``, ``tau_c``, ``tau_s``, ``c_v`` and any effect's amplitudes) has a
log-normal prior whose median is a scale of the log in hand and whose central 95 % spans
a factor 10.5 on each side of it (sd 1.2 in log). A positive parameter that an effect
leaves out gets the same log-normal around its ``start`` rule (so a new effect always
brings a prior); a parameter with neither keeps the flat box of ±``PRIOR_HALF_WIDTH``
around the least-squares value. A prior of the user's (``prior=`` / ``--prior``, a
datasheet's) replaces the default of the parameters it names. ``default_prior="flat"``
restores the earlier defaults (flat in log, or in value for ``k2``, ``tau_c``, ``c_v``),
which put posterior mass on limits the data do not support and on which no sampler
measured here converged; they are an option, not the default.

The scales (:func:`prior_scales`) come from the log's readings alone, never from the fitted
values of the parameters they centre (the inertia excepted, which the user gives or the
model assumes): the release amplitude ``A`` (largest distance of a hold reading from the
set-up's zero guess), the peak speed ``v`` (largest chord between samples), the swing
frequency ``ω`` (:func:`swing_frequency`: the swings after each release fitted as a
linear spring with Coulomb friction; else the median half period between the readings'
turning points, or ``v/A`` without turns), the swing stiffness at the WG ``k_wg = J·ω²``
and the friction torque of the ring-down ``max(k_wg·(A₀ − rest)/4, 0.02·k_wg·A)`` — as
the fit's start rules (``_fitting._starts.log_scales``) compute them from the prepared
log, but for ``ω``: the turning points read the paper design's (250 Hz: two readings a
half-swing) 25 % low, k1's centre at 0.57× the truth; the swing fit puts it at 1.05×
(shipped paper log) and 1.03× (rich log), the cubic spring's stiffening included.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from ..effects import Scales, ScalePrior
from ..effects._base import SCALE_PRIOR_SD

#: The probability inside the reported prior range.
RANGE = 0.95
_Z = 1.959963984540054  # the 97.5 % point of the standard normal


class PriorSpec(NamedTuple):
    """One free parameter's prior: ``kind`` (``"log-normal"``, ``"logit-normal"``,
    ``"normal"``, ``"datasheet"`` (the user's), ``"flat box"``, ``"flat in value"``),
    ``mean``/``sd`` in the transformed space (NaN for the flat ones), and ``source``."""

    kind: str
    mean: float
    sd: float
    source: str


def prior_scales(problem) -> Scales:
    """The log's magnitudes (:class:`~hdid.effects.Scales`) from the problem's readings
    (module docstring): amplitude, peak speed, swing frequency, friction torque."""
    theta = np.asarray(problem.theta, dtype=float)
    times = np.asarray(problem.times, dtype=float)
    weight = np.asarray(problem.weight, dtype=float)
    off = np.asarray(problem.offset0, dtype=float)[np.asarray(problem.setup_index)]
    hold = np.asarray(problem.hold, dtype=float)
    moving = np.zeros(theta.shape[0], dtype=bool)
    if problem.moving_index is not None and np.size(problem.moving_index):
        moving[np.asarray(problem.moving_index, dtype=int)] = True
    step = float(problem.step)
    inertia = float(np.median(float(problem.base.inertia)
                              + np.asarray(problem.added_inertia, dtype=float)))
    theta0 = np.abs(hold - off)
    excursion = np.max(np.abs(theta - off[:, None]), axis=1)
    amp = float(np.max(np.where(moving, excursion, theta0)))
    if not amp > 0:
        amp = float(np.max(excursion)) or step
    dt = np.diff(times, axis=1)
    dth = np.abs(np.diff(theta, axis=1))
    with np.errstate(divide="ignore", invalid="ignore"):
        speed = float(np.max(np.where(dt > 0, dth / np.where(dt > 0, dt, 1.0), 0.0)))
    half = []
    for r in range(theta.shape[0]):
        on = weight[r] >= 1.0  # the motion (not the hold or the stuck tail)
        t, th = times[r][on], theta[r][on]
        if th.size < 3:
            continue
        from .._simulation._prepare import turning_points

        tp = turning_points(th, max(2.0 * step, 1e-300))
        if len(tp) >= 2:
            half.extend(np.diff(t[np.asarray(tp)]))
    half = np.asarray([h for h in half if h > 0])
    w = math.pi / float(np.median(half)) if half.size else (speed / amp if amp > 0 else 1.0)
    if not (math.isfinite(w) and w > 0):
        w = 1.0
    w = swing_frequency(problem, moving, w) or w
    k_wg = inertia * w**2
    rest = np.abs(theta[:, -1] - off)  # padded runs repeat their last reading
    held = ~moving
    lost = float(np.median(theta0[held] - np.minimum(rest[held], theta0[held]))) if held.any() else 0.0
    torque = max(k_wg * lost / 4.0, 0.02 * k_wg * amp)
    speed = max(speed, w * amp)
    return Scales(ratio=float(problem.base.ratio), inertia=inertia, k_wg=k_wg, amplitude=amp,
                  speed=speed, torque=torque, band=float(np.max(rest)))


def default_priors(problem, default: str = "weak") -> dict[str, PriorSpec]:
    """Each free physical parameter's default prior (before a user's ``prior=``):
    ``default="weak"`` (the default: module docstring) or ``"flat"`` (the earlier flat
    priors; the effects' tuple priors — ``v_s``, ``delta`` — are kept in both)."""
    from .._models._transforms import to_unconstrained

    if default not in ("weak", "flat"):
        from .errors import PosteriorError

        raise PosteriorError(f"default_prior must be 'weak' or 'flat', not {default!r}")
    specs = problem.base.parameter_specs()
    free = list(problem.free)
    scales = prior_scales(problem)
    mean0 = np.asarray(problem.prior_mean, dtype=float)
    declared: dict[str, tuple] = {}
    for e in problem.base.effects:
        for n, d in e.posterior_prior.items():
            if n in free:
                declared[n] = (type(e).__name__, d)
    out = {}
    for i, n in enumerate(free):
        spec = specs[n]
        owner, d = declared.get(n, (None, None))
        if isinstance(d, ScalePrior) and default == "flat":
            d = None
        if d is None and default == "weak" and spec.transform == "log" and spec.start is not None:
            d = ScalePrior(spec.start, "its effect's start rule (no posterior_prior declared)",
                           SCALE_PRIOR_SD)
        if isinstance(d, ScalePrior):
            c = float(d.centre(scales))
            if spec.transform == "log" and not (math.isfinite(c) and c > 0):
                c = math.exp(mean0[i])  # a degenerate log (no swing): the fit's start
            out[n] = PriorSpec(_kind(spec), float(to_unconstrained(spec, c)), float(d.sd),
                               d.source)
        elif d is not None:
            centre, sd = d
            if centre is None:
                m = float(mean0[i])
                src = f"{owner}.posterior_prior, centred on the fit's start rule from the log"
            else:
                m = float(to_unconstrained(spec, centre))
                src = f"{owner}.posterior_prior (median {centre:g})"
            out[n] = PriorSpec(_kind(spec), m, float(sd), src)
        elif spec.flat_in_value and spec.transform == "log":
            out[n] = PriorSpec("flat in value", math.nan, math.nan,
                               "flat in the value within the box (default_prior='flat')")
        else:
            out[n] = PriorSpec("flat box", math.nan, math.nan,
                               "flat in the transformed space within the box around the fit")
    return out


def _kind(spec) -> str:
    t = spec.transform
    return "log-normal" if t == "log" else "normal" if t == "identity" else "logit-normal"


def with_user(defaults: dict[str, PriorSpec], problem, prior: dict | None) -> dict[str, PriorSpec]:
    """``defaults`` with the user's Gaussian priors (``{name: (centre value, sd)}``) in
    place of the parameters they name (validated by ``density.gaussian_prior``)."""
    from .._models._transforms import to_unconstrained

    specs = problem.base.parameter_specs()
    out = dict(defaults)
    for n, (centre, sd) in (prior or {}).items():
        out[n] = PriorSpec("datasheet", float(to_unconstrained(specs[n], centre)), float(sd),
                           f"the user's prior (prior= / --prior {n}=VALUE,SD)")
    return out


def prior_table(problem, priors: dict[str, PriorSpec], u_fit, half_width: float
                ) -> dict[str, dict]:
    """Per free parameter, what the report and JSON show of its prior: ``kind``, median
    (``centre``) and central 95 % range (``ci95``) in the parameter's unit, the sd in the
    transformed space, and where its scale came from (``source``). A flat prior shows its
    box (±``half_width`` in the transformed space around the least-squares ``u_fit``) as
    its range and no centre."""
    from .._models._transforms import from_unconstrained

    specs = problem.base.parameter_specs()
    out = {}
    for i, n in enumerate(problem.free):
        p = priors[n]
        row = {"kind": p.kind, "source": p.source, "centre": None, "ci95": None,
               "sd_transformed": None}
        if math.isfinite(p.mean):
            lo, mid, hi = (float(from_unconstrained(specs[n], p.mean + z * p.sd, np))
                           for z in (-_Z, 0.0, _Z))
            row.update(centre=mid, ci95=[lo, hi], sd_transformed=p.sd)
        else:
            c = float(u_fit[i])
            row["ci95"] = [float(from_unconstrained(specs[n], c - half_width, np)),
                           float(from_unconstrained(specs[n], c + half_width, np))]
        out[n] = row
    return out


def finish(result, basin, prior, default_prior, half_width: float):
    """``result`` with the table of the priors it was sampled under (:func:`prior_table`,
    with each parameter's posterior/prior width; flat ones in the box of ±``half_width``)
    and the basin check's record (its statement first in the warnings, then the line saying
    a needed check could not refit for want of the log)."""
    prob = result.fit.problem
    specs = with_user(default_priors(prob, default_prior), prob, prior)
    table = prior_table(prob, specs, np.asarray(result.fit.u, dtype=float), half_width)
    for n, row in table.items():
        w = result.widths.get(n, {})
        row["posterior_over_prior_width"] = w.get("posterior_over_prior_width")
        row["set_by_prior"] = w.get("set_by_prior")
    result.priors = table
    result.default_prior = default_prior
    result.basin = basin.to_dict()
    if basin.unchecked:  # a needed check could not refit: after the statement, if any
        result.warnings.insert(0, basin.unchecked)
    if basin.statement:
        result.warnings.insert(0, basin.statement)
    return result


#: Half-swings of the Coulomb oscillator modelled after a release (:func:`_coulomb_swing`).
MAX_HALF_SWINGS = 24


def _coulomb_swing(t, a0, t_r, w, d):
    """Angle (relative to the spring's zero) at times ``t`` of a linear oscillator of
    frequency ``w`` with Coulomb friction ``d`` (the friction torque over the stiffness, an
    angle) released from rest at ``a0`` at ``t_r``: each half-swing is a cosine about a
    centre shifted by ``d`` against the motion, the turning points shrink by ``2d`` a
    half-swing, and it sticks at the first turning point within ``d`` of zero."""
    sgn = 1.0 if a0 >= 0 else -1.0
    starts, centres = [a0], []
    while abs(starts[-1]) > d and len(centres) < MAX_HALF_SWINGS:
        c = sgn * (-1) ** len(centres) * d
        centres.append(c)
        starts.append(2 * c - starts[-1])
    phase = np.maximum(w * (t - t_r), 0.0)
    k = np.minimum(np.floor(phase / math.pi).astype(int), len(centres))
    st, ce = np.asarray(starts), np.asarray(centres + [0.0])
    swing = ce[k] + (st[k] - ce[k]) * np.cos(phase - k * math.pi)
    return np.where(k < len(centres), swing, st[-1])


def swing_frequency(problem, moving, w0: float) -> float | None:
    """The swing frequency ``ω`` [rad/s] of the log's releases from a hold: every such run's
    readings from its last hold reading to its rest, fitted together (least squares in the
    readings' own angle, relative to the set-up's zero guess) by :func:`_coulomb_swing` —
    one ``ω`` and one friction shift for the log, a release instant per run within its
    bracket — from six starts ``w0 × 0.4 … 3``. The half period between turning points (the
    fallback ``w0``) needs several swings of several samples each; a paper-design log
    (250 Hz) has one or two half-swings of two samples a run, and it read the shipped
    log's ω 25 % low. ``None`` when no run is released from a hold or the fit does not
    describe the readings (RMS residual above a tenth of the release amplitude)."""
    from scipy.optimize import least_squares

    theta = np.asarray(problem.theta, dtype=float)
    times = np.asarray(problem.times, dtype=float)
    weight = np.asarray(problem.weight, dtype=float)
    off = np.asarray(problem.offset0, dtype=float)[np.asarray(problem.setup_index)]
    lo, hi = np.asarray(problem.release_lo, dtype=float), np.asarray(problem.release_hi, dtype=float)
    runs = []
    for r in range(theta.shape[0]):
        on = np.flatnonzero(weight[r] >= 1.0)
        if moving[r] or on.size < 2:
            continue
        i = np.arange(max(on[0] - 1, 0), min(on[-1] + 3, theta.shape[1]))
        a0 = float(problem.hold[r] - off[r])
        if a0 == 0:
            continue
        runs.append((times[r][i], theta[r][i] - off[r], a0, float(lo[r]), float(hi[r])))
    if not runs or not (math.isfinite(w0) and w0 > 0):
        return None
    scale = max(abs(x[2]) for x in runs)

    def res(p):
        w, d = math.exp(p[0]), scale * p[1]
        out = []
        for (t, y, a0, l, h), tr in zip(runs, p[2:]):
            t_r = l + (h - l) / (1.0 + math.exp(-tr))
            out.append((_coulomb_swing(t, a0, t_r, w, d) - y) / scale)
        return np.concatenate(out)

    best = None
    for f in (0.4, 0.6, 0.9, 1.3, 2.0, 3.0):
        for d0 in (0.1,):
            p0 = np.concatenate([[math.log(f * w0), d0], np.zeros(len(runs))])
            lb = np.concatenate([[-np.inf, 0.0], np.full(len(runs), -8.0)])
            ub = np.concatenate([[np.inf, 1.0], np.full(len(runs), 8.0)])
            try:
                r = least_squares(res, p0, bounds=(lb, ub), method="trf", max_nfev=200)
            except (ValueError, FloatingPointError):
                continue
            if best is None or r.cost < best.cost:
                best = r
    if best is None:
        return None
    rms = math.sqrt(2 * best.cost / best.fun.size)
    w = math.exp(best.x[0])
    return w if rms < 0.1 and math.isfinite(w) and w > 0 else None
