"""Print rounding beside rounded time stamps: both terms in the floor.

A 2^15-count encoder printed to 0.1 mrad (a step of 1.92 print units) logged at 3 kHz
with its instants printed to whole microseconds (steps of 333 and 334 us: instants cut to
the print unit, :mod:`hdid._simulation._timing`). Each reading's error is the encoder's
rounding, the print error of its level (:mod:`hdid._simulation._print_rounding`) and its
speed times its stamp's error; the floor prepare reports must be the RMS of those errors
as the fit weights them. Before, beside rounded stamps the print term was left out and the
readings' error sat 12 % above the floor. The logs are Coulomb ring-downs in numpy (the
floor needs no gear model).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hdid import read_log
from hdid._simulation._prepare import prepare
from hdid._simulation._print_rounding import print_variance
from test_world_logs_more import _coulomb_swing  # (HV's Coulomb ring-down: 0.004 rad band)

Q15 = 2.0 * math.pi / 2**15  # 1.92e-4 rad
P = 1e-4  # the print unit [rad] ("%.4f")


def _stamped_log(tmp_path, seed: int):
    """Six runs at 3 kHz read by the 2^15 encoder at a random offset, printed to 1e-4 rad,
    stamped to 1 us; the log's path and, per run, each reading's true error (against the
    true angle at its printed stamp)."""
    rng = np.random.default_rng(seed)
    offset = rng.uniform(-3.0, 3.0)
    t = np.arange(900) / 3000.0  # (0.3 s)
    rows, errors = [], []
    stamp = np.round(t * 1e6) / 1e6
    for k, s in enumerate((1, -1, 1, -1, 1, -1), 1):
        a, release = 0.157 * rng.uniform(0.7, 1.0) * s, rng.uniform(0.03, 0.04)
        x = _coulomb_swing(t, a, f=58.0, release=release) + offset
        printed = np.round(np.round(x / Q15) * Q15 / P) * P
        # against the true angle at the printed instant
        errors.append(printed - _coulomb_swing(stamp, a, f=58.0, release=release) - offset)
        rows.append(np.column_stack((np.full(x.size, k), stamp, printed)))
    path = tmp_path / f"stamped{seed}.csv"
    np.savetxt(path, np.vstack(rows), fmt=["%d", "%.6f", "%.4f"], delimiter=",",
               header="run,time,theta", comments="")
    return path, errors


def _ratio(tmp_path, seed: int) -> tuple[float, object]:
    """The readings' weighted RMS true error (about its weighted mean, the offset's) over
    prepare's floor, and the prepared log."""
    path, errors = _stamped_log(tmp_path, seed)
    prep = prepare(read_log(path, resolution=Q15))
    assert prep.time_scale is not None  # the stamps are rounded instants here
    w2 = np.concatenate([prep.weight[i, : e.size] ** 2 for i, e in enumerate(errors)])
    err = np.concatenate(errors)
    err = err - np.sum(w2 * err) / np.sum(w2)
    return math.sqrt(np.sum(w2 * err**2) / np.sum(w2)) / prep.floor, prep


def test_the_floor_holds_print_and_stamp_rounding_together(tmp_path):
    # Each log has ~2500 effective readings (holds and stuck tails one each): the RMS of
    # uniform-like errors is within ~1 % (one sd, ~0.45/sqrt(n_eff); 0.9 % over seeds
    # 3-12, mean 0.999) of its expectation, the mean of 4 seeds within ~0.55 %: 3 % is
    # 5 sd. Without the print term the floor misses the print errors' variance (1/1.92^2
    # = 27 % of q^2/12 on the slow readings): the ratio is 1.12 on every seed and fails.
    ratios = []
    for seed in (3, 4, 5, 6):
        r, prep = _ratio(tmp_path, seed)
        assert prep.print_rms == pytest.approx(P / math.sqrt(12.0), rel=0.1)
        ratios.append(r)
    assert float(np.mean(ratios)) == pytest.approx(1.0, abs=0.03), ratios
    assert max(abs(r - 1.0) for r in ratios) < 0.06, ratios  # each: ~5 sd


def test_fast_readings_damp_the_print_term():
    """Beside stamps the term counts by the floor it moves: readings whose stamps' error
    dominates (``s`` large) hide a print error that would count at ``s = 1``."""
    rng = np.random.default_rng(7)
    x = np.cumsum(rng.normal(0.0, 3e-3, 2000)) + 0.7
    theta = np.round(np.round(x / Q15) * Q15 / P) * P
    runs = [type("Run", (), {"theta": theta})()]
    w, setups = np.ones((1, theta.size)), np.zeros(1, int)
    # incommensurate: ~p^2/12, 12 v/q^2 = 0.27 at s = 1; damped 9x by s = 3 everywhere
    # (0.03, still counted) and 25x by s = 5 (0.011, below 0.0201: left out)
    assert print_variance(runs, Q15, P, w, setups) == pytest.approx(P**2 / 12, rel=0.05)
    assert print_variance(runs, Q15, P, w, setups, np.full_like(w, 3.0)) > 0.0
    assert print_variance(runs, Q15, P, w, setups, np.full_like(w, 5.0)) == 0.0
