"""The rival's best fit to the other form's noise-free readings: a separation's *value*.

Two forms ``A`` and ``B`` (two fits of one log), a design ``D``. With ``A`` true, a log of
``D`` is ``A``'s trajectory ``μ`` plus the encoder's rounding ``ε`` (variance
``σ² = step²/12``; a random sub-count phase per test). Fitting both forms to it, to first
order in the fits' linearisations (projections ``P_A``, ``P_B`` onto each form's Jacobian,
the runs' nuisances included),

    2 ln LR = χ²_B − χ²_A = λ + 2 μ_⊥ᵀ ε/σ + εᵀ (P_A − P_B) ε/σ²,
    λ = min over B's parameters of χ²(B | μ)            (noise-free, units of σ²),

so, for nested and non-nested pairs alike,

    E[2 ln LR]   ≈ λ + (k_A − k_B),
    sd[2 ln LR]  ≈ √(4 λ + 2 tr((P_A − P_B)²)),   |k_A − k_B| ≤ tr(…) ≤ k_A + k_B,

``k`` the number of physical parameters each form fits (the nuisances are the same runs'
in both and cancel). The noise-free ``λ`` is the separation; the ``k`` term and the spread
are :func:`expected`'s.

``λ`` needs ``B``'s *best* fit to ``μ``, which on a design far from the log's lies far from
``B``'s fit to the log (behind changes of the stick–slip sequence a local refit cannot
cross: local refits overstated the realised 2·ln LR 3–25×). :func:`rival_chi2` therefore
fits ``μ``'s readings (unrounded, the design's encoder step given, so χ² is in units of
its quantization variance) with :func:`hdid.fit` — the fit's own driver: its data-driven
grid of starts (``B``'s own start rules), the multi-start one-lane Levenberg–Marquardt
(:func:`hdid._fitting._one_lane._local_fits`), its limit checks above the floor — with
``B``'s fit to the log as one more start (``start_from_model``), the same model structure,
fixed values and inertia handling as :func:`hdid._design._check.run` fits a simulated log.
A position-periodic rival (ripple, kinematic error) is fitted at its best order near its
fitted one (:func:`best_rival_fit`), as diagnose scans the order of each candidate.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ._candidates import Experiment
from ._fisher import as_log, readings


def fit_options(fit, e: Experiment) -> dict:
    """:func:`hdid.fit`'s options for a log of ``e`` fitted as ``fit`` was: the same model
    (its values the start), fixed values, and the inertia fixed or freed as the fit's
    default does for the design's added inertias."""
    fixed = {k: p.value for k, p in fit.parameters.items() if p.fixed and k != "inertia"}
    opts = dict(model=fit.model, fix=fixed or None)
    inertia = fit.model.float_values().get("inertia")
    if e.free_inertia:
        opts["free_inertia"] = True
    elif inertia is not None:
        opts["inertia"] = inertia
    return opts


def noise_free_log(e: Experiment, theta: np.ndarray, source: str):
    """A log of ``e``'s runs with trajectories ``theta`` ``(R, n)`` (spring frame), not
    rounded, the design's encoder step given (the fit's weights are ``√12/step``)."""
    log = as_log(e, readings(e, theta, quantized=False), source, quantized=False)
    return dataclasses.replace(log, resolution=float(e.resolution), resolution_source="given")


def chi2(result, step: float) -> float:
    """A fit's χ² in units of the quantization variance ``step²/12``."""
    return float(result.n_effective * (result.rms_residual_rad / (step / math.sqrt(12.0))) ** 2)


def rival_chi2(rival, e: Experiment, theta: np.ndarray, *, nested="auto") -> float:
    """``min χ²(rival | theta's noise-free readings of e)`` by :func:`hdid.fit`
    (module docstring), a position-periodic rival at its best order
    (:func:`best_rival_fit`); NaN where the fit fails (a design with no usable log)."""
    return rival_fit(rival, e, theta, nested=nested)[0]


