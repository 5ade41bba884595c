"""The rounding floor measured on the log in hand (``hdid._diagnosis._floor``) and the
report and warning built on it (``hdid._diagnosis._excess``;
``docs/decisions/floor-threshold.md``): the floor against brute force, the threshold's
statistics, the generated thresholds against the committed calibration, the warning's rule."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from hdid._diagnosis import _excess
from hdid._diagnosis._excess import FloorCheck, FloorThreshold, choose, floor_text
from hdid._diagnosis._floor import projected_floor, saw, white_floor
from hdid._diagnosis._rates import upper_bound

from synthetic import ROOT


def _brute_floor(yhat, w, J, sigma, step, rows, phases):
    """The same mean by another route: round the trajectory on each shifted grid, refit
    the linear model by ``lstsq`` and average the χ² left."""
    out = []
    for c in (np.arange(phases) + 0.5) / phases * step:
        data = step * np.round((yhat + c) / step) - c
        r = np.zeros(J.shape[0])
        r[rows] = w * (yhat - data) / sigma
        d, *_ = np.linalg.lstsq(J, -r, rcond=None)
        out.append(float(np.sum((r + J @ d) ** 2)))
    return float(np.mean(out)), float(np.std(out))


def test_the_floor_is_the_mean_chi2_a_correct_model_leaves():
    rng = np.random.default_rng(0)
    step = 1.0
    sigma = step / math.sqrt(12)
    t = np.linspace(0, 1, 60)
    yhat = 7.3 * np.sin(5 * t) * np.exp(-2 * t) + 0.2  # a decaying swing, a few steps
    w = np.ones(60)
    w[:10] = 1 / math.sqrt(10)  # a "hold" sharing one observation's weight
    yhat[:10] = 0.2
    J = np.zeros((63, 5))  # 60 data rows, 3 prior rows
    J[:60] = np.column_stack([np.ones(60), t, np.sin(5 * t), np.cos(5 * t), t**2]) * w[:, None]
    J[60:, :3] = np.diag(rng.uniform(0.5, 2, 3))
    rows = np.arange(60)
    F, sd = projected_floor(yhat, w, J, sigma, step, rows, phases=64)
    Fb, sdb = _brute_floor(yhat, w, J, sigma, step, rows, phases=64)
    assert F == pytest.approx(Fb, rel=1e-9)
    assert sd == pytest.approx(sdb, rel=1e-9)


def test_slow_motion_leaves_far_less_than_n_minus_k():
    # 40 samples creeping 0.3 of a step (a slow approach to rest): the rounding error is
    # one smooth piece with at most one jump, an offset and a slope absorb most of it
    # (white noise would leave n − k = 38)
    step, sigma = 1.0, 1 / math.sqrt(12)
    t = np.linspace(0, 1, 40)
    yhat = 0.3 * t**2
    J = np.column_stack([np.ones(40), t])
    F, _ = projected_floor(yhat, np.ones(40), J, sigma, step, np.arange(40))
    assert F < 0.5 * (40 - 2)
    # and fast motion (many steps between samples) leaves the white-noise floor
    F, _ = projected_floor(37.1 * np.arange(40) ** 1.1, np.ones(40), J, sigma, step,
                           np.arange(40), phases=256)
    assert F == pytest.approx(38, rel=0.1)


def test_white_noise_floor_and_sawtooth():
    J = np.column_stack([np.ones(10), np.arange(10.0), np.arange(10.0)])  # rank 2
    assert white_floor(J, 10.0) == 8.0
    assert saw(np.array([0.49, 0.51, -0.2, 2.2]), 1.0) == pytest.approx([0.49, -0.49, -0.2, 0.2])


# -- the threshold: an order statistic of clean logs' χ²/F -------------------------------
def test_choose_takes_the_order_statistic_the_bound_allows():
    # 0 of N exceed the largest: shown (≤ 5 % at 95 %) from 59 logs on
    assert choose(range(58)) is None
    assert choose(range(59)) == (58.0, 0)
    # 200 logs: the 5th largest (4 above it): upper_bound(4, 200) = 4.5 %, (5, 200) 5.2 %
    thr, above = choose(np.arange(200.0))
    assert (thr, above) == (195.0, 4)
    assert upper_bound(above, 200) <= 0.05 < upper_bound(above + 1, 200)


def test_a_new_clean_log_exceeds_the_threshold_at_most_at_the_stated_rate():
    """The footing, by simulation: the exceedance probability of the threshold chosen from
    N exchangeable draws is Beta(j, N + 1 − j); above the stated 95 % bound (≤ 5 %) in at
    most 5 % of calibrations. Uniform draws: the exceedance of threshold t is 1 − t.
    4000 calibrations: the Monte Carlo sd of a 5 % fraction is 0.34 %; 3 sd allowed."""
    rng = np.random.default_rng(19)
    for n in (60, 200):
        p = np.array([1 - choose(rng.uniform(size=n))[0] for _ in range(4000)])
        _, above = choose(np.arange(n))
        assert np.mean(p > upper_bound(above, n)) <= 0.05 + 3 * 0.0034
        assert np.mean(p) == pytest.approx((above + 1) / (n + 1), abs=3 * np.std(p) / 63)


def test_the_thresholds_are_the_committed_clean_log_results():
    """``_excess.ROWS`` is generated from ``calibration/results/floor_thresholds.json`` by
    ``calibration/floor_thresholds.py --threshold``, never typed by hand: every design of the file with
    enough clean logs is there, with its logs, exceedances and threshold."""
    doc = json.loads((ROOT / "calibration" / "results" / "floor_thresholds.json").read_text())
    designs = {r["design"] for r in doc["rows"]}
    assert {t.design for t in _excess.THRESHOLDS} == designs
    for t in _excess.THRESHOLDS:
        r = [x["ratio"] for x in doc["rows"] if x["design"] == t.design
             and x["kind"] == "calibration"]
        thr, above = choose(r)
        assert (t.logs, t.above) == (len(r), above)
        # rounded up at the 4th decimal: never below the order statistic, no log crosses
        assert thr <= t.threshold < thr + 1e-4
        assert sum(x > t.threshold for x in r) == above
        assert t.upper <= 0.05  # the target is shown, not hoped for


# -- the report and the warning ----------------------------------------------------------
RICH = FloorThreshold("rich", 1000.0, 8, 200, 4, 1.25, "test")


def _check(chi2, threshold=RICH):
    return FloorCheck(chi2, floor=100.0, floor_sd=12.0, n=128.0, k=24, threshold=threshold)


def test_the_warning_is_for_verdicts_naming_no_effect_above_the_threshold():
    above, below = _check(130.0), _check(120.0)
    assert above.exceeded and not below.exceeded
    w = above.warnings("adequate")
    assert len(w) == 1 and "1.30× the rounding floor" in w[0] and "rich design" in w[0]
    assert f"{100 * upper_bound(4, 200):.1f} %" in w[0]
    assert above.warnings("unexplained") and not above.warnings("missing_effect")
    assert not above.warnings("ambiguous") and not below.warnings("adequate")
    assert above.notes() == []


def test_far_from_every_measured_design_the_ratio_is_reported_without_warning():
    far = _check(200.0, threshold=None)
    assert far.exceeded is None and far.warnings("adequate") == []
    assert "not measured for a design near" in far.notes()[0]
    assert _excess.threshold_for(5000.0, 8, (RICH,)) is None  # 5× the rate: not near
    assert _excess.threshold_for(1000.0, 4, (RICH,)) is RICH  # runs 2×: near


def test_the_report_line_names_chi2_the_floor_its_spread_the_ratio_and_n_minus_k():
    d = _check(130.0).to_dict()
    assert d["n_minus_k"] == 104.0 and d["chi2_over_floor"] == pytest.approx(1.3)
    text = floor_text(d)
    for part in ("χ² 130.0", "1.30×", "F 100.0 ± 12.0", "n − k = 104.0", "1.25×"):
        assert part in text, text
    assert "no clean-log threshold" in floor_text(_check(130.0, None).to_dict())
