"""The decision rules of :func:`hdid.diagnose` (module docstring of ``hdid._diagnosis._diagnose``),
checked on constructed candidate tables: no fit, so they run in milliseconds.

Statistical footing used below: χ² is in units of the quantization variance
``σ_q² = step²/12``, so a correct model leaves ``E χ² = n − k`` on a log with ``n``
effective observations and ``k`` fitted unknowns.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from hdid._diagnosis import _diagnose as D

from synthetic import ROOT


def _cand(key, dbic, *, at_floor=True, white=True, rms=1.0):
    return D.CandidateResult(
        key, key, 1.5, rms, dbic, 2, at_floor, "", {}, None, None,
        white_after=white, moving_ratio_after=rms,
    )


def _round(results, *, at_floor=False, white=False):
    w = SimpleNamespace(at_floor=at_floor, white=white, rms_ratio=1.0 if at_floor else 2.0,
                        p_value=0.5 if white else 1e-6, max_lag=1)
    return [{"results": results, "white": w, "floor": 1.0}]


CANDS = {c.key: c for c in D.default_candidates()}


# -- evidence below the floor ---------------------------------------------------------
def test_fitting_the_rounding_is_no_evidence():
    """The issue's paper-design false alarm: base at 0.42× the floor, a candidate with
    two more parameters at 0.32×, n ≈ 40 effective observations. With σ profiled this is
    ΔBIC = 40·ln(0.32²/0.42²) + 2·ln 40 ≈ −14 (a "strong" claim); with the variance
    held at the floor both fits sit at E χ² = n − k and ΔBIC is the parameter penalty."""
    n, k = 40.0, 14
    base = D.bic_value(0.42**2 * n, n, k)
    cand = D.bic_value(0.32**2 * n, n, k + 2)
    profiled = n * math.log(0.32**2 / 0.42**2) + 2 * math.log(n)
    assert profiled < D.STRONG_DBIC  # what the old rule claimed
    assert cand - base > 0  # no evidence at all now
    assert cand - base == pytest.approx(n * math.log((n - k - 2) / (n - k)) + 2 * math.log(n))


def test_above_the_floor_the_bic_is_the_profiled_one():
    """A real effect: base at 2× the floor (χ² = 4n), candidate at 0.9× → clipped to
    n − k. ΔBIC = n·ln((n − k − 2)/(4n)) + 2 ln n — strongly negative for n = 300."""
    n, k = 300.0, 20
    d = D.bic_value(0.81 * n, n, k + 2) - D.bic_value(4 * n, n, k)
    assert d == pytest.approx(n * math.log((n - k - 2) / (4 * n)) + 2 * math.log(n))
    assert d < -300
    # and with χ² above n − k on both sides it is exactly n·ln(χ²_c/χ²_b) + Δk·ln n
    d2 = D.bic_value(1.5 * n, n, k + 2) - D.bic_value(4 * n, n, k)
    assert d2 == pytest.approx(n * math.log(1.5 / 4) + 2 * math.log(n))


# -- verdicts ---------------------------------------------------------------------------
def test_tie_between_unrelated_candidates_is_ambiguous_with_the_pair_to_separate():
    from hdid._diagnosis._verdict import pairs_to_separate

    rounds = _round([_cand("hysteresis", -30), _cand("backlash", -25), _cand("ripple", -5)])
    verdict, summary, _ = D._verdict(rounds, CANDS)
    assert verdict == "ambiguous"
    assert "ambiguous between hysteresis, backlash" in summary
    assert "ripple" not in summary  # not strong: not named
    # the separating experiment is computed for the pair (hdid.design), never a fixed text
    assert CANDS["hysteresis"].experiment not in summary
    assert [(a.key, b.key) for a, b in pairs_to_separate(verdict, rounds, CANDS)] == [
        ("hysteresis", "backlash")]


def _fit(cost, n=200.0, k=20):
    """A refit as the rules read it: χ², effective observations, unknowns."""
    return SimpleNamespace(finite=True, cost=cost, n_effective=n, n_unknowns=k)


def test_forms_of_other_families_that_all_reach_the_floor_are_ambiguous():
    """The issue's case (a ripple in the WG angle, paper design, independent simulator):
    asymmetric_friction −84.8 (RMS 0.80× the floor), kinematic_error −72.8 (0.60×),
    ripple −71.0 (0.62×). All three below the white floor n − k: the BIC holds them at
    it and the 12–14 gap is the penalties' (one parameter against two plus an order
    scan). Penalties never choose between forms that reach the floor: ambiguous, with a
    pair to separate for each rival. (Before: missing_effect, add asymmetric_friction.)"""
    from hdid._diagnosis._verdict import pairs_to_separate

    cands = [_cand("asymmetric_friction", -84.8, rms=0.80),
             _cand("kinematic_error", -72.8, rms=0.60), _cand("ripple", -71.0, rms=0.62)]
    for c, cost in zip(cands, (0.80**2 * 200, 0.60**2 * 200, 0.62**2 * 200)):
        c.fit = _fit(cost)
    rounds = _round(cands)
    verdict, summary, _ = D._verdict(rounds, CANDS)
    assert verdict == "ambiguous", summary
    assert "ambiguous between asymmetric_friction, kinematic_error, ripple" in summary
    assert [(a.key, b.key) for a, b in pairs_to_separate(verdict, rounds, CANDS)] == [
        ("asymmetric_friction", "kinematic_error"), ("asymmetric_friction", "ripple")]


def test_a_floor_level_form_the_likelihood_clearly_favours_is_still_named():
    """The rule does not overreach: both at the floor by RMS (1.2×) but above n − k, the
    best's χ² 250 against 300 at n = 200 — the likelihood part of the BIC gap is
    200·ln(300/250) = 36 > 10: the data, not the penalties, favour the best. Likewise
    both below n − k with the rounding's 2·ln LR 14 for the best (:mod:`._rival`)."""
    best, other = _cand("hysteresis", -80, rms=1.2), _cand("backlash", -65, rms=1.2)
    best.fit, other.fit = _fit(250.0), _fit(300.0)
    verdict, _, _ = D._verdict(_round([best, other]), CANDS)
    assert verdict == "missing_effect"
    best.fit, other.fit = _fit(100.0), _fit(120.0)  # both below n − k = 180
    other.floor_evidence = {"against": "hysteresis", "two_ln_lr_for_against": 14.0}
    verdict, _, _ = D._verdict(_round([best, other]), CANDS)
    assert verdict == "missing_effect"
    other.floor_evidence = {"against": "hysteresis", "two_ln_lr_for_against": 3.0}
    verdict, _, _ = D._verdict(_round([best, other]), CANDS)
    assert verdict == "ambiguous"


