"""An encoder finer than the print unit: the readings' resolution is the printing.

A 2^20-count encoder printed in degrees to 3 decimals (its step 0.34 print units) or in rad
to 4 decimals (0.06): every level difference is a whole number of print units, no encoder
step can be told (the reader says so and claims none), a still stretch repeats one printed
level, and a moving reading's error is its rounding to the print unit, ``p/√12``, plus the
encoder's ``q/√12`` (unknown, below the unit). Before, the still stretches' noise estimate
had nothing to measure and the floor came from an upper bound (the motion's third
differences here: 130x the readings' error in degrees, 20x in rad; ``1e-4`` of the angle
span on a 58 Hz CSF-8 log at 1 kHz: 6x, a right fit at 0.14x its floor). Logs are Coulomb
ring-downs in numpy (the floor needs no gear model), at 1 kHz in whole milliseconds.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from hdid import read_log
from hdid._simulation._noise import print_floor
from hdid._simulation._prepare import prepare
from test_world_logs_more import _coulomb_swing  # (HV's Coulomb ring-down: 0.004 rad band)

Q20 = 2.0 * math.pi / 2**20  # 5.99e-6 rad


def _printed_log(tmp_path, degrees: bool, seed: int):
    """Four runs (releases at +-0.3 rad, 58 Hz, stuck tails) read by the 2^20 encoder at a
    random offset and printed as a logger prints them; the path, the print unit [rad] and
    each reading's true error [rad]."""
    rng = np.random.default_rng(seed)
    offset = rng.uniform(-1.0, 1.0)
    t = np.arange(400) * 1e-3
    unit, fmt = (math.radians(1e-3), "%.3f") if degrees else (1e-4, "%.4f")
    rows, errors = [], []
    for k, s in enumerate((1, -1, 1, -1), 1):
        x = _coulomb_swing(t, 0.3 * rng.uniform(0.8, 1.0) * s, f=58.0,
                           release=rng.uniform(0.03, 0.04)) + offset
        reading = np.round(x / Q20) * Q20
        tick = 1e-3 if degrees else 1e-4  # (the print unit in the log's own unit)
        printed = np.round((np.degrees(reading) if degrees else reading) / tick) * tick
        errors.append((np.radians(printed) if degrees else printed) - x)
        rows.append(np.column_stack((np.full(x.size, k), t * 1e3, printed)))
    path = tmp_path / f"fine{int(degrees)}_{seed}.csv"
    np.savetxt(path, np.vstack(rows), fmt=["%d", "%.0f", fmt], delimiter=",",
               header=f"run,time [ms],theta [{'deg' if degrees else 'rad'}]", comments="")
    return path, unit, errors


@pytest.mark.parametrize("degrees", [True, False], ids=["deg3", "rad4"])
def test_the_print_unit_sets_the_floor_of_a_finer_encoder(tmp_path, degrees):
    for seed in (1, 2):
        path, unit, errors = _printed_log(tmp_path, degrees, seed)
        log = read_log(path)
        assert log.resolution is None  # never the print unit taken for the encoder's step
        prep = prepare(log)
        assert prep.floor == pytest.approx(unit / math.sqrt(12.0), rel=1e-9)
        w2 = np.concatenate([prep.weight[i, : e.size] ** 2 for i, e in enumerate(errors)])
        err = np.concatenate(errors)
        err = err - np.sum(w2 * err) / np.sum(w2)
        rms = math.sqrt(np.sum(w2 * err**2) / np.sum(w2))
        # the readings' error is sqrt(p^2 + q^2)/sqrt(12) (1.057x the floor in degrees,
        # 1.002x in rad: the encoder's q is below the unit and unknown); its RMS over
        # ~1150 effective readings: 1.3 % (one sd, 0.45/sqrt(n_eff)), 2.7 % observed over
        # seeds 1-8 (slow readings share print errors; 1.051 +- 0.027, 0.992 +- 0.016):
        # 10 % is ~4 sd. Before: 0.0076-0.011x in degrees, 0.041-0.060x in rad
        expect = math.sqrt(1.0 + (Q20 / unit) ** 2)
        assert rms / prep.floor == pytest.approx(expect, abs=0.1), (seed, rms / prep.floor)


def test_a_print_unit_finer_than_the_readings_steps_keeps_the_noise_estimate():
    """Guards: readings printed to 1e-10 (a processed log: the reverted rule gave it a
    1e-10 floor) and readings whose still stretches flicker over a few units are left to
    the noise estimate; only exact repeats with levels one unit apart are the printing."""
    rng = np.random.default_rng(3)
    t = np.arange(600) * 1e-3
    x = _coulomb_swing(t, 0.2, f=30.0)
    coarse = SimpleNamespace(theta=np.round(x / 1e-4) * 1e-4)
    assert print_floor([coarse], 1e-4) == pytest.approx(1e-4 / math.sqrt(12.0))
    processed = SimpleNamespace(theta=np.round(np.round(x / 1e-3) * 1e-3 * 1.0123456789e0
                                               / 1e-10) * 1e-10)
    assert print_floor([processed], 1e-10) == 0.0
    noisy = SimpleNamespace(theta=np.round((x + rng.normal(0.0, 2e-4, x.size)) / 1e-4) * 1e-4)
    assert print_floor([noisy], 1e-4) == 0.0