def rival_fit(rival, e: Experiment, theta: np.ndarray, *, nested="auto", near=None,
              truth=None):
    """``(χ², fit)`` of :func:`rival_chi2` (``(NaN, None)`` where it fails). ``near``: the
    rival's fit to a neighbouring problem (the same design, other release instants), its
    optimum the start beside the fit's own grid, at its order, without the limit checks
    (which as restarts find the basin that start already holds: a fifth of the cost).
    ``truth``: the form whose readings ``theta`` are (:func:`best_rival_fit`'s corner start)."""
    if not np.all(np.isfinite(theta)):
        return math.nan, None
    log = noise_free_log(e, theta, f"{e.name} (noise-free)")
    if near is None:
        r = best_rival_fit(log, rival, e, nested=nested, truth=truth)
    else:
        from .._errors import HdidError
        from .._fitting._fit import fit as fit_log

        try:
            r = fit_log(log, start_from_model=True, nested=False, **{**fit_options(rival, e), "model": near.model})
        except (HdidError, ValueError, FloatingPointError):
            r = None
    return (math.nan, None) if r is None else (chi2(r, e.resolution), r)


#: A position-periodic rival (an effect with an ``order``: ripple, kinematic error) is
#: fitted at every order within this many of its fitted one, and further out while the
#: best is at the window's edge (a discrete descent in the order, up to ``MAX_ORDER``).
#: The order is no parameter of the fit, so a design that moves the angle further than
#: the log did may favour another order: on the rich 2 kHz log 8805, amplitude x2, a
#: ripple of order 10 is fitted by a kinematic error of order 8 to χ² 12.1 against 346.6
#: at order 10 (orders 6-14: 103, 91, 12.1, 60, 347, 993, 1892, 2668, 3068), and diagnose
#: named that kinematic error on 2 of 10 such ripple logs.
ORDER_WINDOW = 3
#: At the best order the fit is repeated from its amplitude pair (``x_a sin nθ + x_b cos nθ``)
#: turned by each quarter of a period: the amplitude a fit at another order starts from is the
#: own order's, which says nothing of the phase there. Rich log 8805, four amplitudes at
#: 8 kHz: a kinematic error of order 8 fitted to a ripple's noise-free readings ended at χ²
#: 213 from it and at 43.0 from each quarter turn; 5 simulated logs realised a median 2·ln LR 35.
PHASE_TURNS = 4


def _order_effect(model):
    """``model``'s effect with a scanned ``order`` (its index), or ``None``."""
    for i, eff in enumerate(model.effects):
        o = getattr(eff, "order", None)
        if o is not None and math.isfinite(float(o)) and float(o) > 0:
            return i
    return None


def _with_order(model, i: int, order: float):
    import equinox as eqx

    return eqx.tree_at(lambda m: m.effects[i].order, model, float(order))


def _turned(model, i: int, quarter: int):
    """``model`` with effect ``i``'s amplitude pair (fields ``*_a``, ``*_b``) turned by
    ``quarter`` quarters of a period (``model`` itself where it has no such pair)."""
    import equinox as eqx

    eff = model.effects[i]
    fields = [f.name for f in dataclasses.fields(eff)]
    names = [f for f in fields if f.endswith("_a") and f[:-2] + "_b" in fields]
    if not names:
        return model
    fa, fb = names[0], names[0][:-2] + "_b"
    a, b = float(getattr(eff, fa)), float(getattr(eff, fb))
    c, s = round(math.cos(quarter * math.pi / 2)), round(math.sin(quarter * math.pi / 2))
    return eqx.tree_at(lambda m: (getattr(m.effects[i], fa), getattr(m.effects[i], fb)), model,
                       (a * c - b * s, a * s + b * c))


def corner_model(truth_model, rival_model, twist: float):
    """The rival's start at the corner of its parameters that *is* the true form, or
    ``None`` where it contains no such corner. The soft wind-up with its centre segment
    gone is a free play then a stiffening spring (``K1 → 0``, ``T1/K1 = b/2N``, ``K2 = K3 =
    k1``: :meth:`~hdid.effects.ThreeSegmentStiffness.free_play_corner`): fitted to a
    backlash's readings from its own fit to the log (a soft centre) and from its grid
    it stayed in the soft-centre basin (rate ×4 + encoder ×16 on log 9902: λ 84 predicted,
    −1.7 ± 2.9 realised on 5 logs), so it also starts from the backlash fit's play, the
    shared parameters (friction, inertia) at the true form's values. ``twist``: the output
    twist the design swings to [rad] (where the start puts the stiffening bend)."""
    from ..effects import FreePlayStiffness, ThreeSegmentStiffness

    spring = next((x for x in truth_model.effects if isinstance(x, FreePlayStiffness)), None)
    rich = next((x for x in rival_model.effects if isinstance(x, ThreeSegmentStiffness)), None)
    if spring is None or rich is None or not (math.isfinite(twist) and twist > 0):
        return None
    values = ThreeSegmentStiffness.free_play_corner(
        float(spring.k1), float(spring.backlash), float(truth_model.ratio), twist)
    return truth_model.with_effect(ThreeSegmentStiffness(**values))