def _soft_windup_fit(K1, K1_sd, play, ratio=100.0):
    """An analysed soft wind-up refit as the nesting rule reads it: ``K1`` [N m/rad] with
    its std, ``T1`` putting the zone's total play at ``play`` [rad, WG]."""
    P = SimpleNamespace
    return P(parameters={"K1": P(value=K1, std=K1_sd), "T1": P(value=K1 * play / (2 * ratio), std=math.nan)},
             model=P(ratio=ratio))


def _backlash_and_soft_windup(first, K1, K1_sd):
    """Both forms at the floor, χ² 150 and 152 at n = 200 (likelihood gap 2.7 < 10):
    ambiguous by the floor rule; ``first``: which one the BIC ranks first."""
    from hdid._diagnosis import _nesting

    bl, sw = _cand("backlash", -60.0, rms=0.9), _cand("soft_windup", -60.0, rms=0.88)
    bl.delta_bic, sw.delta_bic = (-60.0, -55.0) if first == "backlash" else (-55.0, -60.0)
    bl.fit, sw.fit = _fit(152.0), _fit(150.0)
    bl.values = {"k1": 1096.0, "k2": 4e7, "backlash": 0.0229}
    sw.result = _soft_windup_fit(K1, K1_sd, 0.0228)
    ranked = sorted([bl, sw], key=lambda c: c.delta_bic)
    rounds = _round(ranked)
    rounds[0]["nested"] = _nesting.corners(ranked, lambda c: c.result)
    return rounds


@pytest.mark.parametrize("first", ["backlash", "soft_windup"])
def test_a_richer_form_at_its_corner_that_is_the_simpler_one_names_the_simpler(first):
    """Soft wind-up with K1 → 0 (T1/K1 = b/2N, K2 = K3) is a dead zone then a stiffening
    spring: a free play. On simulated backlash logs it reached the floor at that corner
    (K1 11.7 against k1 1096) and the verdict was ``ambiguous backlash | soft_windup`` on
    10/10; no experiment separates them when backlash is true. K1 = 11.7 ± 40: zero is
    within 2 std (a two-sided 95 % interval), so the soft wind-up adds nothing the free play
    lacks and the form with fewer parameters is named, whichever the BIC put first; the
    summary and ``Diagnosis.nested`` say why. (Before: ambiguous.)"""
    from hdid._diagnosis._verdict import nested_named, pairs_to_separate

    rounds = _backlash_and_soft_windup(first, 11.7, 40.0)
    verdict, summary, _ = D._verdict(rounds, CANDS)
    assert verdict == "missing_effect", summary
    assert summary.startswith("add backlash") and "corner that is backlash" in summary
    assert "0.0228 rad at the WG against backlash's 0.0229" in summary
    rec = nested_named(rounds, CANDS)
    assert [(r["named"], r["richer"], r["parameter"]) for r in rec] == [
        ("backlash", "soft_windup", "K1")]
    assert pairs_to_separate(verdict, rounds, CANDS) == []  # no pair left to separate


