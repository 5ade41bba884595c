"""Runs that never move are data (issue 33, "What to build" 3).

A release inside the stick band is a perfectly real outcome: the gear stays where it was
let go. Such a run is kept: its reading is a rest point, the model releases it at its
first sample from that reading (a model whose stick band holds it stays stuck, residual
zero; one whose band is narrower slides off and pays for it), so it bounds the band from
below. It is named in the warnings, never fatal; a log of still runs only is one
:class:`hdid.LogError` line (nothing to fit).

The log comes from the independent generator (``tests/independent.py``, solve_ivp with
an exact stick rule), the paper's design plus a fifth release at half the plant's stick
band edge; the old code refused it (``run '5' shows no motion``, exit 2).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import hdid
import independent as ind
from hdid._simulation._prepare import prepare

PLANT = ind.gear_plant("csf8")
A = 0.157
SETUPS = ["A", "A", "B", "B", "B"]
OFFSETS = {"A": 0.012, "B": -0.020}


def _band_edge(plant: ind.Plant) -> float:
    """Smallest |θ| from which the plant slides from rest: |rest torque| = tau_s."""
    th = np.linspace(0.0, A, 200_001)
    return float(th[np.argmax(np.abs(plant.rest_torque(th)) > plant.static)])


EDGE = _band_edge(PLANT)  # 0.0464 rad at the WG for this plant


@pytest.fixture(scope="module")
def still_log():
    df, truth = ind.make_log(
        PLANT, [A, -A, A, -A, 0.5 * EDGE], rate=250.0, duration=0.5, hold=0.04,
        setups=SETUPS, offsets=OFFSETS, counts_per_rev=4000,
        release_phase=[0.19, 0.43, 0.61, 0.87, 0.3],
    )
    assert truth["runs"][4]["events"] == 0  # the generator agrees: it never moves
    return df, truth


@pytest.fixture(scope="module")
def still_fit(still_log):
    return hdid.fit(still_log[0])


def test_reading_and_preparing_keep_a_still_run(still_log):
    df, _ = still_log
    log = hdid.read_log(df)
    assert [r.name for r in log.runs] == ["1", "2", "3", "4", "5"]
    assert len(log.notes) == 1 and "'5'" in log.notes[0]
    prep = prepare(log)
    assert list(prep.still) == [False] * 4 + [True]
    n = prep.lengths[4]
    # one reading repeated is one observation (quantization error shared by all samples)
    assert np.sum(prep.weight[4, :n] ** 2) == pytest.approx(1.0)
    assert prep.release_lo[4] == prep.release_hi[4] == df[df.run == "5"]["time"].iloc[0]
    assert prep.rest[4] == prep.hold[4]
    assert not prep.ends_moving[4] and not prep.moving_start[4]
    assert prep.direction()[4] == 0.0


def test_a_log_of_still_runs_only_is_one_line(still_log, tmp_path):
    df, _ = still_log
    path = tmp_path / "still_only.csv"
    df[df.run == "5"].to_csv(path, index=False)
    with pytest.raises(hdid.LogError) as info:
        hdid.read_log(path)
    msg = str(info.value)
    assert "\n" not in msg and "no run shows motion" in msg and "still_only.csv" in msg


def test_fit_keeps_the_still_run_stuck_and_bounds_the_band(still_fit, still_log):
    r = still_fit
    _, truth = still_log
    assert any("'5'" in w and "never move" in w for w in r.warnings), r.warnings
    run5 = r.runs[4]
    # released from inside the fitted band, it stays stuck: zero speed, zero residual
    # (its reading is the start angle the fit chose, exact to rounding)
    assert run5.peak_speed == 0.0
    assert run5.rms_rad <= 1e-9 * A
    # its rest point bounds the stick band from below: the fitted half-width is at least
    # its distance from the spring zero (less one encoder step for the reading's rounding)
    step = 2 * math.pi / 4000
    hw = r.derived["stick_band_halfwidth_rad"][0]
    assert hw >= abs(run5.theta0) - step, (hw, run5.theta0)
    # no run's release time is a silent NaN (a release pinned to the first sample is known)
    assert all(math.isfinite(x.release_time_std) for x in r.runs)
    # the stiffness, which the four moving runs determine, is unharmed: within 3 σ of the
    # truth (3 σ: a two-sided 0.3 % false alarm for a Gaussian estimate)
    k1 = r.parameters["k1"]
    assert abs(k1.value - truth["params"]["k1"]) <= 3 * k1.std, (k1.value, k1.std)
