"""The verdict rules of :func:`hdid.diagnose` (their list and statistical footing: the
module docstring of :mod:`hdid._diagnosis._diagnose`), its warnings, and the plain-language reasons.
Pure functions of the candidate table: no fit, no program."""

from __future__ import annotations

import math

import numpy as np

from ._candidates import Candidate
from ._nesting import text as _nesting_text
from ._result import CandidateResult

#: ΔBIC below this is "very strong" evidence (Kass & Raftery 1995: |ΔBIC| > 10).
STRONG_DBIC = -10.0
#: Two candidates whose BIC differ by less than this explain the data about equally well:
#: the evidence between them is not "very strong" on the Kass–Raftery scale (> 10).
AMBIGUOUS_DBIC = 10.0


def _features_text(feat: dict[str, float]) -> str:
    parts = []
    c = feat.get("corr_sign_omega")
    if c is not None and np.isfinite(c) and abs(c) > 0.2:
        parts.append(f"flips with the velocity (corr with sign ω {c:+.2f})")
    e = feat.get("near_rest_energy_share")
    if e is not None and np.isfinite(e) and e > 0.35:
        parts.append(f"{100 * e:.0f} % of its energy in the last fifth before rest")
    r = feat.get("stuck_signed_counts")
    if r is not None and np.isfinite(r) and abs(r) > 0.5:
        side = "beyond" if r > 0 else "short of"
        parts.append(f"logged rest points lie {abs(r):.1f} counts {side} the model's (towards the release side)")
    o = feat.get("theta_peak_order")
    s = feat.get("theta_peak_share")
    if o is not None and s is not None and np.isfinite(s) and s > 0.3:
        parts.append(f"periodic in the WG angle (order ≈ {o:.0f} per rev, {100 * s:.0f} % of power)")
    ce = feat.get("corr_abs_theta")
    if ce is not None and np.isfinite(ce) and abs(ce) > 0.3:
        parts.append(f"grows with the twist (corr with |θ| {ce:+.2f})")
    return "; ".join(parts) if parts else "no single dominant pattern"



def _reason(c: CandidateResult, cand: Candidate, feat: dict[str, float], floor: float) -> str:
    if c.error:
        return f"fit failed: {c.error}"
    head = (
        f"{c.label}: RMS {c.rms_before_rad / floor:.2f} → {c.rms_after_rad / floor:.2f}× the "
        f"quantization floor, ΔBIC {c.delta_bic:.1f} for {c.n_added} more parameter(s)."
    )
    return f"{head} The residual before: {_features_text(feat)}. A missing {c.key} leaves this " \
           f"mark: {cand.mark}."



def _rivals(best: CandidateResult, ranked: list[CandidateResult], all_cands,
            floor: float | None = None) -> list:
    """Candidates of another family within ``AMBIGUOUS_DBIC`` of the (strong) best: the
    evidence for the best *over them* is not very strong (Kass–Raftery), whether or not
    theirs against the current model is (a best at −14 and a rival at −6 are 8 apart: no
    ground to name the first). Where both fit below the floor, the BIC sees neither χ²
    and the gap is the penalties': the evidence is then ``floor_gap`` (the BIC gap plus
    the rounding's ``2·ln LR``, :mod:`hdid._diagnosis._rival`). And (with ``floor``) a
    strong candidate of another family that, like the best, brings the residual to the
    floor is a rival unless the *likelihood* favours the best by ``AMBIGUOUS_DBIC``
    (:func:`_likelihood_gap`: the penalties — parameters, scan costs — never decide
    between two forms that both reach the floor)."""
    fam = all_cands[best.key].family or best.key
    # the best reaches the floor as missing_effect asks it to (its moving residual, where
    # analysed), a rival by its RMS (its moving residual is not analysed)
    at_floor = best.adequate_after is not False and _reaches_floor(best, floor)
    return [c for c in ranked if c is not best and c.error is None
            and (c.delta_bic - best.delta_bic < AMBIGUOUS_DBIC
                 or c.floor_gap < AMBIGUOUS_DBIC  # below the floor: _rival's evidence
                 or (at_floor and c.delta_bic < STRONG_DBIC and _reaches_floor(c, floor)
                     and _likelihood_gap(best, c) < AMBIGUOUS_DBIC))
            and (all_cands[c.key].family or c.key) != fam]


def _reaches_floor(c: CandidateResult, floor: float | None) -> bool:
    """The candidate's refit leaves an RMS residual at the floor (≤ ``AT_FLOOR_RATIO``
    quantization floors, the whiteness test's rule)."""
    from .._results._whiteness import AT_FLOOR_RATIO

    return (floor is not None and c.error is None and math.isfinite(c.rms_after_rad)
            and c.rms_after_rad <= AT_FLOOR_RATIO * floor)