def test_a_richer_form_away_from_its_corner_stays_a_rival():
    """A real soft centre (K1 270 ± 30: zero 9 std away) is not the free play: the pair
    stays ambiguous, with the experiment to separate them."""
    rounds = _backlash_and_soft_windup("backlash", 270.0, 30.0)
    assert rounds[0]["nested"] == []
    verdict, summary, _ = D._verdict(rounds, CANDS)
    assert verdict == "ambiguous" and "backlash, soft_windup" in summary


def test_clear_winner_at_the_floor_is_named():
    rounds = _round([_cand("hysteresis", -60), _cand("backlash", -25)])
    verdict, summary, _ = D._verdict(rounds, CANDS)
    assert verdict == "missing_effect" and "hysteresis" in summary


def test_tie_within_one_family_is_not_ambiguous_but_noted():
    """Ripple and kinematic error both put a torque periodic in the WG angle: a tie says
    which physics is missing, only not its form."""
    rounds = _round([_cand("ripple", -230), _cand("kinematic_error", -222)])
    verdict, summary, notes = D._verdict(rounds, CANDS)
    assert verdict == "missing_effect" and "ripple" in summary
    assert any("kinematic_error" in n for n in notes)
    # the summary itself names the look-alike: the physics is named, its form is not
    assert "or kinematic_error" in summary and "same mark" in summary


def test_floor_reached_with_a_powerless_whiteness_test_is_not_unexplained():
    rounds = _round([_cand("ripple", -40, at_floor=True, white=False, rms=0.94)])
    verdict, _, notes = D._verdict(rounds, CANDS)
    assert verdict == "missing_effect"
    assert any("not white" in n for n in notes)


def test_strong_candidate_above_the_floor_is_unexplained():
    rounds = _round([_cand("asymmetric_friction", -200, at_floor=False, rms=1.6)])
    verdict, summary, _ = D._verdict(rounds, CANDS)
    assert verdict == "unexplained" and "1.60" in summary


def test_no_strong_candidate():
    assert D._verdict(_round([_cand("ripple", -3)], at_floor=True, white=True), CANDS)[0] == "adequate"
    assert D._verdict(_round([_cand("ripple", -3)], at_floor=False), CANDS)[0] == "unexplained"


def test_an_unexplained_verdict_s_same_mark_pair_is_separated_too():
    """The note "leave the same mark … (the experiment that separates them:
    separating_experiments)" is written for every verdict with a same-mark pair; an
    ``unexplained`` one (the best strong but above the floor) gets the pair as well."""
    from hdid._diagnosis._verdict import pairs_to_separate

    rounds = _round([_cand("ripple", -230, at_floor=False, rms=1.6),
                     _cand("kinematic_error", -222, at_floor=False, rms=1.6)])
    verdict, _, notes = D._verdict(rounds, CANDS)
    assert verdict == "unexplained" and any("same mark" in n for n in notes)
    assert [(a.key, b.key) for a, b in pairs_to_separate(verdict, rounds, CANDS)] == [
        ("ripple", "kinematic_error")]


# -- experiments that would detect what an adequate verdict cannot ----------------------
def _separation(name, a_true, b_true, *, linear=None, converged=(True, True)):
    """A separation as :func:`hdid._design._separate.separations` returns it (A: the
    candidate, B: the base)."""
    exp = SimpleNamespace(name=name, describe=lambda: f"{name} (runs, rate, encoder)")
    lin = linear or (a_true, b_true)
    return SimpleNamespace(experiment=exp, linear=lin, refitted=(a_true, b_true),
                           converged=converged, value=min(a_true, b_true),
                           to_dict=lambda: {"experiment": name, "expected_2lnlr": min(a_true, b_true),
                                            "a_true": a_true, "b_true": b_true})


