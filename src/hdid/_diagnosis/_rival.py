"""Which of two candidates the log favours when the BIC sees neither fit (both below its
floor): the χ² difference between their optima, against its distribution under the
rounding alone (``docs/decisions/rival-scale.md``).

Where both candidates' fits go below the white-noise floor ``n − k``, the BIC
(:func:`hdid._diagnosis._ladder.bic_value`) holds both at that floor: their likelihoods
are the same to it, and their ranking is the penalty alone. For the two position-periodic
candidates (``ripple``, ``kinematic_error``: two parameters each, an order scanned each)
that is ``2·ln M`` of the two scans (120 periodogram orders against 48: 1.83), a rule of
the scan's bookkeeping, not of the data: on the independent suite every hidden ripple was
ranked ``kinematic_error`` first by exactly 1.83.

Below the floor the χ² difference of two fits is still information, but not on the
white-noise scale (the rounding errors of neighbouring samples are correlated,
:mod:`hdid._diagnosis._floor`). Its scale is computed from the log in hand, as the floor
``F`` is: take one candidate's fitted trajectory ``ŷ_A`` as the truth, round it on
``PHASES`` grid phases ``c`` (``Y(c) = ŷ_A − saw(ŷ_A + c)``), refit *both* candidates
linearly at their own optima (``χ²_M(c) = min_δ ‖r_M(c) + J_M δ‖²``, ``r_M(c)`` the
candidate's residual rows for ``Y(c)``, its prior rows as fitted) and record
``D(c) = χ²_B(c) − χ²_A(c)``; the same with ``ŷ_B`` as the truth. The observed
``D = χ²_B − χ²_A`` of the two nonlinear fits is then judged under both hypotheses
(a non-nested test in the manner of Cox 1961, with the rounding's phase as the only
randomness): ``2·ln LR = 2·ln[N(D; μ_A, s_A) / N(D; μ_B, s_B)]`` (positive favours ``A``).
That is the likelihood part the floored BIC left out, so it is added to the BIC
difference: ``B`` ranks above ``A`` when ``ΔBIC_B − ΔBIC_A + 2·ln LR < 0``. When the two
trajectories are the same to the rounding (both distributions alike) ``2·ln LR ≈ 0`` and
the BIC's order stands; the report says the form is not told apart. When ``D`` is more
than ``OUTSIDE`` standard deviations from both means, neither hypothesis explains it
(the linearisation does not hold there) and it is no evidence.

Two uses (:func:`rank_within_families`): inside one family it decides who is named first
(the other named as the same mark); across families it is the evidence for the best over
another strong candidate that also fits below the floor (``floor_gap``), and a gap less
than ``AMBIGUOUS_DBIC`` makes that candidate a rival (an ``ambiguous`` verdict) even where
the penalties alone put it further behind (seed 9905: a ripple named asymmetric friction
by the penalty gap 14.6, with the χ² difference favouring the ripple, 2·ln LR −7.0).
Where the log cannot tell the two fits apart at all — the evidence it is expected to give
under either as the truth (:meth:`Evidence.power`) is under ``SEPARABLE`` — the BIC gap
between two fits it holds at the floor is the penalties' alone (parameters, scan costs),
a prior, not the data: it is dropped and ``2·ln LR`` alone is the evidence (``docs/decisions/rival-scale.md``:
logs drawn from 9905's *fitted* ripple, where ``2·ln LR`` ≈ 0, were otherwise
named ``asymmetric_friction`` with confidence on the penalties' 14.5).

Calibration (``calibration/rival_scale.py``, ``calibration/results/rival_scale.md``): on 89 logs
drawn from the fitted forms of seeds 8905 and 8805 (ripple, kinematic error), 8901
(backlash, kinematic error) and 9905 (ripple, asymmetric friction), each with a random
encoder phase and release instants, the z-score of the observed ``D`` under the true form
has mean 0.02 and sd 0.91 (3.4 % beyond ±2; per form means −0.84 to +0.37): the
phase-only scale is not over-confident, and neither an independent phase per set-up nor
random release instants beside it do better (sd 1.02, 0.99 on the first 47), so it is kept.
No candidate becomes strong or weak, and a log with no strong candidate (``adequate``)
is never touched, so the false-alarm rates (:mod:`hdid._diagnosis._rates`) are those of
the rules without it. A ``missing_effect`` can become ``ambiguous`` or name the other
member of its family first (and, were that member's moving residual above the floor,
``unexplained``: the rule only swaps two fits both below ``n − k``, so not seen).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._floor import PHASES, RCOND, saw

#: ``D`` further than this many standard deviations from both hypotheses' means is
#: explained by neither: no evidence (a linearised refit does not reach that far).
OUTSIDE = 4.0
#: Standard deviations of ``D(c)`` below this (χ² units: one quantization variance) are
#: held at it: a χ² difference below one σ_q² is no evidence on any scale.
MIN_SD = 1.0
#: The log tells two fits apart only if the evidence it is expected to give, under either
#: as the truth (:meth:`Evidence.power`: ``2·KL`` of the two distributions of ``D``), is
#: at least this: Kass & Raftery's (1995) "not worth more than a bare mention" ends at
#: ``2·ln B`` = 2. Below it, across families, the penalties alone would rank the two, and
#: they are dropped (:func:`rank_within_families`; measured by simulation,
#: ``docs/decisions/rival-scale.md``: logs drawn from 9905's fitted ripple were named ``asymmetric_friction`` on
#: the penalty gap ~14.5 alone, with ``2·ln LR`` ≈ 0).
SEPARABLE = 2.0


@dataclass(frozen=True)
class Linear:
    """A fit linearised at its optimum: all residual rows ``r``, an orthonormal basis
    ``U`` of its Jacobian's columns, the predicted readings ``yhat`` at the weighted
    samples ``rows`` with weights ``w``, the quantization ``sigma`` and the χ² ``cost``."""

    r: np.ndarray
    U: np.ndarray
    rows: np.ndarray
    w: np.ndarray
    sigma: float
    yhat: np.ndarray
    cost: float

    def chi2(self, truth: np.ndarray, phases: int = PHASES) -> np.ndarray:
        """``χ²(c)`` of the linearised refit when the log is ``truth`` rounded at each of
        ``phases`` grid phases."""
        step = self.sigma * math.sqrt(12.0)
        c = (np.arange(phases) + 0.5) / phases * step
        R = np.repeat(self.r[None, :], phases, axis=0)
        R[:, self.rows] = self.w[None, :] * (
            self.yhat[None, :] - truth[None, :] + saw(truth[None, :] + c[:, None], step)
        ) / self.sigma
        left = R - (R @ self.U) @ self.U.T
        return np.sum(left**2, axis=1)


def linear(r, J, weight, theta, sigma: float, cost: float) -> Linear:
    """:class:`Linear` from residuals ``r`` and Jacobian ``J`` (all rows; the first
    ``weight.size`` are the data's), the problem's weights and logged angles."""
    J = np.asarray(J, dtype=float)
    w = np.asarray(weight, dtype=float).ravel()
    rows = np.flatnonzero(w > 0)
    r = np.asarray(r, dtype=float)
    yhat = np.asarray(theta, dtype=float).ravel()[rows] + r[: w.size][rows] * sigma / w[rows]
    U, S, _ = np.linalg.svd(J, full_matrices=False)
    U = U[:, S > RCOND * (S[0] if S.size else 0.0)]
    return Linear(r, U, rows, w[rows], float(sigma), yhat, float(cost))


def linear_of(sf) -> Linear | None:
    """:class:`Linear` of a refit (:class:`~hdid._fitting._refit.StructureFit`), from its
    structure's Levenberg–Marquardt program (no program of its own); ``None`` if not
    finite or not on a quantized log."""
    from .._fitting._refit import residuals_and_jacobian

    p = sf.setup.problem
    if not sf.finite or not sf.setup.prep.quantized:
        return None
    r, J = residuals_and_jacobian(p, sf.u)
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        return None
    return linear(r, J, p.weight, p.theta, float(p.sigma), sf.cost)


@dataclass(frozen=True)
class Evidence:
    """``D = χ²_B − χ²_A`` observed, its mean and sd under ``A`` and under ``B`` as the
    truth, and ``two_ln_lr`` (positive favours ``A``; 0 when neither explains ``D``)."""

    d: float
    mean_a: float
    sd_a: float
    mean_b: float
    sd_b: float
    two_ln_lr: float

    def power(self) -> float:
        """The evidence the log is expected to give for the truth, under the worse of the
        two: ``min(2·KL(N_A‖N_B), 2·KL(N_B‖N_A))`` of the two normal distributions of
        ``D`` (the mean of ``2·ln LR`` under each as the truth)."""

        def kl2(m1, s1, m2, s2):
            return (m1 - m2) ** 2 / s2**2 + s1**2 / s2**2 - 1.0 - math.log(s1**2 / s2**2)

        return min(kl2(self.mean_a, self.sd_a, self.mean_b, self.sd_b),
                   kl2(self.mean_b, self.sd_b, self.mean_a, self.sd_a))

    def to_dict(self, a: str) -> dict:
        """The JSON entry of ``b`` (the candidate holding it) against ``a``."""
        return {"against": a, "chi2_difference": self.d,
                "mean_if_against_true": self.mean_a, "sd_if_against_true": self.sd_a,
                "mean_if_this_true": self.mean_b, "sd_if_this_true": self.sd_b,
                "two_ln_lr_for_against": self.two_ln_lr,
                "expected_two_ln_lr": self.power()}

    def text(self, a: str, b: str) -> str:
        return (f"χ²({b}) − χ²({a}) = {self.d:.1f}; under the rounding alone it is "
                f"{self.mean_a:.1f} ± {self.sd_a:.1f} if {a} is the truth, "
                f"{self.mean_b:.1f} ± {self.sd_b:.1f} if {b} is: 2·ln LR = "
                f"{self.two_ln_lr:+.1f} for {a}")


def cross_evidence(a: Linear, b: Linear, phases: int = PHASES) -> Evidence | None:
    """The observed χ² difference of two fits of one log judged under each as the truth
    (module docstring). ``None`` when the two are not fits of the same samples."""
    if (a.rows.shape != b.rows.shape or not np.array_equal(a.rows, b.rows)
            or not np.allclose(a.w, b.w) or not math.isclose(a.sigma, b.sigma, rel_tol=1e-9)):
        return None
    d_obs = b.cost - a.cost
    stats = []
    for truth in (a.yhat, b.yhat):
        D = b.chi2(truth, phases) - a.chi2(truth, phases)
        stats.append((float(np.mean(D)), max(float(np.std(D)), MIN_SD)))
    (ma, sa), (mb, sb) = stats
    za, zb = (d_obs - ma) / sa, (d_obs - mb) / sb
    if min(abs(za), abs(zb)) > OUTSIDE:
        lr = 0.0
    else:
        lr = (-za**2 - 2 * math.log(sa)) - (-zb**2 - 2 * math.log(sb))
    return Evidence(d_obs, ma, sa, mb, sb, float(lr))


def _floored(c) -> bool:
    """The BIC holds this candidate's fit at the white floor (``χ² ≤ n − k``)."""
    sf = c.fit
    return sf is not None and sf.finite and sf.cost <= max(sf.n_effective - sf.n_unknowns, 1.0)


def _evidence_of(evidence):
    """``evidence(a, b)`` as given, or :func:`cross_evidence` of the two candidates'
    linearised fits (each linearised once)."""
    if evidence is not None:
        return evidence
    cache = {}

    def lin(c):
        if id(c) not in cache:
            cache[id(c)] = linear_of(c.fit)
        return cache[id(c)]

    def default(a, b):
        la, lb = lin(a), lin(b)
        return None if la is None or lb is None else cross_evidence(la, lb)

    return default


def rank_within_families(results, all_cands, strong_dbic: float, tie_dbic: float,
                         evidence=None) -> list[str]:
    """Below the floor, the χ² difference judged under the rounding (module docstring):

    1. among the strong best's family within ``tie_dbic`` of it, with both fits held at
       the floor by the BIC, the candidate the log favours (the BIC difference plus
       ``2·ln LR`` for the BIC's best) is put first;
    2. every strong candidate of another family whose fit the BIC holds at the floor as
       it does the best's gets ``floor_gap``: its BIC gap to the best plus ``2·ln LR``
       for the best — the evidence for the best over it, which the verdict's rival rule
       reads beside the BIC gap (:func:`hdid._diagnosis._verdict._rivals`).

    Reorders ``results`` (sorted by ΔBIC) in place; returns the notes. ``evidence(a,
    b)``: :class:`Evidence` of ``b`` against ``a`` (default: :func:`cross_evidence` of
    their linearised fits)."""
    ok = [c for c in results if c.error is None]
    if not ok or ok[0].delta_bic >= strong_dbic or not _floored(ok[0]):
        return []
    evidence = _evidence_of(evidence)
    best = ok[0]
    fam = all_cands[best.key].family
    tied = [c for c in ok[1:] if fam and all_cands[c.key].family == fam
            and c.key != best.key and c.delta_bic < strong_dbic
            and c.delta_bic - best.delta_bic < tie_dbic and _floored(c)]
    notes, winner, score = [], best, 0.0
    for c in tied:
        ev = evidence(best, c)
        if ev is None:
            continue
        # c against the BIC's best: its BIC difference plus the evidence for the best
        # (2·ln LR of the best over c; the same scale, −2·ln of a likelihood ratio)
        s = (c.delta_bic - best.delta_bic) + ev.two_ln_lr
        c.floor_evidence = ev.to_dict(best.key)
        verdict = "ranked first" if s < score else "not ranked first"
        notes.append(
            f"{best.key} and {c.key} both fit below the white floor n − k, where the BIC "
            f"holds both at it (ΔBIC {best.delta_bic:.1f} and {c.delta_bic:.1f}: the "
            f"penalties alone); {ev.text(best.label, c.label)}. BIC gap plus it: "
            f"{s:+.1f} → {c.label} {verdict}"
            + ("" if abs(ev.two_ln_lr) >= 2.0 else
               " (|2·ln LR| < 2: the log does not tell the two forms apart)"))
        if s < score:
            winner, score = c, s
    if winner is not best:
        results.remove(winner)
        results.insert(results.index(best), winner)
        best = winner
    fam = all_cands[best.key].family or best.key
    for c in ok:
        if (c is best or (all_cands[c.key].family or c.key) == fam
                or c.delta_bic >= strong_dbic or not _floored(c)
                or c.delta_bic - best.delta_bic < tie_dbic):
            continue  # (within tie_dbic it is a rival by the BIC already)
        ev = evidence(best, c)
        if ev is None:
            continue
        # where the log cannot tell the two fits apart (expected 2·ln LR < SEPARABLE
        # under either), the BIC gap is the penalties' alone: dropped, the χ² evidence left
        blind = ev.power() < SEPARABLE
        c.floor_gap = (0.0 if blind else c.delta_bic - best.delta_bic) + ev.two_ln_lr
        c.floor_evidence = {**ev.to_dict(best.key), "floor_gap": c.floor_gap}
        rival = c.floor_gap < tie_dbic
        notes.append(
            f"{best.key} and {c.key} both fit below the white floor n − k (ΔBIC "
            f"{best.delta_bic:.1f} and {c.delta_bic:.1f}); {ev.text(best.label, c.label)}. "
            + (f"The log cannot tell the two apart (the evidence expected under either as "
               f"the truth, {ev.power():.1f}, is under {SEPARABLE:g}): the penalties' gap "
               f"dropped, the evidence for {best.key} over it is this alone"
               if blind else f"The evidence for {best.key} over it, BIC gap plus this")
            + f": {c.floor_gap:.1f}" + (f", less than {tie_dbic:g}: a rival" if rival else ""))
    return notes


__all__ = ("Evidence", "Linear", "cross_evidence", "linear", "linear_of",
           "rank_within_families")
