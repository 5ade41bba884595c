"""The time column's printing, as the reader sees it: ``Log.time_print_unit``.

A logger stamps each reading with its clock cut to a print unit (whole milliseconds from
``millis()``, microseconds from a timer, seconds to 6 decimals). That rounding is a
timing error of up to one unit on every reading, ``ω·u/√12`` rad where the angle moves
at ``ω`` rad/s, which the fit side may add to its noise budget. Each log here is written
by numpy in the test. Every test failed before (no such attribute).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from hdid import read_log


def _ring(t: np.ndarray) -> np.ndarray:
    """A 20 Hz ring-down [rad] on a 4096-count grid, released at t = 5 ms."""
    s = np.maximum(t - 0.005, 0.0)
    x = 0.15 * np.exp(-4.0 * s) * np.cos(2 * math.pi * 20.0 * s)
    q = 2 * math.pi / 4096
    return np.round(x / q) * q


@pytest.mark.parametrize("header, fmt, scale, unit", [
    ("time [s]", "%.6f", 1.0, 1e-6),  # seconds to 6 decimals
    ("time [ms]", "%d", 1e3, 1e-3),  # millis(): whole milliseconds
    ("time [us]", "%d", 1e6, 1e-6),  # micros(): whole microseconds
    ("time [ms]", "%.3f", 1e3, 1e-6),  # milliseconds to 3 decimals
])
def test_the_time_columns_print_unit_is_reported(tmp_path, header, fmt, scale, unit):
    """500 Hz with 2 % jitter, one run: the unit each cell is cut to, in seconds. (Whole
    milliseconds at 1 kHz with jitter repeat a stamp: a one-line error, by design.)"""
    rng = np.random.default_rng(4)
    t = np.cumsum(np.full(600, 2e-3) + rng.normal(0.0, 4e-5, 600))
    t -= t[0]
    path = tmp_path / "log.csv"
    np.savetxt(path, np.column_stack((t * scale, _ring(t))), fmt=[fmt, "%.6f"],
               delimiter=",", header=f"{header},theta [rad]", comments="")
    log = read_log(path)
    assert log.time_print_unit == pytest.approx(unit, rel=1e-12)


def test_times_rebuilt_as_uniform_steps_carry_no_print_unit(tmp_path):
    """4 kHz stamped to whole milliseconds (each stamp written four times): the time is
    rebuilt as uniform steps (noted), so no stamp rounding is left to report."""
    t = np.arange(2000) / 4000.0
    path = tmp_path / "fast.csv"
    np.savetxt(path, np.column_stack((np.floor(t * 1e3), _ring(t))), fmt=["%d", "%.6f"],
               delimiter=",", header="time [ms],theta [rad]", comments="")
    log = read_log(path)
    assert any("rebuilt" in n for n in log.notes)
    assert log.time_print_unit is None


def test_numbers_never_printed_have_no_time_print_unit():
    """A DataFrame's floats were never cut to a print unit."""
    t = np.arange(500) / 1000.0
    log = read_log(pd.DataFrame({"time": t, "theta": _ring(t)}))
    assert log.time_print_unit is None
