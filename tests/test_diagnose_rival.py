"""Same-family candidates the BIC holds at the floor (``hdid._diagnosis._rival``): the χ²
difference of their fits judged under the rounding alone decides which is named first.
Pure NumPy and constructed candidate tables: milliseconds."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from hdid._diagnosis import _diagnose as D
from hdid._diagnosis import _rival as R

CANDS = {c.key: c for c in D.default_candidates()}
SIGMA = 1.0 / math.sqrt(12.0)  # the quantization sd of a unit grid step


def _fits(truth: str, amp: float = 0.2, n: int = 600, phase: float = 0.37):
    """A logged swing read on a unit grid, fitted linearly by two position-periodic forms:
    ``ripple`` (constant amplitude in the angle ``x``) and ``kinematic_error`` (amplitude
    growing with the twist, ∝ ``x``), the truth one of them. Returns the two
    :class:`~hdid._diagnosis._rival.Linear` fits (ripple, kinematic error)."""
    t = np.linspace(0.0, 1.0, n)
    x = np.exp(-3 * t) * np.cos(12 * t)
    base = np.column_stack([np.ones(n), t, 40 * x])
    forms = {"ripple": np.column_stack([np.sin(9 * x), np.cos(9 * x)]),
             "kinematic_error": 3 * x[:, None] * np.column_stack([np.sin(9 * x), np.cos(9 * x)])}
    y = base @ np.array([0.3, -0.5, 1.1]) + forms[truth] @ np.array([amp, -0.4 * amp])
    theta = np.round(y + phase)  # the reading: the angle rounded on the grid
    out = []
    for key in ("ripple", "kinematic_error"):
        X = np.column_stack([base, forms[key]])
        beta, *_ = np.linalg.lstsq(X, theta, rcond=None)
        r = (X @ beta - theta) / SIGMA
        out.append(R.linear(r, X / SIGMA, np.ones(n), theta, SIGMA, float(r @ r)))
    return out


def test_the_chi2_difference_under_the_rounding_favours_the_true_form():
    """Two fits of one rounded log, the truth either form: the observed χ² difference is
    typical of the true form's rounding and not of the other's."""
    for truth, sign in (("ripple", 1), ("kinematic_error", -1)):
        rip, ke = _fits(truth)
        ev = R.cross_evidence(rip, ke)
        assert sign * ev.two_ln_lr > 10, (truth, ev)
        under_truth = (ev.mean_a, ev.sd_a) if truth == "ripple" else (ev.mean_b, ev.sd_b)
        assert abs(ev.d - under_truth[0]) < 3 * under_truth[1]


def test_one_form_against_itself_is_no_evidence():
    rip, _ = _fits("ripple")
    ev = R.cross_evidence(rip, rip)
    assert ev.d == 0 and ev.two_ln_lr == 0


def test_fits_of_other_samples_are_not_compared():
    rip, ke = _fits("ripple")
    other = R.Linear(ke.r, ke.U, ke.rows[:-1], ke.w[:-1], ke.sigma, ke.yhat[:-1], ke.cost)
    assert R.cross_evidence(rip, other) is None


def _cand(key, dbic, chi2, n=141.0, k=26):
    fit = SimpleNamespace(finite=True, cost=chi2, n_effective=n, n_unknowns=k)
    return D.CandidateResult(key, key, 4.1, 0.9, dbic, 2, True, "", {}, None, None,
                             fit=fit, white_after=True, moving_ratio_after=0.9)


def _table():
    # seed 8905's (hidden ripple, order 36): both position-periodic fits below n − k = 115,
    # the BIC gap 1.83 = 2·ln(120/48), the two scans' cost
    return [_cand("kinematic_error", -404.71, 108.17), _cand("ripple", -402.88, 105.65),
            _cand("hysteresis", -270.61, 325.7)]


def _evidence(two_ln_lr):
    return lambda a, b: R.Evidence(b.fit.cost - a.fit.cost, 12.9, 9.2, -13.0, 5.6, two_ln_lr)


def test_below_the_floor_the_evidence_not_the_scan_cost_names_the_form():
    """The suite's hidden ripples were named kinematic error by the scans' cost alone;
    with the χ² difference favouring the ripple (2·ln LR 5.4 > 1.83) the ripple is named,
    the kinematic error as the same mark, and the note gives the numbers."""
    results = _table()
    notes = R.rank_within_families(results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
                                   evidence=_evidence(-5.4))
    assert [c.key for c in results] == ["ripple", "kinematic_error", "hysteresis"]
    assert len(notes) == 1 and "ranked first" in notes[0] and "-3.6" in notes[0]
    verdict, summary, _ = D._verdict([{"results": results, "white": None, "floor": 1.0}],
                                     CANDS)
    assert verdict == "missing_effect"
    assert summary.startswith("add ripple") and "or kinematic_error" in summary


def test_no_evidence_leaves_the_bic_order_and_says_so():
    results = _table()
    notes = R.rank_within_families(results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
                                   evidence=_evidence(0.3))
    assert [c.key for c in results] == ["kinematic_error", "ripple", "hysteresis"]
    assert "not ranked first" in notes[0] and "does not tell the two forms apart" in notes[0]


def test_above_the_floor_the_bic_decides():
    """A fit above n − k is seen by the BIC (its χ² is in it): no reordering, no note."""
    results = _table()
    results[0].fit.cost = 130.0
    assert R.rank_within_families(results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
                                  evidence=_evidence(-50.0)) == []
    assert results[0].key == "kinematic_error"


def test_other_families_and_weak_candidates_are_left_alone():
    results = [_cand("hysteresis", -30.0, 100.0), _cand("backlash", -29.0, 99.0)]
    assert R.rank_within_families(results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
                                  evidence=_evidence(-50.0)) == []
    results = [_cand("kinematic_error", -9.0, 100.0), _cand("ripple", -8.0, 99.0)]
    assert R.rank_within_families(results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
                                  evidence=_evidence(-50.0)) == []


def test_diagnose_ranks_within_families_after_sorting():
    """``diagnose`` applies the rule to its sorted table (the wiring: the call is there)."""
    import inspect

    src = inspect.getsource(D._ladder_of_candidates)  # each round of diagnose
    assert src.index("candidate_table(") < src.index("rank_within_families(") < src.index(
        "analyse_strong(")
    assert "results.sort(" in inspect.getsource(D.candidate_table)  # the table is sorted


def _paper_9905():
    # seed 9905 (paper design, hidden ripple of order 16): all three fit below n − k;
    # asymmetric friction first by the penalties alone (one parameter and no scan less)
    return [_cand("asymmetric_friction", -100.5, 11.54, n=35.0, k=18),
            _cand("kinematic_error", -87.8, 2.53, n=35.0, k=19),
            _cand("ripple", -85.9, 2.75, n=35.0, k=19),
            _cand("backlash", 3.0, 327.4, n=35.0, k=18)]


def test_below_the_floor_a_penalty_gap_the_chi2_difference_contradicts_is_a_rival():
    """9905: the χ² difference favours the ripple (2·ln LR −7.0 for asymmetric friction,
    −5.5 against the kinematic error): the evidence for asymmetric friction over them is
    7.6 and 7.2, not very strong: ambiguous, not a confident wrong name."""
    results = _paper_9905()
    lr = {"ripple": -7.0, "kinematic_error": -5.5}
    notes = R.rank_within_families(
        results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
        evidence=lambda a, b: R.Evidence(b.fit.cost - a.fit.cost, -1.9, 1.9, -4.3, 1.9,
                                         lr[b.key]))
    # the two D distributions (−1.9 ± 1.9, −4.3 ± 1.9) overlap: power 1.6 < SEPARABLE, so
    # the penalties' gap is dropped and 2·ln LR alone is the evidence (docs/decisions/rival-scale.md)
    assert [round(c.floor_gap, 1) for c in results[1:3]] == [-5.5, -7.0]
    assert math.isnan(results[3].floor_gap)  # not strong, not compared
    assert sum("a rival" in n for n in notes) == 2
    verdict, summary, _ = D._verdict([{"results": results, "white": None, "floor": 1.0}],
                                     CANDS)
    assert verdict == "ambiguous" and "asymmetric_friction, kinematic_error" in summary


def test_below_the_floor_evidence_for_the_best_keeps_it_named():
    """Only the data name one of two floor-level forms of different families: the
    rounding's 2·ln LR for the best of 12 (> AMBIGUOUS_DBIC) keeps asymmetric friction
    named; 3 (the penalties' gap of 12.7 beside it no longer counts) is ambiguous."""
    for lr, want in ((12.0, "missing_effect"), (3.0, "ambiguous")):
        results = _paper_9905()
        R.rank_within_families(
            results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
            evidence=lambda a, b: R.Evidence(b.fit.cost - a.fit.cost, 1.0, 1.0, -1.0, 1.0,
                                             lr))
        verdict, summary, _ = D._verdict([{"results": results, "white": None, "floor": 1.0}],
                                         CANDS)
        assert verdict == want, (lr, summary)
    assert summary.startswith("ambiguous between asymmetric_friction")


def test_the_evidence_is_in_each_compared_candidates_json_entry():
    """The numbers behind a reordering or a rival are in the JSON (``floor_evidence``, as
    declared in diagnose.schema.json), not only in the notes; a candidate not compared
    has none."""
    import json

    jsonschema = __import__("pytest").importorskip("jsonschema")
    from hdid._results._saved import schema

    results = _table()
    R.rank_within_families(results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
                           evidence=_evidence(-5.4))
    ripple, kinematic, hysteresis = results
    entry = json.loads(json.dumps(ripple.to_dict(), allow_nan=False))["floor_evidence"]
    # compared against the BIC's best of the family (kinematic error), 2·ln LR as given
    assert entry["against"] == "kinematic_error" and entry["two_ln_lr_for_against"] == -5.4
    assert entry["chi2_difference"] == ripple.fit.cost - kinematic.fit.cost
    assert "floor_evidence" not in kinematic.to_dict() and "floor_evidence" not in hysteresis.to_dict()
    results = _paper_9905()
    R.rank_within_families(
        results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
        evidence=lambda a, b: R.Evidence(b.fit.cost - a.fit.cost, -1.9, 1.9, -4.3, 1.9, -7.0))
    rip = next(c for c in results if c.key == "ripple").to_dict()
    assert rip["floor_evidence"]["against"] == "asymmetric_friction"
    assert rip["floor_evidence"]["floor_gap"] == next(
        c for c in results if c.key == "ripple").floor_gap
    # the log's power to tell them apart, which decided that the BIC gap was dropped:
    # D's two distributions, −1.9 ± 1.9 and −4.3 ± 1.9, expect 2·ln LR = 2.4²/1.9² = 1.6 < 2
    assert abs(rip["floor_evidence"]["expected_two_ln_lr"] - 2.4**2 / 1.9**2) < 1e-12
    assert rip["floor_evidence"]["expected_two_ln_lr"] < R.SEPARABLE
    validator = jsonschema.Draft202012Validator(
        schema("diagnose")["properties"]["candidates"]["items"])
    for c in (ripple, rip):
        d = c if isinstance(c, dict) else c.to_dict()
        assert not list(validator.iter_errors(d)), list(validator.iter_errors(d))[:1]
    bad = {**rip, "floor_evidence": {"against": "ripple"}}
    assert list(validator.iter_errors(bad))  # the entry's fields are required, not only allowed


def test_the_power_is_the_expected_evidence_of_the_two_distributions():
    """``Evidence.power``: 2·KL of the two normals, the worse way round; equal sds give
    (Δμ/s)², one distribution against itself 0, and it equals the Monte Carlo mean of
    2·ln LR under the truth (tolerance: 5 standard errors of a 40 000-draw mean)."""
    assert R.Evidence(0.0, 1.0, 2.0, 1.0, 2.0, 0.0).power() == 0.0
    assert math.isclose(R.Evidence(0.0, 3.0, 2.0, -1.0, 2.0, 0.0).power(), 4.0)
    ev = R.Evidence(0.0, 13.8, 12.6, -11.8, 7.1, 0.0)  # seed 8901's backlash vs KE
    rng = np.random.default_rng(1)
    two_ln = []
    for (m, s) in ((ev.mean_a, ev.sd_a), (ev.mean_b, ev.sd_b)):
        d = rng.normal(m, s, 40_000)
        lr = (-((d - ev.mean_a) / ev.sd_a) ** 2 - 2 * math.log(ev.sd_a)
              + ((d - ev.mean_b) / ev.sd_b) ** 2 + 2 * math.log(ev.sd_b))
        two_ln.append((abs(lr.mean()), lr.std() / math.sqrt(lr.size)))
    low = min(two_ln)
    assert abs(ev.power() - low[0]) < 5 * low[1]


def _blind(a, b):
    # 9905's distributions of D (power 1.6: the paper log cannot tell the fits apart) with
    # D typical of both, as on logs drawn from its fitted ripple (2·ln LR ≈ +0.5)
    return R.Evidence(b.fit.cost - a.fit.cost, -1.9, 1.9, -4.3, 1.9, 0.5)


def test_below_the_floor_a_log_that_cannot_tell_two_families_apart_names_neither():
    """Asymmetric friction 12.7 and 14.6 ahead of the kinematic error and the ripple by the
    penalties alone, the log giving no evidence either way: ambiguous (before the rival test was calibrated by simulation it
    was named with confidence, floor gaps 13.2 and 15.1), and the note says why."""
    results = _paper_9905()
    notes = R.rank_within_families(results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
                                   evidence=_blind)
    assert [round(c.floor_gap, 1) for c in results[1:3]] == [0.5, 0.5]
    assert sum("cannot tell the two apart" in n and "a rival" in n for n in notes) == 2
    verdict, _, _ = D._verdict([{"results": results, "white": None, "floor": 1.0}], CANDS)
    assert verdict == "ambiguous"


def test_below_the_floor_a_log_that_separates_the_fits_no_longer_keeps_the_penalty_gap():
    """The same gaps and 2·ln LR with distributions the log separates (8901's, power 4.6):
    the rival rule of :mod:`._rival` keeps the BIC gap (13.2, 15.1: not rivals by it), but
    the three forms all reach the floor and the data's own evidence for asymmetric friction
    is 2·ln LR 0.5: the penalties alone would choose, so the verdict is ambiguous (issue:
    penalties never choose between floor-level forms of different families)."""
    results = _paper_9905()
    R.rank_within_families(
        results, CANDS, D.STRONG_DBIC, D.AMBIGUOUS_DBIC,
        evidence=lambda a, b: R.Evidence(b.fit.cost - a.fit.cost, 13.8, 12.6, -11.8, 7.1,
                                         0.5))
    assert [round(c.floor_gap, 1) for c in results[1:3]] == [13.2, 15.1]
    verdict, summary, _ = D._verdict([{"results": results, "white": None, "floor": 1.0}],
                                     CANDS)
    assert verdict == "ambiguous"
    assert summary.startswith("ambiguous between asymmetric_friction, kinematic_error, ripple")
