"""An encoder step of a few print units: the readings' print rounding in the floor.

A 2^15-count encoder printed to 0.1 mrad (a step of 1.92 print units) reads each angle
with the encoder's rounding (``q²/12``) plus the print error of the level it reads, which
is fixed by the level and the offset. The floor is ``√(q² + v)/√12``-like with ``v`` the
print errors' variance measured on the lattice (:mod:`hdid._simulation._print_rounding`):
before, the floor was ``q/√12`` alone and a right fit sat 1.13× above it. Every log here is
drawn by hdid's simulator and numpy (random offsets), never read from a shipped file.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from hdid import read_log
from hdid._simulation._prepare import prepare
from hdid._simulation._print_rounding import print_variance
from hdid._simulation._synthetic import synthesize

Q15 = 2.0 * math.pi / 2**15  # 1.92e-4 rad
P = 1e-4  # the print unit [rad] ("%.4f")
#: the default gear with a tenth of its friction: a ring-down of ~0.3 s, ~30 swings
LOW_FRICTION = {"tau_c": 3e-4, "tau_s": 4.5e-4, "c_v": 2e-6}


def _printed_log(tmp_path, seed: int, step: float = Q15, decimals: int = 4):
    """Six runs of a low-friction default gear (2 kHz, releases at 0.11-0.157 rad) read by an encoder
    of ``step`` at a random offset and printed with ``decimals`` decimals; returns the
    log's path, the true angles (offset included) per run and the offset."""
    rng = np.random.default_rng(seed)
    amps = [0.157 * rng.uniform(0.7, 1.0) * s for s in (1, -1, 1, -1, 1, -1)]
    runs = synthesize(tmp_path / f"true{seed}.csv", amplitudes=amps, rate=2000.0,
                      duration=0.4, counts_per_rev=None, seed=seed, overwrite=True,
                      values=LOW_FRICTION)
    offset = rng.uniform(-3.0, 3.0)
    rows, truth = [], []
    for k, r in enumerate(runs, 1):
        x = np.asarray(r.theta) + offset
        truth.append(x)
        rows.append(np.column_stack((np.full(x.size, k), r.time, np.round(x / step) * step)))
    path = tmp_path / f"printed{seed}.csv"
    np.savetxt(path, np.vstack(rows), fmt=["%d", "%.6f", f"%.{decimals}f"], delimiter=",",
               header="run,time,theta", comments="")
    return path, truth


@pytest.mark.parametrize("seed", [3, 4])
def test_the_floor_is_the_rms_error_of_readings_printed_to_half_a_step(tmp_path, seed):
    """The readings' actual error against the true angle (weighted as the fit weights
    them, about the offset) is the floor prepare reports, not ``q/√12``."""
    path, truth = _printed_log(tmp_path, seed)
    log = read_log(path, resolution=Q15)
    prep = prepare(log)
    w2 = np.concatenate([prep.weight[i, : x.size] ** 2 for i, x in enumerate(truth)])
    err = np.concatenate([np.asarray(r.theta) - x for r, x in zip(log.runs, truth)])
    err = err - np.sum(w2 * err) / np.sum(w2)
    rms = math.sqrt(np.sum(w2 * err**2) / np.sum(w2))
    # ~1900 effective readings: the RMS of uniform-like errors is within ~1 % (one sd,
    # 0.45/√n_eff; 1.1 % over ten seeds) of its expectation; 5 % is > 4 sd. The step's
    # rounding alone (q/√12) is 1/√(1 + 1/1.92²) = 0.887 of it: that floor fails by 12 %.
    assert rms / prep.floor == pytest.approx(1.0, abs=0.05)
    assert prep.print_rms == pytest.approx(P / math.sqrt(12.0), rel=0.1)  # (incommensurate)


def test_the_print_variance_comes_from_the_lattice_not_from_p_squared_over_12():
    """A step of exactly two print units prints every level with one error (a constant
    the offset takes up): nothing is added, where ``p²/12`` would add 6 % to the floor;
    a step of 1.92 units cycles through its levels' errors (≈ ``p²/12``); printed with
    three more decimals the term vanishes (below 1 % of the floor)."""
    rng = np.random.default_rng(7)
    x = np.cumsum(rng.normal(0.0, 3e-3, 2000)) + 0.7
    for step, unit, expect in [(2 * P, P, 0.0), (Q15, P, P**2 / 12), (Q15, P * 1e-3, 0.0)]:
        theta = np.round(np.round(x / step) * step / unit) * unit
        runs = [SimpleNamespace(theta=theta)]
        v = print_variance(runs, step, unit, np.ones((1, theta.size)), np.zeros(1, int))
        # (2000 levels of an incommensurate step: their errors' mean square within 5 %)
        assert v == pytest.approx(expect, rel=0.05, abs=1e-30), (step, unit)