def test_the_detecting_experiment_is_ranked_with_the_effect_as_the_truth(monkeypatch):
    """Base and candidate are nested: with the base as the truth the candidate fits its
    readings too (2·ln LR ≈ 0 on any design), so the smaller direction — the separation of
    two rival forms — would rank nothing. The experiment named maximises the 2·ln LR with
    the effect there (``a_true``): here "rate x4" (40), not "more amplitudes" (the larger
    smaller-direction value, 0.3); one whose linearisation the refit contradicts (200 vs
    600) comes after the confirmed ones."""
    import hdid._design._separate as S
    from hdid._diagnosis import _detecting, _separating

    seps = [_separation("this log", 0.5, 0.0), _separation("more amplitudes", 12.0, 0.3),
            _separation("rate x4", 40.0, 0.0),
            _separation("encoder x8", 200.0, 0.0, linear=(600.0, 0.0))]
    monkeypatch.setattr(S, "separations", lambda fa, fb, exps: seps)
    monkeypatch.setattr(_separating, "experiments_for", lambda fa, fb: [])
    cand = SimpleNamespace(key="backlash", label="backlash", result=object(), fit=None)
    base = SimpleNamespace(model=SimpleNamespace(effect_names=("spring", "friction")))
    rec = _detecting.detecting(cand, base)
    assert rec["purpose"] == "detect" and rec["forms"] == ["backlash", _detecting.BASE]
    assert rec["experiment"] == "rate x4" and rec["expected_2lnlr"] == 40.0
    assert rec["this_log_2lnlr"] == 0.5 and rec["reaches_min_separation"]
    assert [a["experiment"] for a in rec["alternatives"]] == ["more amplitudes", "encoder x8"]
    assert "to detect backlash" in rec["text"] and "rate x4" in rec["text"]
    assert "expected 2·ln LR 40" in rec["text"]
    # the log's own design computed far beyond what the two fits to the log allow
    # ((√24 + √25)² ≈ 98, held within a factor 2): the simulation is not the fit's
    cand.fit = SimpleNamespace(cost=24.0)
    base.starts = SimpleNamespace(costs=[25.0], best=0)
    assert _detecting.log_bound(cand, base) == pytest.approx((24**0.5 + 25**0.5) ** 2)
    rec = _detecting.detecting(cand, base)
    assert rec["consistent_with_log"] and "NOT CREDIBLE" not in rec["text"]
    seps[0] = _separation("this log", 4.1e4, 0.0)
    rec = _detecting.detecting(cand, base)
    assert not rec["consistent_with_log"] and "NOT CREDIBLE" in rec["text"]
    # an effect fitted at almost no size: no default experiment reaches 10, and it says so
    seps[:] = [_separation("this log", 0.01, 0.0), _separation("rate x4", 0.4, 0.0)]
    rec = _detecting.detecting(cand, base)
    assert not rec["reaches_min_separation"] and "no default candidate reaches" in rec["text"]


def test_only_an_adequate_verdict_s_candidates_are_not_detectable_and_the_best_first(
        monkeypatch):
    from hdid._diagnosis import _detecting

    cands = [_cand(k, d) for k, d in (("ripple", -6), ("backlash", -3), ("hysteresis", 1),
                                       ("load_friction", 2))]
    for c in cands:
        c.fit = _fit(100.0)
    cands.append(D.CandidateResult("soft_windup", "soft_windup", math.nan, math.nan, math.inf,
                                   0, None, "", {}, None, "RuntimeError: no finite refit"))
    rounds = _round(cands, at_floor=True, white=True)
    assert D._verdict(rounds, CANDS)[0] == "adequate"
    monkeypatch.setattr(_detecting, "MAX_DETECTED", 3)
    named = _detecting.undetected("adequate", rounds)
    assert [c.key for c in named] == ["ripple", "backlash", "hysteresis", "load_friction"]
    text = _detecting.note(named)
    assert text.startswith("not detectable in this design: ripple (ΔBIC -6.0), backlash")
    assert "load_friction (ΔBIC 2.0)" in text and "each of the first 3" in text
    computed = []
    monkeypatch.setattr(_detecting, "detecting", lambda c, base: computed.append(c.key) or {})
    rounds[0]["result"] = None
    assert len(_detecting.for_verdict("adequate", rounds, lambda m: None)) == 3
    assert computed == ["ripple", "backlash", "hysteresis"]  # the best 3, ΔBIC order
    for verdict in ("missing_effect", "ambiguous", "unexplained"):
        assert _detecting.undetected(verdict, rounds) == []


