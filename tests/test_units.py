"""Units in column headers (``time [ms]``, ``theta (deg)``): read as hdid's units.

The oracle is the same log written unitless in s and rad: each header unit must give the
same numbers up to float rounding (a product with a decimal factor: a few ulp).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import hdid
from hdid import LogError
from hdid.cli import main

EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"
DRIVEN = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "driven_csf8.csv"
#: relative rounding of one product by a decimal factor and its inverse
ULP = 1e-14


def _frame(time_unit, theta_unit, t_factor, th_factor):
    d = pd.read_csv(EXAMPLE)
    d["time"] *= t_factor
    d["theta"] *= th_factor
    return d.rename(columns={"time": f"time {time_unit}", "theta": f"theta {theta_unit}"})


@pytest.mark.parametrize("time_unit, theta_unit, t_factor, th_factor", [
    ("[s]", "[rad]", 1.0, 1.0),
    ("[ms]", "[mrad]", 1e3, 1e3),
    ("(s)", "(deg)", 1.0, 180.0 / math.pi),
    ("[ s ]", "[rev]", 1.0, 1.0 / (2 * math.pi)),
    ("[us]", "[µrad]", 1e6, 1e6),
])
def test_header_units_read_as_seconds_and_radians(time_unit, theta_unit, t_factor, th_factor):
    ref = hdid.read_log(EXAMPLE)
    log = hdid.read_log(_frame(time_unit, theta_unit, t_factor, th_factor))
    assert log.sample_period == pytest.approx(ref.sample_period, rel=ULP * 10)
    assert log.resolution == pytest.approx(ref.resolution, rel=1e-9)  # grid found again
    for a, b in zip(ref.runs, log.runs):
        np.testing.assert_allclose(b.theta, a.theta, rtol=ULP * 10, atol=0)
        np.testing.assert_allclose(b.time, a.time, rtol=ULP * 10, atol=1e-18)


def test_a_unitless_log_is_read_unchanged():
    ref = hdid.read_log(EXAMPLE)
    d = pd.read_csv(EXAMPLE)
    for a, b in zip(ref.runs, hdid.read_log(d.rename(columns=str.upper)).runs):
        assert np.array_equal(a.theta, b.theta) and np.array_equal(a.time, b.time)


def test_given_resolution_is_in_the_headers_unit():
    step = 2 * math.pi / 4000
    log = hdid.read_log(_frame("[s]", "[mrad]", 1.0, 1e3), resolution=step * 1e3)
    assert log.resolution == pytest.approx(step, rel=ULP * 10)
    assert log.resolution_source == "given"


def test_driven_columns_take_units():
    d = pd.read_csv(DRIVEN)
    ref = hdid.read_log(d)
    d["motor_torque"] *= 1e3
    d = d.rename(columns={"motor_torque": "motor_torque [mNm]"})
    log = hdid.read_log(d)
    for a, b in zip(ref.runs, log.runs):
        np.testing.assert_allclose(b.motor_torque, a.motor_torque, rtol=ULP * 10, atol=0)


def test_an_unknown_unit_is_a_one_line_error_naming_the_column(tmp_path):
    p = tmp_path / "furlongs.csv"
    _frame("[s]", "[furlong]", 1.0, 1.0).to_csv(p, index=False)
    with pytest.raises(LogError, match=r"theta \[furlong\].*unknown unit 'furlong'.*rad, mrad"):
        hdid.read_log(p)
    res = CliRunner().invoke(main, ["fit", str(p), "-q"])
    assert res.exit_code == 2
    assert "Traceback" not in res.output and "unknown unit 'furlong'" in res.output


# ------------------------------------------------------------- implausible units


def _problem(**kw):
    from hdid._units import implausible_units

    base = dict(sample_period=0.004, swing=0.157, ratio=100.0, band_halfwidth=0.047,
                step=2 * math.pi / 4000, geared_spring=True)
    return implausible_units(**{**base, **kw})


def test_plausible_numbers_have_no_unit_problem():
    assert _problem() is None
    # a pendulum (gravity, no gear) swinging a radian, sampled at 100 Hz
    assert _problem(sample_period=0.01, swing=1.0, ratio=1.0, band_halfwidth=0.03,
                    geared_spring=False) is None


@pytest.mark.parametrize("kw, fix", [
    # a 250 Hz log with time in ms reads as 0.25 Hz; in µs as 2.5e-4 Hz
    ({"sample_period": 4.0}, "`time [ms]`"),
    ({"sample_period": 4000.0}, "`time [us]`"),
    # the paper's ±0.157 rad in degrees: 9 "rad" at the input, 0.09 at the output
    ({"swing": 9.0, "band_halfwidth": 2.1, "step": 0.09}, "`theta [deg]`"),
    ({"swing": 157.0, "band_halfwidth": 47.0, "step": 1.571}, "`theta [mrad]`"),
    # raw counts: a whole-number step
    ({"swing": 100.0, "band_halfwidth": 30.0, "step": 1.0}, "--counts-per-rev"),
])
def test_implausible_units_name_the_fix(kw, fix):
    problem = _problem(**kw)
    assert problem is not None and problem.startswith("units:") and fix in problem
    assert "\n" not in problem
