"""The limits a fit's model may reach: fitted, restarted from, and named in the result.

A free-motion model nests simpler ones that the data may choose:

- ``coulomb``: a Stribeck law with ``tau_s = tau_c`` is Coulomb friction (``v_s``,
  ``delta`` then act on nothing);
- ``no_friction``: with the dry friction law removed (``tau_c``, ``tau_s`` → 0) the
  model is viscous-only (with gravity and no spring: the gravity-only pendulum);
- ``no_cubic``: a cubic spring with ``k2 → 0`` is the linear spring.

The full model's least-squares optimum can never be worse than a limit's, yet a
multi-start fit can end worse: a clean 1 kHz log of an independent simulator ended at
3.55× the quantization floor with ``tau_s < tau_c`` and ``c_v → 0``; the Silverbox
ring-downs (a Duffing oscillator, no friction) put their exponential decay into Coulomb
friction; on the shipped paper log the linear-spring limit has χ² 11.8 against the
reported 24.0. :func:`check` fits each limit inside the full model — its parameters held
by strong prior rows (:func:`pinned`: ``v_s`` → 1000× the peak speed for Coulomb
friction at ``tau_s``; ``tau_c``, ``tau_s`` at ``NUDGE`` × the spring torque; ``k2`` at
``NUDGE`` × its start), from the fit's optimum and ``LIMIT_GRID_STARTS`` grid starts,
through the one-lane program of the fit's own structure (nothing new to compile beyond
it) — then restarts the full model from each limit's optimum (released; from the
Coulomb limit with a few Stribeck shapes), keeps the best optimum, and records every
limit in ``result.limits`` (``limit``, ``chi2``, ``chi2_fit``, ``dchi2``, ``dof``,
``fits_as_well``, ``fits_better``) and ``result.restarted_from``. A limit that fits as
well by the likelihood-ratio rule (Δχ² below the ``LIMIT_LEVEL`` point of χ² with the
limit's degrees of freedom) is named in a warning ("friction not supported: the
viscous-only model fits as well"); a limit that still fits better than the reported fit
is never silent.

A fit still above the floor after its limits, or with ``c_v`` gone to 0
(:func:`viscous_gone`), restarts once more from its best optimum with a regular Stribeck law at its sliding level and the viscous share spanned
(:func:`stribeck_restarts`; ``restarted_from`` ``"stribeck"`` when one wins): poorer basins
of clean logs put the damping into the Stribeck shape (``c_v → 0``) or into a creeping law
(``tau_s ≪ tau_c``), which no limit undoes (clean paper logs 49, 103, 129 of
``docs/decisions/limits-at-the-floor.md``: 2.24, 2.28, 1.56× → 0.82, 0.98, 0.88× the floor).

At the floor a limit nested in another that already fits worse by its own bound is not
fitted (:func:`implied`: the viscous-only model is the Coulomb limit at ``tau_s → 0``; its
row has ``chi2_at_least``): that ringing fit was 60 % of the shipped paper log's checks.

When (:func:`wanted`): a residual above :func:`above_floor` × the floor (the fit has not
reached it: every limit), or a symptom that a term may vanish — the parameter a limit
removes has a relative sd above ``VANISH_REL_SD`` or none finite, or ``tau_s ≤ tau_c``
(that limit only). A fit at the floor with every term determined runs none.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable

import numpy as np
# the χ² quantile as scipy.stats.chi2.ppf computes it (2·gammaincinv(ν/2, q)), without
# importing scipy.stats (~0.5 s CPU of every cold command)
from scipy.special import gammaincinv

from ..effects import AbstractFriction, StribeckFriction
from ..effects.stiffness import CubicStiffness
from ._unknowns import PIN_SD, data_chi2, pinned, with_values, with_values_rows  # noqa: F401

#: Probability of the likelihood-ratio test by which a limit "fits as well": its χ² above
#: the full model's is below the ``LIMIT_LEVEL`` point of χ² with as many degrees of
#: freedom as the limit removes free parameters (3.84 for k2, 7.81 for the Coulomb
#: limit's tau_s, v_s, delta, 9.49 for the four of a Stribeck law).
LIMIT_LEVEL = 0.95
#: A term "may vanish" when the linearised sd of its coefficient exceeds this fraction of
#: its value: its vanishing end is then within 5 sd (Δχ² ≤ 25 linearised), where a curved
#: cost may well reach it (the posterior's limit screen, ``LIMIT_SCREEN_REL_SD``: the
#: shipped paper log's k2 is at 34 %, and its linear-spring limit has χ² 11.8 against the
#: fit's 24.0 from another basin). Each limit costs a few runs of the fit's own compiled
#: Levenberg–Marquardt program.
VANISH_REL_SD = 0.2
#: A limit holds a removed torque at ``NUDGE`` × the spring torque at the log's
#: amplitude, ``k2`` at ``NUDGE`` × its start (17 % of the spring torque at the largest
#: twist): Coulomb friction ``ε`` takes ``2ε/k`` of amplitude a half-swing, 2e-6 of it,
#: under 0.2 of a count after a thousand half-swings of a paper-size release; the cubic
#: shifts the frequency by ~1e-7 (at 1e-3 a frictionless 1 kHz log's limit was 4700 χ²
#: above the fit that had friction at 3e-9 N m). The full model's restart from the limit
#: starts there, i.e. at the limit's χ², and can only end lower.
NUDGE = 1e-6
#: ``tau_s`` above ``tau_c`` in a restart (the Stribeck rise has no gradient at equality).
RESTART_RATIO = 1.02
#: Relative χ² margin within which two optima are the same (LM stopping tolerance 1e-6 a
#: step, starts that converge together agree to ~1e-4).
SAME_MARGIN = 1e-3
#: The Coulomb limit's Stribeck velocity, a multiple of the log's peak speed: the
#: Stribeck factor ``exp(−|ω/v_s|^delta)`` is then 1 within 1e-3 at every logged speed.
COULOMB_V_S = 1e3
#: The full model's restarts from the Coulomb limit: Stribeck shapes (``v_s`` as a
#: fraction of the log's peak speed, ``delta``) spanning the law's prior (5 % of the peak
#: speed, sd 1 in log; delta 0.5–2.5): a 3 × 2 grid ...
COULOMB_RESTART_SHAPES = tuple((f, d) for f in (0.05, 0.15, 0.4) for d in (1.0, 2.5))
#: ... and ``(tau_c, tau_s)`` as multiples of the limit's level: just off the limit (the
#: limit's ``c_v``), and a rise of 1.7 (the level lies between sliding and breakaway
#: friction) with ``c_v`` at its start rule (5 % of critical): poorer basins of clean
#: logs put ``c_v → 1e-9`` and the damping into the Stribeck shape.
COULOMB_RESTART_LEVELS = ((1.0 / RESTART_RATIO, 1.0), (0.75, 1.3))
#: Restarts of a fit still above the floor after its limits (:func:`stribeck_restarts`):
#: the share of critical damping ``2·√(k_wg·I)`` given to ``c_v`` (``None``: the fit's
#: own). Poorer basins of clean logs trade the viscous loss (exponential decay) against
#: the Stribeck shape or a creeping law (``tau_s ≪ tau_c``); the sliding level ``tau_c``
#: (the linear decrement) is what they keep. Harmonic-drive grease damps 1–10 % of
#: critical (the clean-floor plant: 1–14 %), so the restarts span 1, 3 and 10 %.
VISCOUS_RESTART_SHARES = (None, 0.01, 0.03, 0.1)
#: The speed, a fraction of the log's peak, at which those restarts read the fitted
#: friction level: a swing spends most of its path between half and full speed, where
#: the level sets the amplitude decrement (a clean paper log ended with ``v_s`` 80 rad/s
#: above its 60 rad/s peak and ``tau_s < tau_c``: its friction on the swings was
#: ``tau_s``, not the ``tau_c`` it never reaches).
LEVEL_SPEED = 0.5
#: Grid starts of a limit's own fit, beside the warm start at the full fit.
LIMIT_GRID_STARTS = 2
#: Whether a fit that has reached the floor (:func:`reached_floor`) is still replaced by
#: a restart from a limit that ends lower. False: a fit at the floor keeps its optimum and
#: a better limit is a warning ("fits better", never silent); above the floor the best
#: optimum is always kept. Why: at the floor the residuals are rounding errors, and an
#: optimum far below the floor fits the rounding itself, where the Gaussian likelihood is
#: not the quantizer's. The shipped paper log shows it: its fit at 0.83x the floor
#: (chi2 24.0, nu = 35) is consistent with rounding; the linear-spring basin's chi2 11.8
#: lies below chi2_35's 0.1 % point (14.7) and has k1 +13 % from its truth, tau_s 2.2x and
#: a stick band 0.093 +- 0.001 rad against the true 0.047 (the data bracket it to
#: [0.036, 0.094]): adopting it would trade honest wide errors for confident wrong ones.
KEEP_BETTER_AT_FLOOR = False
FLOOR_TAIL = 1e-3  # tail probability of the floor test (:func:`above_floor`)
#: Smallest trigger multiple of the floor: exact models leave 0.4–1.0× it (less where the
#: gear sticks); the simulator's own error is ≤ 0.04× of it.
FLOOR_MIN = 1.2


def _chi2_ppf(q: float, dof: float) -> float:
    """The ``q`` quantile of χ² with ``dof`` degrees of freedom (``0 < q < 1``)."""
    return float(2.0 * gammaincinv(dof / 2.0, q))


def above_floor(n_effective: float, n_unknowns: float = 0) -> float:
    """Multiple of the floor above which a residual has not reached it: at the floor the
    residuals are rounding errors, and a fit of ``n_unknowns`` to ``n`` effective samples
    leaves RMS² ≈ floor²·χ²_ν/n, ν = n − n_unknowns (Gaussian errors: uniform rounding
    errors scatter less, kurtosis 1.8 against 3, so this is conservative); the
    ``1 − FLOOR_TAIL`` point of √(χ²_ν/n) (1.38 for n = 35 and no unknowns, 1.10 with the
    shipped paper log's 17; 1.14 for n = 500), at least ``FLOOR_MIN``. The unknowns
    matter where they are many for the samples: a world log, 18 effective readings for 10
    unknowns, sat at 1.3–1.5× in a poorer basin under the 1.53× that ν = n allows."""
    n = max(float(n_effective), 1.0)
    nu = max(n - max(float(n_unknowns), 0.0), 1.0)
    return max(FLOOR_MIN, math.sqrt(_chi2_ppf(1.0 - FLOOR_TAIL, nu) / n))


@dataclass(frozen=True)
class Limit:
    """One nested limit of a model, reached inside the model itself: ``pins(values,
    scales)`` gives the values at which the limit holds its parameters (strong prior rows
    on the fit's own problem: the same compiled programs), ``restarts(values, scales)``
    the full model's starts next to the limit's optimum ``values``."""

    key: str
    label: str
    #: free parameters the limit removes (its degrees of freedom)
    removed: tuple[str, ...]
    #: the claim when the limit fits as well
    claim: str
    pins: Callable[[dict, object], dict]
    restarts: Callable[[dict, object], list]
    #: values a start of the limit's fit takes from its own and the log's scales (e.g. the
    #: Coulomb level)
    start: Callable[[dict, object], dict] = lambda v, scales: {}
    #: keys of limits whose model contains this one's (:func:`implied`)
    within: tuple[str, ...] = ()


def limits_of(model, fixed) -> list[Limit]:
    """The limits of ``model`` with ``fixed`` parameters held (only limits that remove a
    free parameter)."""
    out = []
    law = model.friction
    specs = model.parameter_specs()
    viscous_start = (specs["c_v"].start if "c_v" in specs and "c_v" not in fixed
                     and specs["c_v"].start is not None else None)
    if type(law) is StribeckFriction and not {"tau_c", "tau_s", "v_s"} & set(fixed):
        # v_s → ∞: the Stribeck factor is 1 at every speed, friction is tau_s sliding and
        # holding, i.e. Coulomb friction at tau_s (tau_c and delta then act on nothing)
        def coulomb_pins(v, scales):
            return {"v_s": COULOMB_V_S * scales.speed}

        def coulomb_restarts(v, scales):
            level = v["tau_s"]
            rows = []
            for f, d in COULOMB_RESTART_SHAPES:
                for (lo, hi), c_v in zip(COULOMB_RESTART_LEVELS, (None, viscous_start)):
                    row = {"tau_c": level * lo, "tau_s": level * hi,
                           "v_s": f * scales.speed, "delta": d}
                    if c_v is not None and "c_v" in v:
                        row["c_v"] = c_v(scales)  # out of a c_v → 0 corner
                    rows.append(row)
            return rows

        out.append(Limit("coulomb", "Coulomb friction (tau_s = tau_c)",
                         tuple(n for n in ("tau_s", "v_s", "delta") if n not in fixed),
                         "no Stribeck rise supported: Coulomb friction (tau_s = tau_c) fits "
                         "as well", coulomb_pins, coulomb_restarts,
                         # the limit's level is tau_s: a start's sliding level on the
                         # swings (a fit's tau_c → 0 with v_s above the peak speed slides
                         # at tau_s: HV log09, tau_s = tau_c there started frictionless)
                         lambda v, scales: {"tau_s": sliding_level(v, scales)}))
    if isinstance(law, AbstractFriction):
        torques = tuple(p.name for p in law.parameters if p.unit == "N m"
                        and p.name not in fixed)
        if torques and all(n in ("tau_c", "tau_s") for n in torques):
            gravity = "gravity" in model.effect_names and model.spring is None
            viscous = "viscous" in model.effect_names
            what = ("the gravity-only pendulum" if gravity
                    else "the viscous-only model" if viscous else "the model without friction")

            def off_pins(v, scales, torques=torques):
                eps = NUDGE * scales.k_wg * scales.amplitude
                return {n: eps * (RESTART_RATIO if n == "tau_s" else 1.0) for n in torques}

            # the Coulomb limit at tau_s → NUDGE (tau_c there too) is this limit
            within = tuple(lim.key for lim in out if lim.key == "coulomb")
            out.append(Limit("no_friction", what.removeprefix("the "),
                             tuple(p.name for p in law.parameters if p.name not in fixed),
                             f"friction not supported: {what} fits as well", off_pins,
                             lambda v, scales: [{}], within=within))
    if type(model.spring) is CubicStiffness and "k2" not in fixed:
        def k2_pins(v, scales, spec=model.parameter_specs()["k2"]):
            return {"k2": NUDGE * spec.start(scales)}

        out.append(Limit("no_cubic", "linear spring (k2 = 0)", ("k2",),
                         "no cubic stiffness supported: the linear spring (k2 = 0) fits as "
                         "well", k2_pins, lambda v, scales: [{}]))
    return out


def sliding_level(values: dict, scales):
    """The fitted Stribeck friction at ``LEVEL_SPEED`` of the log's peak speed (arrays of
    values give arrays)."""
    shape = np.exp(-(LEVEL_SPEED * scales.speed / np.asarray(values["v_s"], dtype=float))
                   ** np.asarray(values["delta"], dtype=float))
    return values["tau_c"] + (values["tau_s"] - values["tau_c"]) * shape


def stribeck_restarts(values: dict, scales, fixed) -> list[dict]:
    """Full-model restarts for a fit still above the floor after its limits: a regular
    Stribeck law (``tau_s`` 1.3, ``tau_c`` 0.75 × the fitted friction at half the log's
    peak speed, ``LEVEL_SPEED``: the sliding level ``tau_c`` where the fitted ``v_s`` lies
    below the swing's speeds, ``tau_s`` where a fit put ``v_s`` above them) in
    the Coulomb restarts' shapes (``COULOMB_RESTART_SHAPES``), with ``c_v`` at the fit's
    own value and at ``VISCOUS_RESTART_SHARES`` of critical damping (module constants);
    empty unless the model has a free Stribeck law and a free ``c_v``."""
    names = ("tau_c", "tau_s", "v_s", "delta", "c_v")
    if set(names) & set(fixed) or not all(n in values for n in names):
        return []
    shape = math.exp(-(LEVEL_SPEED * scales.speed / values["v_s"]) ** values["delta"])
    level = values["tau_c"] + (values["tau_s"] - values["tau_c"]) * shape
    critical = 2.0 * math.sqrt(scales.k_wg * scales.inertia)
    rows = []
    for share in VISCOUS_RESTART_SHARES:
        c_v = values["c_v"] if share is None else share * critical
        for f, d in COULOMB_RESTART_SHAPES:
            rows.append({"tau_c": 0.75 * level, "tau_s": 1.3 * level, "v_s": f * scales.speed,
                         "delta": d, "c_v": c_v})
    return rows


#: ``c_v`` below this fraction of critical damping ``2·√(k_wg·I)`` has run towards 0 (the
#: poorer basin that put the damping into the Stribeck shape): a 0.157 rad swing then loses
#: 2π·5e-8·100·0.157 = 5e-6 rad in 100 cycles, 0.1 of a 131072-count step.
VISCOUS_GONE = 1e-7


def viscous_gone(values: dict, scales, fixed) -> bool:
    """Whether a free ``c_v`` has run towards 0 (``VISCOUS_GONE``): then the
    :func:`stribeck_restarts` run although the fit is at the floor (a 500 Hz sweep log at
    1.07× the floor, Δχ² 65 above its truth, ``tau_c`` +21 %; restarted: +0.3 %)."""
    if "c_v" in fixed or "c_v" not in values:
        return False
    critical = 2.0 * math.sqrt(scales.k_wg * scales.inertia)
    return bool(values["c_v"] < VISCOUS_GONE * critical)


def vanishing(result, limit: Limit) -> bool:
    """Whether ``result`` shows a symptom that ``limit``'s term may vanish (module doc)."""
    if limit.key == "coulomb":
        tc, ts = result.values["tau_c"], result.values["tau_s"]
        est = result.parameters["tau_s"]
        if not (ts > RESTART_RATIO * tc and est.std <= VANISH_REL_SD * (ts - tc)):
            return True
        names = ("v_s", "delta")
        return any(not math.isfinite(result.parameters[n].std) for n in names
                   if n in result.parameters and not result.parameters[n].fixed)
    elif limit.key == "no_friction":
        names = tuple(n for n in ("tau_c", "tau_s") if n in limit.removed) or limit.removed
    else:
        names = limit.removed
    for n in names:
        est = result.parameters.get(n)
        if est is None or est.fixed:
            continue
        if not (math.isfinite(est.std) and est.std <= VANISH_REL_SD * abs(est.value)):
            return True
    return False


def wanted(result, fixed, nested) -> list[Limit]:
    """The limits :func:`check` fits for ``result``: ``nested`` True all, False none,
    ``"auto"`` all above the floor (:func:`above_floor`), else those with a symptom."""
    if nested is False:
        return []
    limits = limits_of(result.model, fixed)
    if nested is True or not reached_floor(result):
        return limits
    return [lim for lim in limits if vanishing(result, lim)]


def needs_check(result, fixed) -> bool:
    """Whether ``nested="auto"`` fits any limit for ``result`` (:func:`wanted`)."""
    return bool(wanted(result, fixed, "auto"))


def reached_floor(result) -> bool:
    floor = result.quantization_floor_rad
    rms = result.rms_residual_rad
    if not (math.isfinite(rms) and floor > 0):
        return False
    return rms <= above_floor(result.n_effective, result.n_unknowns) * floor


@dataclass
class LimitOutcome:
    """A limit fitted on the log: its best optimum's data χ² and values."""

    limit: Limit
    chi2: float
    values: dict
    #: its unknowns (the full model's, the limit's parameters held)
    u: np.ndarray | None
    #: not fitted: ``chi2`` is then a lower bound, the χ² of this enclosing limit
    #: (:func:`implied`)
    implied_by: str | None = None

    def to_dict(self, chi2_fit: float) -> dict:
        q = len(self.limit.removed)
        d = self.chi2 - chi2_fit
        bound = _chi2_ppf(LIMIT_LEVEL, q)
        row = {"limit": self.limit.key, "label": self.limit.label,
               "removed": list(self.limit.removed), "chi2": self.chi2,
               "chi2_fit": chi2_fit, "dchi2": d, "dof": q, "dchi2_bound": bound,
               "fits_as_well": bool(d < bound),
               "fits_better": bool(d < -SAME_MARGIN * max(abs(chi2_fit), 1.0))}
        if self.implied_by is not None:  # a bound, not a fit: no χ² of its own
            row.update(chi2=None, dchi2=None, chi2_at_least=self.chi2, dchi2_at_least=d,
                       implied_by=self.implied_by)
        return row


def implied(limit: Limit, outcomes: list, chi2_fit: float) -> LimitOutcome | None:
    """``limit``'s verdict without fitting it, or ``None``: when a limit whose model
    contains ``limit``'s (``limit.within``; the Coulomb limit at ``tau_s`` → 0 has no
    friction) was fitted and already lies ``limit``'s bound or more above the fit
    (Δχ² ≥ the ``LIMIT_LEVEL`` point of χ² with ``limit``'s degrees of freedom), the
    nested limit's χ², never below the enclosing one's (its multi-start optimum standing
    for its minimum, as everywhere here), cannot fit as well. Its row then
    carries that χ² as ``chi2_at_least`` (``implied_by`` the enclosing limit's key).
    Only for a fit at the floor, where a limit is a verdict; above it each limit's own
    optimum is also a restart of the full model (:func:`check`)."""
    bound = _chi2_ppf(LIMIT_LEVEL, len(limit.removed))
    for o in outcomes:
        if (o.limit.key in limit.within and o.implied_by is None
                and o.chi2 - chi2_fit >= bound):
            return LimitOutcome(limit, o.chi2, {}, None, implied_by=o.limit.key)
    return None


def verdict_cost(result, solutions) -> float:
    """The cost below which a limit's optimum fits better than ``result`` (and so as
    well: :meth:`LimitOutcome.to_dict`), ``solutions`` ``(U, costs, …)`` holding its
    optimum: a fit at the floor, where a limit is only a verdict, stops a limit's fit
    once one of its starts converges below it (:class:`hdid._fitting._lm._Schedule`'s
    ``stop_below``; a cost, data χ² plus prior rows, is never below its data χ²)."""
    U, costs = np.asarray(solutions[0]), np.asarray(solutions[1])
    chi2_fit = data_chi2(result.problem, result.u, _cost_of(result, U, costs))
    return chi2_fit - SAME_MARGIN * max(abs(chi2_fit), 1.0)


def check(result, solutions, limits, fit_limit, restart, finish, switch: bool = True,
          again=None) -> object:
    """Fit ``limits`` for ``result``, restart the full model from each, keep the best.

    ``solutions`` ``(U, costs, ok, steps)``: the full model's local fits so far;
    ``fit_limit(limit)`` → :class:`LimitOutcome` (or ``None``); ``restart(limit,
    outcome)`` → ``(U, costs, ok, steps)`` of the full model's local fits started next to
    the limit's optimum (``limit.nudges``); ``finish(U, costs, ok, steps)`` analyses the
    best (``switch`` False: no restarts, the result is kept and only named); ``again(u,
    cost)`` → ``(U, costs, ok, steps)`` or ``None``: more full-model restarts from the best
    optimum so far (:func:`stribeck_restarts`, key ``"stribeck"``). Returns the
    result (a new one when a restart won) with ``limits`` (list of dicts) and
    ``restarted_from`` (the limit key, or ``None``) set, and the warnings. With ``switch``
    False a limit :func:`implied` by one fitted before it is not fitted."""
    U, costs, ok, steps = (np.asarray(a) for a in solutions)
    outcomes, won = [], None
    chi2_now = data_chi2(result.problem, result.u, _cost_of(result, U, costs))
    for lim in limits:
        out = None if switch else implied(lim, outcomes, chi2_now)
        out = fit_limit(lim) if out is None else out
        if out is None:
            continue
        outcomes.append(out)
        if not switch:
            continue
        U1, c1, ok1, s1 = restart(lim, out)
        if len(U1):
            U, costs = np.concatenate([U, U1]), np.concatenate([costs, c1])
            ok, steps = np.concatenate([ok, ok1]), np.concatenate([steps, s1])
            c = float(np.nanmin(np.where(np.isfinite(c1), c1, np.inf)))
            cur = float(np.nanmin(np.where(np.isfinite(costs[:-len(c1)]),
                                           costs[:-len(c1)], np.inf)))
            if c < cur * (1 - SAME_MARGIN):
                won = lim.key
    if switch and again is not None:
        cf = np.where(np.isfinite(costs), costs, np.inf)
        b = int(np.argmin(cf))
        more = again(U[b], float(cf[b]))
        if more is not None and len(more[0]):
            U1, c1, ok1, s1 = (np.asarray(a) for a in more)
            U, costs = np.concatenate([U, U1]), np.concatenate([costs, c1])
            ok, steps = np.concatenate([ok, ok1]), np.concatenate([steps, s1])
            if float(np.min(np.where(np.isfinite(c1), c1, np.inf))) < cf[b] * (1 - SAME_MARGIN):
                won = "stribeck"
    if won is not None:
        result = finish(U, costs, ok, steps)
    chi2_fit = data_chi2(result.problem, result.u, _cost_of(result, U, costs))
    rows = [o.to_dict(chi2_fit) for o in outcomes]
    result.limits = rows
    result.restarted_from = won
    # (Coulomb friction "fits as well" says nothing more when no friction does)
    no_friction = any(r["fits_as_well"] for r in rows if r["limit"] == "no_friction")
    for r, o in zip(rows, outcomes):
        if r["fits_better"]:
            result.warnings.append(
                f"the {r['label']} limit fits better (χ² {r['chi2']:.4g}) than the reported "
                f"fit (χ² {chi2_fit:.4g})"
                + (", even with the full model restarted from it" if switch else
                   " (the fit is at the floor and keeps its optimum)")
                + f": this log does not determine {', '.join(o.limit.removed)}; fit the "
                "limit's model, or compare both")
        elif r["fits_as_well"] and not (no_friction and r["limit"] == "coulomb"):
            result.warnings.append(
                f"{o.limit.claim} (χ² {r['chi2']:.4g} against {chi2_fit:.4g}: Δχ² "
                f"{r['dchi2']:.3g} < {r['dchi2_bound']:.3g}, the {100 * LIMIT_LEVEL:.0f} % "
                f"point of χ² with {r['dof']} degree(s) of freedom); "
                f"the log does not require {', '.join(o.limit.removed)}")
    return result


def _cost_of(result, U, costs) -> float:
    """The cost of ``result.u`` among the solutions (its row), else the lowest."""
    u = np.asarray(result.u, dtype=float)
    for row, c in zip(np.asarray(U), np.asarray(costs)):
        if row.shape == u.shape and np.array_equal(row, u):
            return float(c)
    return float(np.nanmin(np.where(np.isfinite(costs), costs, np.inf)))