def best_rival_fit(log, rival, e: Experiment, *, nested="auto", window: int = ORDER_WINDOW,
                   truth=None):
    """:func:`hdid.fit` of ``rival``'s model to ``log`` (a log of ``e``) with
    :func:`fit_options`; a rival with a position-periodic effect at its best order
    (``window`` orders either side of its own, ``ORDER_WINDOW``; 0: its own order only);
    with ``truth`` (the true form's fit) also from the rival's corner that is the true
    form (:func:`corner_model`), where it has one: the fit of the smallest χ². ``None``
    where every fit fails."""
    from .._errors import HdidError
    from .._fitting._fit import fit as fit_log
    from ..effects._candidate import MAX_ORDER

    opts = fit_options(rival, e)

    def at(model):
        try:
            return fit_log(log, start_from_model=True, nested=nested, **{**opts, "model": model})
        except (HdidError, ValueError, FloatingPointError):
            return None

    i = _order_effect(rival.model)
    if i is None or window <= 0:
        out = at(rival.model)
        twist = max((abs(a) for a in e.amplitudes), default=math.nan) / float(rival.model.ratio)
        corner = None if truth is None else corner_model(truth.model, rival.model, twist)
        if corner is not None:
            r = at(corner)
            if r is not None and (out is None or chi2(r, e.resolution) < chi2(out, e.resolution)):
                out = r
        return out
    fitted = float(rival.model.effects[i].order)
    n0 = max(1, int(round(fitted)))
    top = max(MAX_ORDER, n0 + window)
    tried: dict[float, object] = {fitted: at(rival.model)}

    def cost(n):
        if n not in tried:
            tried[n] = at(_with_order(rival.model, i, n))
        r = tried[n]
        return math.inf if r is None else chi2(r, e.resolution)

    for n in range(max(1, n0 - window), n0 + window + 1):
        cost(float(n))
    while True:  # the best at the window's edge: go on in that direction
        best = min(tried, key=cost)
        if best == min(tried) and best > 1:
            cost(best - 1.0)
        elif best == max(tried) and best < top:
            cost(best + 1.0)
        else:
            break
        if min(tried, key=cost) == best:
            break
    best = min(tried, key=cost)
    if not math.isfinite(cost(best)):
        return None
    out = tried[best]
    for q in range(1, PHASE_TURNS):  # the amplitude's phase at that order (PHASE_TURNS)
        r = at(_turned(tried[best].model, i, q))
        if r is not None and chi2(r, e.resolution) < chi2(out, e.resolution):
            out = r
    return out


def n_physical(fit) -> int:
    """The number of physical parameters ``fit`` adjusts (its free ones)."""
    return sum(1 for p in fit.parameters.values() if not p.fixed)


def expected(lam: float, k_true: int, k_rival: int, tr: float | None = None
             ) -> tuple[float, float]:
    """``(mean, sd)`` of ``2·ln LR`` on noisy logs from the noise-free separation ``lam``
    (module docstring); ``tr`` ``tr((P_A − P_B)²)``, default its lower bound ``|k_A − k_B|``."""
    if not math.isfinite(lam):
        return math.nan, math.nan
    t = abs(k_true - k_rival) if tr is None else tr
    return lam + (k_true - k_rival), math.sqrt(max(4.0 * lam + 2.0 * t, 0.0))


def projection_trace(Ua: np.ndarray, Ub: np.ndarray) -> float:
    """``tr((P_A − P_B)²) = r_A + r_B − 2‖U_Aᵀ U_B‖²`` for projections ``P = U Uᵀ`` onto
    orthonormal columns ``U`` (the two forms' weighted Jacobians at a design)."""
    return float(Ua.shape[1] + Ub.shape[1] - 2.0 * np.sum((Ua.T @ Ub) ** 2))