def _likelihood_gap(best: CandidateResult, c: CandidateResult) -> float:
    """The evidence for ``best`` over ``c`` without the penalties: the likelihood part of
    their BIC difference, ``n·ln(max(χ², n − k)/n)`` (:func:`hdid._diagnosis._ladder.bic_value`);
    where both fits are below the white floor ``n − k`` (the BIC holds both at it), the
    χ² difference judged under the rounding instead (``2·ln LR`` for the best,
    :mod:`hdid._diagnosis._rival`; 0 where not computed). ``inf`` without the refits (a
    loaded diagnosis): the rule is then not applied."""
    a, b = best.fit, c.fit
    if a is None or b is None or not (a.finite and b.finite):
        return math.inf
    fa, fb = a.n_effective - a.n_unknowns, b.n_effective - b.n_unknowns
    if a.cost <= max(fa, 1.0) and b.cost <= max(fb, 1.0):
        ev = c.floor_evidence or {}
        lr = ev.get("two_ln_lr_for_against") if ev.get("against") == best.key else None
        return float(lr) if lr is not None and math.isfinite(lr) else 0.0
    n = a.n_effective

    def lik(sf):
        return n * math.log(max(sf.cost, sf.n_effective - sf.n_unknowns, 1e-300) / n)

    return lik(b) - lik(a)


def _contenders(first, all_cands, with_nested: bool = False):
    """``(best, rivals, same)`` of a round: the strong best, the candidates of other
    families it cannot be told from (:func:`_rivals`), and the strong ones of its own
    family within ``AMBIGUOUS_DBIC`` (the same mark); ``(None, [], [])`` without a strong
    candidate. A richer form at its corner that is a simpler contender is dropped (the
    nesting rule, :func:`hdid._diagnosis._nesting.resolve`; the round's ``nested``
    records), the simpler one the best in its place; ``with_nested``: the records applied
    are returned fourth."""
    from ._nesting import resolve

    ok = [c for c in first["results"] if c.error is None]
    strong = [c for c in ok if c.delta_bic < STRONG_DBIC]
    if not strong:
        return (None, [], [], []) if with_nested else (None, [], [])
    best = strong[0]
    rivals = _rivals(best, ok, all_cands, first.get("floor"))
    best, rivals, applied = resolve(best, rivals, first.get("nested") or [])
    same = [c for c in strong if c is not best and c.delta_bic - best.delta_bic < AMBIGUOUS_DBIC
            and c not in rivals and c.key not in {r["richer"] for r in applied}
            and (all_cands[c.key].family or c.key) == (all_cands[best.key].family or best.key)]
    return (best, rivals, same, applied) if with_nested else (best, rivals, same)


def nested_named(rounds, all_cands) -> list[dict]:
    """The nesting records the verdict of the first round applied (``Diagnosis.nested``)."""
    return _contenders(rounds[0], all_cands, with_nested=True)[3]


def pairs_to_separate(verdict: str, rounds, all_cands) -> list[tuple]:
    """The candidate pairs a separating experiment is computed for: an ``ambiguous``
    verdict's best against each rival; otherwise the strong best against each same-mark
    one (a named effect's look-alike, and an ``unexplained`` verdict's too: its note names
    the pair)."""
    best, rivals, same = _contenders(rounds[0], all_cands)
    if best is None:
        return []
    return [(best, c) for c in (rivals if verdict == "ambiguous" else same)]


