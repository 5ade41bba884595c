"""A still run held beyond a turning point from which a moving run of its set-up slid on
is no rest point (hdid._log._unreleased): at that turning point the spring beat static
friction, and it pulls harder farther out, so a reading held there was held by something
else (a brake, a servo: a run logged but never released). The reader leaves it out with
a note naming it, its level and the turning point; a still run between the rests and the
innermost turning point stays a rest point.

The logs are drawn here (Coulomb ring-downs: a half cosine about ±band per half period,
each turning point 2·band nearer the zero, stuck once within the band), never read from a
shipped file.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from hdid import read_log

STEP = 1e-4  # [rad], encoder step
BAND = 0.004  # [rad], friction band of the ring-downs below: they slide on from ±0.010


def _ring_down(t, a, release=0.03, f=20.0):
    """HV's Coulomb ring-down (tests/test_world_logs_more.py) in this file's band."""
    from test_world_logs_more import _coulomb_swing

    return _coulomb_swing(t, a, band=BAND, f=f, release=release)


def _log(held, step=STEP, noise=0.0, setup_of_held="A"):
    """Runs 1, 2 released from ±0.05 rad (turning points ∓0.042, ±0.034, ∓0.026, ±0.018,
    ∓0.010, rest ±0.002); run 3 held at ``held`` for 300 samples."""
    t = np.arange(400) * 1e-3
    rng = np.random.default_rng(5)
    frames = []
    for k, a in enumerate((0.05, -0.05)):
        th = _ring_down(t, a) + noise * rng.standard_normal(t.size)
        frames.append(pd.DataFrame({"run": k + 1, "setup": "A", "time": t + k,
                                    "theta": np.round(th / step) * step if step else th}))
    frames.append(pd.DataFrame({"run": 3, "setup": setup_of_held, "time": t[:300] + 2,
                                "theta": np.round(held / step) * step if step else held}))
    return pd.concat(frames, ignore_index=True)


@pytest.mark.parametrize("held, turn", [(0.045, 0.010), (-0.03, -0.010)])
def test_a_run_held_beyond_a_slide_on_turning_point_is_left_out_and_named(held, turn):
    log = read_log(_log(held))
    assert [r.name for r in log.runs] == ["1", "2"]
    (note,) = [n for n in log.notes if "'3'" in n]
    assert "left out" in note and f"held at {held:.6g} rad" in note
    # the innermost turning point slid on from on that side, as printed to the 1e-4 step
    assert f"turning point {turn:.6g} rad" in note and "'setup'" in note


@pytest.mark.parametrize("held", [0.001, 0.007, -0.007])
def test_a_run_held_short_of_the_innermost_turning_point_is_a_rest_point(held):
    """0.001: between the rests (±0.002); ±0.007: beyond them but short of ±0.010 — the
    spring there may be held by static friction."""
    log = read_log(_log(held))
    assert [r.name for r in log.runs] == ["1", "2", "3"]
    assert any("'3'" in n and "kept as rest points" in n for n in log.notes), log.notes


def test_a_run_of_its_own_set_up_is_kept():
    """The fix the note gives: a set-up of its own (another zero) keeps the run."""
    log = read_log(_log(0.045, setup_of_held="B"))
    assert [r.name for r in log.runs] == ["1", "2", "3"]


@pytest.mark.parametrize("held, kept", [(0.045, False), (0.0025, True)])
def test_readings_on_no_grid_with_noise(held, kept):
    """No encoder step: the margin is 4 sigma of the noise (1e-6 rad here); the rests'
    noise makes no turning points, 0.0025 rad (short of 0.010) stays a rest point."""
    log = read_log(_log(held, step=0.0, noise=1e-6))
    assert log.resolution is None
    assert ("3" in [r.name for r in log.runs]) == kept, log.notes