# -- order scans ------------------------------------------------------------------------
def test_order_scan_includes_orders_below_one_period_in_the_swing():
    """The issue's miss: ripple of order 12 over a ±0.24 rad swing (0.46 periods) was
    never tried because the scan skipped orders with less than a period in the swing;
    then order 36 (not in the old list of 11 orders, not a periodogram peak) was never
    tried either. Every integer order 1–48 is screened now, both candidates."""
    import hdid

    m = hdid.Model.default()
    labels = [lb for lb, _ in D._ripple_variants(m, m.float_values(), {"swing_rad": 0.48,
                                                                      "ripple_orders": [37.0, 98.0]})]
    for n in (*range(1, 49), 98):
        assert f"ripple (order {n})" in labels
    assert len(labels) == 49  # 37 is in the list already
    ke = [lb for lb, _ in D._kinematic_variants(m, m.float_values(), {})]
    assert ke == [f"kinematic_error (order {n})" for n in range(1, 49)]
    assert CANDS["ripple"].scanned == 1 and CANDS["kinematic_error"].scanned == 1


def test_every_order_tied_in_the_screen_is_refitted():
    """Less than a period in the swing: low orders screen alike (seed 8805: ripple 1–16
    at one-step Δχ² 460–466), so each within ``SCAN_TIE_DCHI2`` of the best is refitted
    and the fit decides; a clear screen refits the best ``SCAN_REFITS``."""
    assert D._scan_refits([1706.0, 1705.0, 1697.0, 1691.0, 1200.0]) == D.SCAN_REFITS
    tied = [466.0, 465.0, 465.0, 465.0, 465.0, 464.0, 463.0, 462.5, 400.0, 10.0]
    assert D._scan_refits(tied) == 8
    assert D._scan_refits([500.0] * 40) == D.SCAN_MAX_REFITS
    assert D._scan_refits([3.0]) == 1 and D._scan_refits([]) == 0


def test_the_scan_note_states_the_scanned_set_and_the_refitted_orders():
    table = {f"ripple (order {n})": 100.0 - n for n in (*range(1, 49), 98, 101)}
    note = D._scan_note("ripple", table, ["ripple (order 1)", "ripple (order 2)"])
    assert "orders scanned 1–48, 98, 101 (50;" in note and note.endswith("refitted "
        f"(the best {D.SCAN_REFITS} and every one within {D.SCAN_TIE_DCHI2:g} of the best, "
        f"at most {D.SCAN_MAX_REFITS}): 1, 2")


def test_a_base_gain_below_the_floor_is_no_better_optimum():
    """The current model's restart counts as a better basin only when its BIC falls by
    more than ``BASE_IMPROVED_DBIC``. On a clean 250 Hz paper log (n = 35, k = 17: the
    floor is χ² 18) χ² 15.0 → 13.4 is below the floor — no change of BIC, no better
    optimum (the old 1-χ² rule fired) — while 21.7 → 20.2 is above it: ΔBIC 2.5, a
    better basin that still counts."""
    n, k = 35.0, 17
    assert D.bic_value(15.0, n, k) - D.bic_value(13.4, n, k) == 0.0
    assert D.bic_value(21.7, n, k) - D.bic_value(20.2, n, k) > D.BASE_IMPROVED_DBIC
    # far above the floor one χ² is ~n/χ² of BIC: not the 2 that "positive" evidence needs
    assert D.bic_value(400.0, n, k) - D.bic_value(399.0, n, k) < D.BASE_IMPROVED_DBIC


# -- ties that are not strong against the base -------------------------------------------
def test_a_rival_within_ten_is_a_tie_even_if_not_strong_itself():
    """Best at −14, an unrelated candidate at −6: the best is strong against the current
    model, but only 8 better than the other — not "very strong" evidence (> 10) for one
    over the other, so no single confident name."""
    rounds = _round([_cand("hysteresis", -14), _cand("load_friction", -6)])
    verdict, summary, _ = D._verdict(rounds, CANDS)
    assert verdict == "ambiguous"
    assert "ambiguous between hysteresis, load_friction" in summary
    assert CANDS["load_friction"].experiment not in summary  # computed, not a fixed text


