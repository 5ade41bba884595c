"""Issue 16: the fit takes its starts, scales and thresholds from the log in hand.

Cheap checks of the preparation (no fit) and one check that the whole fit is free of
the log's units: the same physical log in rad and in mrad, or with every torque scaled,
must give the same physics with the parameters transformed exactly as their units.
The heavier "fits out of the box" scenarios from an independent generator are in
``test_real_logs_synthetic.py``.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

import hdid
from hdid._fitting._identifiability import plausibility_warnings
from hdid._simulation._prepare import prepare, turning_points

PAPER = "data/synthetic/csf8_paper.csv"


def _log(df: pd.DataFrame, **kw) -> hdid.Log:
    return hdid.read_log(df, **kw)


def _oscillation(f_hz=7.0, fs=500.0, duration=2.0, theta0=0.2, omega0=3.0, zeta=0.02,
                 noise=0.0, seed=0, offset=0.3):
    """A damped linear oscillator in closed form (independent of hdid's simulator)."""
    t = np.arange(0.0, duration, 1.0 / fs)
    w = 2 * math.pi * f_hz
    wd = w * math.sqrt(1 - zeta**2)
    a = theta0
    b = (omega0 + zeta * w * theta0) / wd
    th = np.exp(-zeta * w * t) * (a * np.cos(wd * t) + b * np.sin(wd * t))
    th = th + offset + np.random.default_rng(seed).normal(0.0, noise, t.size)
    return t, th


def test_ring_down_that_starts_in_motion_is_prepared_without_a_hold():
    # Before issue 16 this log was refused ("never moves more than one encoder step from
    # its first reading"): a hold was assumed.
    t, th = _oscillation(noise=2e-4)
    prep = prepare(_log(pd.DataFrame({"time": t, "theta": th})))
    assert prep.moving_start.tolist() == [True]
    assert prep.release_lo[0] == prep.release_hi[0] == t[0]
    # the log is cut while still swinging (amplitude ~0.03 rad at 2 s vs 2e-4 noise)
    assert prep.ends_moving.tolist() == [True]
    # analog readings: no grid, so the noise is estimated, not a 4000-count encoder
    assert prep.resolution_source == "noise" and not prep.resolution_known
    # the initial velocity guess from three samples: within the chord error of a 7 Hz
    # swing sampled at 500 Hz (ω·dt = 0.088: second-order error ~ (ω dt)²/3 ≈ 0.3 % of the
    # peak speed ω·A ≈ 9 rad/s) plus the noise's 3·2e-4/(2·dt)·sqrt(26)/... ≈ 0.5 rad/s
    assert abs(prep.omega_guess[0] - 3.0) < 0.6
    # the oscillation frequency from the turning points (≈ 12 half-periods in the log)
    assert abs(prep.frequency_hz / (7.0 * math.sqrt(1 - 0.02**2)) - 1) < 0.02


def test_hold_and_rest_found_on_a_quantized_paper_log():
    prep = prepare(hdid.read_log(PAPER))
    assert not prep.moving_start.any() and not prep.ends_moving.any()
    assert prep.resolution_source == "estimated" and prep.resolution_known
    # the shipped log's truth: k1 = 940 N m/rad, I = 7e-7 kg m², N = 100 -> 58.3 Hz; the
    # turning points of 4-sample swings at 250 Hz give it within a few percent
    assert abs(prep.frequency_hz / 58.3 - 1) < 0.1


def test_turning_points_ignore_flicker_below_the_threshold():
    x = np.array([0, 1, 0, 1, 0, 5, 9, 10, 9, 10, 6, 2, 1, 2, 1, 3, 8], dtype=float)
    assert turning_points(x, 1.5) == [7, 12]


@pytest.mark.parametrize("change, message", [
    (lambda df: df.assign(time=df["time"] * 1000.0), "sample rate"),
    (lambda df: df.assign(theta=np.degrees(df["theta"])), "degrees"),
])
def test_wrong_units_are_named(change, message):
    # time in ms reads as a 0.25 Hz log; degrees as a 9° = 0.09 rad output twist of a
    # harmonic drive whose rated twist is ~1e-3 rad. Both fitted "confidently" before.
    df = pd.read_csv(PAPER)
    log = hdid.read_log(change(df))
    prep = prepare(log)
    model = hdid.Model.default()
    warns = plausibility_warnings(prep, model, model.float_values(), float("nan"))
    assert any(message in w for w in warns), warns
    # and the log in proper units raises none
    prep0 = prepare(hdid.read_log(df))
    assert plausibility_warnings(prep0, model, model.float_values(), float("nan")) == []


def test_same_physics_in_other_units():
    """Angles in mrad (I, k1 /1e3, k2 /1e9, c_v /1e3, v_s ×1e3) and every torque ×1e3
    (I, k, tau, c_v ×1e3) give the parameters of the rad/SI fit transformed exactly.

    Every start, optimiser scale, prior centre and threshold is derived from the log in
    its own units and the scales are powers of ten, so the optimiser takes the same path
    up to rounding (measured 1e-14 relative); 1e-8 leaves room for a different
    floating-point order, while any unit-bound constant in the path (the former 0.01 rad
    offset scale, 15–400 Hz grid or 3 rad/s prior) changes the result at the percent level.
    """
    df = pd.read_csv(PAPER)
    ref = hdid.fit(df, inertia=7e-7)
    mrad = hdid.fit(df.assign(theta=df["theta"] * 1e3), inertia=7e-10)
    torque = hdid.fit(df, inertia=7e-4)
    per_mrad = {"k1": 1e-3, "k2": 1e-9, "tau_c": 1.0, "tau_s": 1.0, "v_s": 1e3, "delta": 1.0,
                "c_v": 1e-3, "inertia": 1e-3}
    for name, p in ref.parameters.items():
        for other, factor in ((mrad, per_mrad[name]),
                              (torque, 1.0 if name in ("v_s", "delta") else 1e3)):
            q = other.parameters[name]
            assert q.value == pytest.approx(p.value * factor, rel=1e-8), name
            if not p.fixed:
                assert q.std == pytest.approx(p.std * factor, rel=1e-6), name
    assert mrad.stick_band_halfwidth_rad == pytest.approx(ref.stick_band_halfwidth_rad * 1e3,
                                                          rel=1e-8)
    assert mrad.rms_residual_rad == pytest.approx(ref.rms_residual_rad * 1e3, rel=1e-8)
