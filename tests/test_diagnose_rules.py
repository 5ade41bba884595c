"""The decision rules of :func:`hdid.diagnose` (module docstring of ``hdid._diagnose``),
checked on constructed candidate tables: no fit, so they run in milliseconds.

Statistical footing used below: χ² is in units of the quantization variance
``σ_q² = step²/12``, so a correct model leaves ``E χ² = n − k`` on a log with ``n``
effective observations and ``k`` fitted unknowns.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import pytest

from hdid import _diagnose as D


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
def test_tie_between_unrelated_candidates_is_ambiguous_with_both_experiments():
    rounds = _round([_cand("hysteresis", -30), _cand("backlash", -25), _cand("ripple", -5)])
    verdict, summary, _ = D._verdict(rounds, CANDS)
    assert verdict == "ambiguous"
    assert "ambiguous between hysteresis, backlash" in summary
    assert CANDS["hysteresis"].experiment in summary and CANDS["backlash"].experiment in summary
    assert "ripple" not in summary.split("Separating")[0]  # not strong: not named


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


# -- order scans ------------------------------------------------------------------------
def test_order_scan_includes_orders_below_one_period_in_the_swing():
    """The issue's miss: ripple of order 12 over a ±0.24 rad swing (0.46 periods) was
    never tried because the scan skipped orders with less than a period in the swing."""
    import hdid

    m = hdid.Model.default()
    labels = [lb for lb, _ in D._ripple_variants(m, m.float_values(), {"swing_rad": 0.48,
                                                                      "ripple_orders": [37.0]})]
    for n in (1, 2, 3, 12, 37):
        assert f"ripple (order {n})" in labels
    ke = [lb for lb, _ in D._kinematic_variants(m, m.float_values(), {})]
    assert ke == [f"kinematic_error (order {n:g})" for n in D.KINEMATIC_ORDERS]
    assert CANDS["ripple"].scanned == 1 and CANDS["kinematic_error"].scanned == 1