def _verdict(rounds, all_cands) -> tuple[str, str, list[str]]:
    """The verdict of the first round (and the ladder's), by the rules of the module
    docstring. Returns ``(verdict, summary, notes)``."""
    first = rounds[0]
    results, white, floor = first["results"], first["white"], first["floor"]
    notes: list[str] = []
    ok = [c for c in results if c.error is None]
    strong = [c for c in ok if c.delta_bic < STRONG_DBIC]
    if not strong:
        if white.at_floor:
            if not white.white:
                notes.append(
                    f"the residual is at the floor but not white (Ljung–Box p = {white.p_value:.2g} "
                    f"over {white.max_lag} lag(s)): slow rounding near the reversals correlates "
                    "it, or a small effect remains below what this log can resolve"
                )
            return "adequate", (
                f"no candidate improves the fit strongly (ΔBIC < {STRONG_DBIC:g}) and the "
                f"moving residual is at the quantization floor ({white.rms_ratio:.2f}×)"
            ), notes
        return "unexplained", (
            f"the residual is above the floor (moving RMS {white.rms_ratio:.2f}× floor, "
            f"Ljung–Box p = {white.p_value:.2g}) but no library effect improves it strongly"
        ), notes
    best, rivals, same, applied = _contenders(first, all_cands, with_nested=True)
    nested = "".join(f"; {_nesting_text(r)}" for r in applied)
    if same:
        notes.append(
            f"{best.key} and {', '.join(c.key for c in same)} leave the same mark "
            f"({all_cands[best.key].family}) and fit about equally well (the experiment "
            "that separates them: separating_experiments)"
        )
    if rivals:
        names = [best.key] + [c.key for c in rivals]
        return "ambiguous", (
            f"ambiguous between {', '.join(names)} (ΔBIC "
            f"{', '.join(f'{c.delta_bic:.1f}' for c in [best] + rivals)}; RMS "
            f"{', '.join(f'{c.rms_after_rad / floor:.2f}' for c in [best] + rivals)}× the "
            f"floor): the log cannot tell them apart{nested}"
        ), notes
    if best.adequate_after:
        if best.white_after is False:
            notes.append(
                f"after adding {best.label} the residual is at the floor but not white: a "
                "second, smaller effect may remain"
            )
        alt = (f" — or {', '.join(c.label for c in same)}: the same mark "
               f"({all_cands[best.key].family}), its form not told apart by this log"
               if same else "")
        return "missing_effect", (
            f"add {best.label}: RMS {best.rms_before_rad / floor:.2f} → "
            f"{best.rms_after_rad / floor:.2f}× floor, ΔBIC {best.delta_bic:.1f}{alt}{nested}"
        ), notes
    # several effects missing at once: the ladder may reach the floor in more steps
    if len(rounds) > 1:
        every = [c for c in rounds[-1]["results"] if c.error is None]
        last = [c for c in every if c.delta_bic < STRONG_DBIC]
        if last and last[0].adequate_after and not _rivals(last[0], every, all_cands,
                                                            rounds[-1].get("floor")):
            names = [r["results"][0].label for r in rounds]
            return "missing_effect", (
                "add " + " and ".join(names) + f": RMS → {last[0].rms_after_rad / floor:.2f}× floor"
            ), notes
    return "unexplained", (
        f"{best.label} improves the fit (ΔBIC {best.delta_bic:.1f}) but leaves the moving "
        f"residual at {best.moving_ratio_after:.2f}× the floor: the missing physics is "
        "probably not in the library (or several effects are missing: try --steps 2)"
    ), notes


#: Fewer lags than this in the whiteness test (``max_lag``: a quarter of the shortest
#: run's moving samples, at most 10) leave it little power against a correlated residual
#: (a Ljung–Box test over 2–4 lags sees only a lag-1 correlation of ≳ 0.3 at ~40 samples).
LOW_POWER_LAGS = 5


def _warnings(verdict, rounds, all_cands, local_base, fa) -> list[str]:
    """What is known against trusting the verdict (the module docstring's list)."""
    from ._rates import TARGET

    first = rounds[0]
    white, floor = first["white"], first["floor"]
    ok = [c for c in first["results"] if c.error is None]
    strong = [c for c in ok if c.delta_bic < STRONG_DBIC]
    out: list[str] = []
    if fa is None:
        out.append("the false-alarm rate of these rules was not measured for a design near "
                   "this log's (sample rate, number of runs): a claimed effect has no "
                   "calibrated error rate here")
    elif fa.upper > TARGET and verdict != "adequate":
        out.append(f"{fa.text()}: the one-sided upper bound is above the "
                   f"{100 * TARGET:.0f} % target (not yet shown to meet it)")
    if local_base:
        a, b, who = local_base[0]
        out.append(f"the base model's first optimum was a local one (χ² {a:.1f} → {b:.1f} from "
                   f"{who}'s optimum with the effect removed): this log's fits have several "
                   "basins, and a candidate's gain may still hide a base basin no start found")
    if verdict != "adequate" and white.max_lag < LOW_POWER_LAGS:
        out.append(f"the whiteness test has little power here ({white.max_lag} lag(s)): "
                   "'at the floor' rests on the residual's RMS alone")
    if verdict in ("missing_effect", "ambiguous") and strong:
        best = _contenders(first, all_cands)[0]  # the nesting rule's where it applied
        if best.white_after is False:
            out.append(f"after adding {best.label} the residual is not white: a second, "
                       "smaller effect may remain")
        if best.adequate_after is False:
            out.append(f"the best candidate ({best.label}) leaves the moving residual at "
                       f"{best.moving_ratio_after:.2f}× the floor: it does not explain the "
                       "misfit alone")
    if any(c.error for c in first["results"]):
        out.append("some candidate refits failed (" + ", ".join(
            c.key for c in first["results"] if c.error) + "): they were not compared")
    return out