# -- warnings and the calibrated false-alarm rate ----------------------------------------
def test_false_alarm_rate_of_the_nearest_measured_design():
    from hdid._diagnosis._rates import DesignRate, clopper_pearson, false_alarm

    lo, hi = clopper_pearson(0, 40)
    # 0 of 40: the exact upper end is 1 − 0.025^(1/40)
    assert lo == 0 and hi == pytest.approx(1 - 0.025 ** (1 / 40))
    paper = DesignRate("paper", 250.0, 4, 0, 40, lo, hi, "test")
    rich = DesignRate("rich", 1000.0, 8, 1, 40, *clopper_pearson(1, 40), "test")
    assert false_alarm(250.0, 4, (paper, rich)) is paper
    assert false_alarm(1000.0, 4, (paper, rich)) is rich  # rate 1×, runs 2×: near
    assert false_alarm(5000.0, 8, (paper, rich)) is None  # 5× the rich rate: not near
    # 8 runs at 500 Hz, the rate read from time stamps: a factor 2 from the rich design,
    # not pushed past it by rounding (it was matched to the paper design, 2× on both)
    assert false_alarm(499.99999999999955, 8, (paper, rich)) is rich
    assert "0 of 40" in paper.text()


def test_the_target_is_met_when_the_one_sided_bound_is_below_it():
    """"≤ 5 %" at 95 % confidence: 1 alarm in 93 logs shows it, 1 in 80 does not; 0 alarms
    need 59 logs."""
    from hdid._diagnosis._rates import TARGET, DesignRate, upper_bound

    assert upper_bound(1, 93) <= TARGET < upper_bound(1, 80)
    assert upper_bound(0, 59) <= TARGET < upper_bound(0, 58)
    assert DesignRate("paper", 250.0, 4, 1, 93, 0.0, 0.06, "t").to_dict()["upper_95"] <= TARGET


def test_measured_rates_are_the_committed_calibration_results():
    """``MEASURED`` is generated from ``calibration/results/diagnose_rates.json``,
    never typed by hand: its counts are the file's, design by design."""
    import json

    from hdid._diagnosis._rates import MEASURED, clopper_pearson

    doc = json.loads((ROOT / "calibration" / "results" / "diagnose_rates.json").read_text())
    for d in MEASURED:
        rows = [r for r in doc["records"] if r["design"] == d.design and "error" not in r]
        k = sum(r["verdict"] != "adequate" for r in rows)
        assert (d.alarms, d.logs) == (k, len(rows))
        assert (d.lo, d.hi) == pytest.approx(clopper_pearson(k, len(rows)), abs=1e-4)


def _rounds_with(results, *, max_lag=10, at_floor=True):
    r = _round(results, at_floor=at_floor, white=True)
    r[0]["white"].max_lag = max_lag
    return r


def test_warnings_say_what_is_known_against_the_verdict():
    from hdid._diagnosis._rates import DesignRate

    best = _cand("hysteresis", -40, at_floor=False, white=False, rms=1.6)
    rounds = _rounds_with([best], max_lag=2)
    w = D._warnings("unexplained", rounds, CANDS, [(50.0, 30.0, "backlash")], None)
    text = " | ".join(w)
    assert "not measured" in text  # no calibrated design near this log
    assert "local one" in text and "backlash" in text  # the base basin found late
    assert "little power" in text  # 2 lags
    bad = DesignRate("paper", 250.0, 4, 3, 40, 0.016, 0.20, "test")
    w = D._warnings("missing_effect", _rounds_with([_cand("hysteresis", -40)]), CANDS, [], bad)
    assert len(w) == 1 and "above the 5 % target" in w[0]
    good = DesignRate("paper", 250.0, 4, 0, 80, 0.0, 0.045, "test")
    assert D._warnings("missing_effect", _rounds_with([_cand("hysteresis", -40)]), CANDS, [],
                       good) == []


# -- fair crediting: the current model from a candidate's optimum -------------------------
def test_base_start_from_a_candidate_that_replaced_a_piece_keeps_the_current_values():
    """soft_windup replaces the cubic spring: its optimum has no k1, k2. The current
    model's start from it takes the candidate's friction (shared) and the *current fit's*
    k1, k2 — not the set-up model's catalog values, which are no optimum of anything."""
    import hdid
    from hdid._fitting import _refit
    from hdid._log import read_log
    from hdid._models._transforms import to_unconstrained
    from hdid.effects import library

    log = read_log(ROOT / "data" / "synthetic" / "csf8_paper.csv")
    m = hdid.Model.default()
    s = _refit.setup(log, m, {})
    ms = m.with_effect(library({"k1": 940.0, "k2": 6.5e7, "_k_wg": 0.094})["soft_windup"])
    s2 = _refit.setup(log, ms, {})
    tail = np.linspace(0.0, 1.0, s.problem.n_unknowns - s.problem.n_physical)
    now = {**m.float_values(), "k1": 1234.0, "k2": 5.0e7, "tau_c": 2.0e-3}
    cand_vals = {**ms.float_values(), "tau_c": 3.1e-3}
    current = SimpleNamespace(values=lambda: now, setup=s,
                              u=np.concatenate([np.zeros(s.problem.n_physical), tail]))
    sf = SimpleNamespace(finite=True, values=lambda: cand_vals, setup=s2, label="soft_windup",
                         u=np.concatenate([np.zeros(s2.problem.n_physical), tail]))
    (origin, u), = D._base_starts(s, current, [sf], {})
    assert origin == "reverse:soft_windup"
    specs = m.parameter_specs()
    got = dict(zip(s.problem.free, u[: s.problem.n_physical]))
    assert got["k1"] == pytest.approx(float(to_unconstrained(specs["k1"], 1234.0)))
    assert got["k2"] == pytest.approx(float(to_unconstrained(specs["k2"], 5.0e7)))
    assert got["tau_c"] == pytest.approx(float(to_unconstrained(specs["tau_c"], 3.1e-3)))
    np.testing.assert_array_equal(u[s.problem.n_physical:], tail)


def test_candidate_warm_starts_are_at_the_current_optimum(monkeypatch):
    """Item 1: every candidate starts from the current optimum — shared parameters at the
    current fit's values (not at the values its model was set up with, the catalog's),
    the added effect's at its data-derived values. The refits are captured, not run."""
    import hdid
    from hdid._fitting import _refit
    from hdid._log import read_log
    from hdid._models._transforms import to_unconstrained

    log = read_log(ROOT / "data" / "synthetic" / "csf8_paper.csv")
    m = hdid.Model.default()
    s = _refit.setup(log, m, {})
    fitted = {**m.float_values(), "k1": 1100.0, "tau_c": 2.2e-3, "tau_s": 3.5e-3,
              "v_s": 3.5, "delta": 1.2}
    tail = np.linspace(0.0, 1.0, s.problem.n_unknowns - s.problem.n_physical)
    current = SimpleNamespace(values=lambda: fitted, model=m, setup=s,
                              u=np.concatenate([np.zeros(s.problem.n_physical), tail]))
    seen = []
    monkeypatch.setattr(_refit, "run", lambda label, s2, starts: seen.append((s2, starts)))
    D._candidate_fits(log, CANDS["hysteresis"], current, {"swing_rad": 0.3}, {}, [],
                      lambda msg: None, {})
    assert seen and all(o == "warm" for _, st in seen for o, _ in st)
    specs = m.parameter_specs()
    for s2, starts in seen:
        for _, u in starts:
            got = dict(zip(s2.problem.free, u[: s2.problem.n_physical]))
            for k in ("k1", "tau_c", "tau_s", "v_s", "delta"):
                assert got[k] == pytest.approx(float(to_unconstrained(specs[k], fitted[k]))), k
            np.testing.assert_array_equal(u[s2.problem.n_physical:], tail)


def test_an_order_replaced_in_one_set_up_is_the_set_up_of_that_order():
    """The scan builds one set-up and replaces the order (a traced value): leaf for
    leaf the problem a fresh set-up of that order builds."""
    import jax

    import hdid
    from hdid._fitting import _refit
    from hdid.effects import library

    from hdid.reference import logs

    truth = {k: v for k, v in logs.TRUTH_CSF8.items() if k != "ratio"}
    log = logs.make_log(truth, amplitudes=[0.157, -0.157], fs=250.0, duration=0.3, hold=0.04,
                        offsets_by_setup={"A": 0.0}, seed=3)
    m = hdid.Model.default()
    v = m.float_values()
    for key in ("ripple", "kinematic_error"):
        s1 = _refit.setup(log, m.with_effect(library({**v, "order": 1.0})[key]), {})
        s7 = _refit.setup(log, m.with_effect(library({**v, "order": 7.0})[key]), {})
        got = D._reorder(s1, key, 7.0)
        a, ta = jax.tree_util.tree_flatten(got.problem)
        b, tb = jax.tree_util.tree_flatten(s7.problem)
        assert ta == tb and all(np.array_equal(np.asarray(x), np.asarray(y)) for x, y in zip(a, b))
        assert D._effect_of(got.model, key).order == 7.0 and got.model.float_values() == s7.model.float_values()


def test_a_fine_encoders_sparse_levels_are_not_taken_for_its_step(monkeypatch):
    """Diagnose's wrong-step guard (:func:`hdid._diagnosis._wrong_step.readings_step`)
    takes the readings' smallest gap as the step only where every level lies on that
    gap's grid. A fine encoder read at a low rate (64 000 counts/rev at 250 Hz: the
    backlash–soft_windup experiment) may never show adjacent counts: its smallest gap was
    15–37 steps and, taken as the step, turned a 17× misfit into "adequate". Here a run's
    levels 0, 37, 81, 140, 176, 203 steps (smallest gap 27, 37/27 off its grid by 0.37)
    with a residual 10× the given step's floor (within the guard's 3× of the gap's floor):
    the given step stays. Levels 0, 8, 24, 48, 80 steps (an 8-step encoder given as 1
    step) still switch to 8 steps. Fails without the grid check (the first case is
    refitted with the gap as the step)."""
    import dataclasses

    from hdid._diagnosis import _wrong_step as W
    from hdid._fitting import _refit

    step = 2 * math.pi / 64000
    calls = []
    monkeypatch.setattr(_refit, "setup", lambda log, *a: calls.append(log.resolution) or "setup")
    monkeypatch.setattr(_refit, "grid", lambda *a: "grid")
    monkeypatch.setattr(_refit, "run", lambda *a: "refit")

    def guard(levels):
        theta = np.array([[lv * step for lv in levels] + [levels[-1] * step] * 4])
        prep = SimpleNamespace(quantized=True, theta=theta, lengths=[theta.shape[1]],
                               resolution=step)
        current = SimpleNamespace(rms_rad=lambda: 10 * step / math.sqrt(12.0))
        log = dataclasses.make_dataclass(
            "L", [("resolution", float), ("resolution_source", str)])(step, "given")
        return W.readings_step(log, None, {}, SimpleNamespace(prep=prep), "grid0", current,
                               lambda m: None, 1)

    _, _, fit, warning = guard([0, 37, 81, 140, 176, 203])
    assert warning is None and not calls, (warning, calls)
    _, _, fit, warning = guard([0, 8, 24, 48, 80])
    assert warning is not None and fit == "refit"
    assert calls == [pytest.approx(8 * step)]


def test_ambiguous_names_the_experiment_that_separates_the_best_from_every_rival(monkeypatch):
    """With several rivals the experiment named first is the maximin over them (the largest
    smallest separation), not one pair's best: on paper log 9902 the experiment that
    separated backlash from hysteresis by 609 left soft wind-up inside the noise on every
    simulated backlash log. Constructed separations (no fit): experiment X separates the
    best from rival B by 600 but from C by 3, Y by 40 and 25: Y must be named, its smallest
    value 25 against C, each rival's value and kind listed; the pairs' own records stay.
    Fails where each pair's best is named alone (X for B)."""
    from hdid._diagnosis import _separating as S

    best = SimpleNamespace(key="backlash")
    rivals = [SimpleNamespace(key="hysteresis"), SimpleNamespace(key="soft_windup")]
    table = {"hysteresis": {"X": (600.0, True, "x"), "Y": (40.0, True, "y"), "Z": (5.0, False, "z")},
             "soft_windup": {"X": (3.0, False, "x"), "Y": (25.0, False, "y")}}

    def fake(a, b, **kw):
        v = table[b.key]
        top = max(v, key=lambda n: v[n][0])
        return {"forms": [a.key, b.key], "experiment": top, "expected_2lnlr": v[top][0],
                "text": f"{a.key} vs {b.key}: {top}", "_values": dict(v)}

    monkeypatch.setattr("hdid._diagnosis._verdict.pairs_to_separate", lambda *a: [(best, r) for r in rivals])
    monkeypatch.setattr(S, "separating", fake)
    out = S.for_verdict("ambiguous", [], {}, lambda *a: None)
    assert [x["experiment"] for x in out] == ["Y", "X", "Y"], out
    every = out[0]
    assert every["forms"] == ["backlash", "hysteresis", "soft_windup"] and every["against"] == "every rival"
    assert every["expected_2lnlr"] == 25.0 and every["reaches_min_separation"]
    assert every["per_rival"]["hysteresis"] == {"expected_2lnlr": 40.0, "value_kind": "rival fitted globally"}
    assert every["per_rival"]["soft_windup"]["value_kind"] == "upper bound"
    assert "against soft_windup" in every["text"] and all("_values" not in x for x in out)
    # one rival: no combined record (the pair's own is the answer)
    monkeypatch.setattr("hdid._diagnosis._verdict.pairs_to_separate", lambda *a: [(best, rivals[0])])
    assert [x["experiment"] for x in S.for_verdict("ambiguous", [], {}, lambda *a: None)] == ["X"]
    summary = D._separating_summary("ambiguous", out)
    assert "backlash vs hysteresis and soft_windup: Y, expected 2·ln LR 25 (the smallest over the rivals)" in summary
