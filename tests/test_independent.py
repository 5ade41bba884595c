"""The independent log generator (tests/independent.py) against closed forms.

Its logs are the truth for issue 16's "fits on logs hdid did not write" tests, so it is
checked here on its own, without hdid: undamped oscillator, Coulomb decrement and band,
pendulum period (small swings and the exact elliptic-integral period), log format,
quantization and unit changes.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.special import ellipk

import independent as ind


def test_undamped_linear_oscillator_matches_closed_form():
    # k1 at the output, ratio 50: k_wg = k1/N², ω = sqrt(k_wg/I); θ0 and ω0 both nonzero
    plant = ind.Plant(inertia=2e-6, ratio=50.0, k1=2000.0)
    w = math.sqrt(plant.k_wg / plant.inertia)
    theta0, omega0 = 0.1, -30.0
    t = np.linspace(0.0, 5 * 2 * math.pi / w, 400)
    theta, omega = ind.trajectory(plant, theta0, t[-1], omega0)(t)
    exact = theta0 * np.cos(w * t) + omega0 / w * np.sin(w * t)
    amplitude = math.hypot(theta0, omega0 / w)
    # DOP853 at rtol 1e-10 over five periods: 1e-8 of the amplitude is ~100× its error
    # and 1e-4 of what a wrong stiffness by 0.01 % would give (phase 5·2π·5e-5 rad).
    np.testing.assert_allclose(theta, exact, rtol=0, atol=1e-8 * amplitude)
    np.testing.assert_allclose(omega, -theta0 * w * np.sin(w * t) + omega0 * np.cos(w * t),
                               rtol=0, atol=1e-8 * amplitude * w)
    assert plant.natural_frequency_hz == pytest.approx(w / (2 * math.pi), rel=1e-14)


def test_coulomb_decrement_per_cycle_and_rest_inside_the_band():
    # Pure Coulomb (tau_s = tau_c, no viscous), linear spring: each half-swing ends
    # 2·tau_c/k closer to zero (4·tau_c/k per cycle), every half-swing lasts π/ω, and the
    # motion stops at the first reversal inside |θ| ≤ tau_c/k.
    plant = ind.Plant(inertia=7e-7, ratio=100.0, k1=940.0, tau_c=1e-3)
    k, w = plant.k_wg, math.sqrt(plant.k_wg / plant.inertia)
    theta0 = 0.157
    traj = ind.trajectory(plant, theta0, 1.0)
    turns = [th for (_, th, _) in traj.events]
    times = [t for (t, _, _) in traj.events]
    n = np.arange(1, len(turns) + 1)
    expected = (-1.0) ** n * (theta0 - n * 2 * plant.tau_c / k)
    # event location to rtol 1e-10: 1e-9 rad is 1e-6 of one decrement (0.021 rad)
    np.testing.assert_allclose(turns, expected, rtol=0, atol=1e-9)
    np.testing.assert_allclose(np.diff([0.0] + times), math.pi / w, rtol=1e-8)
    assert abs(traj.rest) <= plant.tau_c / k  # inside the band ...
    assert abs(turns[-2]) > plant.tau_c / k  # ... reached at the first reversal there
    assert traj.events[-1][2] == "stick" and all(e[2] != "stick" for e in traj.events[:-1])
    # per cycle (two half-swings): 4·tau_c/k
    full = np.abs(turns[1::2])
    np.testing.assert_allclose(-np.diff(np.r_[theta0, full]), 4 * plant.tau_c / k, rtol=1e-7)
    # stuck means stuck: constant afterwards, zero velocity
    th, om = traj(np.linspace(traj.stuck_at[0], 2.0, 50))
    assert np.all(th == traj.rest) and np.all(om == 0.0)


def test_stribeck_stick_slip_decisions_are_exact():
    # at every velocity zero: slides on only where the rest torque exceeds tau_s, sticks
    # where it does not; the log-level rest point is where it stuck
    plant = ind.gear_plant("csf8")
    traj = ind.trajectory(plant, -0.157, 0.5)
    assert len(traj.events) >= 2
    for _, th, decision in traj.events:
        F = abs(float(plant.rest_torque(th)))
        assert (F <= plant.static) == (decision == "stick")
    assert traj.events[-1][2] == "stick"


@pytest.mark.parametrize("ratio", [1.0, 50.0])
def test_pendulum_period_small_and_large_swings(ratio):
    # Frictionless pendulum on the output: small swings 2π·sqrt(I_out/mgl); any amplitude
    # A (output) exactly 4·sqrt(I_out/mgl)·K(sin²(A/2)).
    I_out, mgl = 2.5e-3, 0.1
    plant = ind.Plant(inertia=I_out / ratio**2, ratio=ratio, mgl=mgl)
    T0 = 2 * math.pi * math.sqrt(I_out / mgl)
    assert 1 / plant.natural_frequency_hz == pytest.approx(T0, rel=1e-12)
    for A, exact in ((0.01, T0 * (1 + 0.01**2 / 16)), (1.0, 4 * math.sqrt(I_out / mgl) * ellipk(math.sin(0.5) ** 2))):
        traj = ind.trajectory(plant, A * ratio, 3.2 * exact)
        t = np.linspace(0, 3.2 * exact, 20001)
        theta, _ = traj(t)
        # upward zero crossings, linearly interpolated on a grid of exact/6250: the
        # interpolation error is far below 1e-7 of a period
        i = np.nonzero((theta[:-1] < 0) & (theta[1:] >= 0))[0]
        tc = t[i] - theta[i] * (t[i + 1] - t[i]) / (theta[i + 1] - theta[i])
        period = np.diff(tc)
        # 1e-6: the small-swing series' next term (A⁴·11/3072 ≈ 4e-11) is negligible, and
        # the large swing differs from T0 by 7 %, so a wrong formula fails by far
        np.testing.assert_allclose(period, exact, rtol=1e-6)


def test_log_format_hold_quantization_and_offsets():
    log, truth = ind.paper_design("csf8", duration=0.1)
    assert list(log.columns) == ["run", "setup", "time", "theta"]
    assert list(log["run"].unique()) == ["1", "2", "3", "4"]
    step = 2 * math.pi / 4000
    assert truth["resolution"] == pytest.approx(step)
    counts = log["theta"].to_numpy() / step
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)  # on the encoder grid
    for r in truth["runs"]:
        rows = log[log["run"] == r["run"]]
        t = rows["time"].to_numpy()
        np.testing.assert_allclose(np.diff(t), 1 / 250, rtol=1e-9)
        held = rows["theta"].to_numpy()[t < r["t_release"]]
        assert len(held) == 10  # 0.04 s hold at 250 Hz
        reading = r["theta0"] + truth["offsets"][r["setup"]]
        assert np.all(np.abs(held - reading) <= step / 2 + 1e-12)
        # it sticks within the log, and the last reading is the rest point + offset
        assert r["stuck_at"] is not None
        rest = r["rest"] + truth["offsets"][r["setup"]]
        assert abs(rows["theta"].iloc[-1] - rest) <= step / 2 + 1e-12


def test_output_encoder_step_and_analog_ring_down():
    log, truth = ind.pendulum_drop(ratio=50.0, duration=0.5)
    step = 50 * 2 * math.pi / 4096  # a 4096-count output encoder, seen at the WG
    assert truth["resolution"] == pytest.approx(step)
    counts = log["theta"].to_numpy() / step
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-9)
    assert 0.5 <= truth["natural_frequency_hz"] <= 2.0
    ring, rt = ind.ring_down(cycles=2)
    assert rt["resolution"] is None and rt["encoder"] == "analog"
    for r in rt["runs"]:
        rows = ring[ring["run"] == r["run"]]
        assert r["omega0"] != 0.0
        # in motion from the first sample: the second already differs by ~ω0·dt
        d = rows["theta"].iloc[1] - rows["theta"].iloc[0]
        assert np.sign(d) == np.sign(r["omega0"]) and abs(d) > 0.5 * abs(r["omega0"]) / rt["rate"]


def test_same_log_in_other_units():
    log, truth = ind.paper_design("csf8", duration=0.1)
    milli, mt = ind.in_units(log, truth, angle=1000.0, time=1000.0, torque=1000.0)
    np.testing.assert_allclose(milli["theta"], 1000 * log["theta"], rtol=1e-15)
    np.testing.assert_allclose(milli["time"], 1000 * log["time"], rtol=1e-15)
    p, q = truth["params"], mt["params"]
    # ω_n² = k_wg/I is a 1/time² (×1e-6), tau_c/k_wg an angle (×1e3), v_s angle/time (×1)
    assert q["k1"] / q["inertia"] == pytest.approx(p["k1"] / p["inertia"] * 1e-6, rel=1e-12)
    assert q["tau_c"] / q["k1"] == pytest.approx(p["tau_c"] / p["k1"] * 1e3, rel=1e-12)
    # the same physical twist is 1000× the number: k2·d³/(k1·d) unchanged
    assert q["k2"] * 1e6 / q["k1"] == pytest.approx(p["k2"] / p["k1"], rel=1e-12)
    assert q["v_s"] == pytest.approx(p["v_s"], rel=1e-12)
    assert q["c_v"] / q["inertia"] == pytest.approx(p["c_v"] / p["inertia"] * 1e-3, rel=1e-12)
    assert mt["natural_frequency_hz"] == pytest.approx(truth["natural_frequency_hz"] / 1000)
    # the transformed plant, simulated directly in the new units, gives the same log
    plant = ind.Plant(**{k: v for k, v in q.items()})
    r = mt["runs"][0]
    rows = milli[milli["run"] == "1"]
    theta, _ = ind.trajectory(plant, r["theta0"], 100.0)(rows["time"].to_numpy() - r["t_release"])
    reading = theta + mt["offsets"]["A"]
    assert np.max(np.abs(rows["theta"].to_numpy() - reading)) <= mt["resolution"] / 2 + 1e-9


def test_torque_offset_shifts_the_centre_of_the_swing():
    # I·θ̈ = −k·θ − tau_0: a cosine about θ_eq = −tau_0/k (hdid's TorqueOffset sign)
    plant = ind.Plant(inertia=1e-4, ratio=1.0, k1=0.5, tau_0=0.01)
    w, eq = math.sqrt(0.5 / 1e-4), -0.01 / 0.5
    t = np.linspace(0.0, 3 * 2 * math.pi / w, 300)
    theta, _ = ind.trajectory(plant, 0.1, t[-1])(t)
    # same error budget as the undamped oscillator above; a wrong sign is off by 2·|eq|
    np.testing.assert_allclose(theta, eq + (0.1 - eq) * np.cos(w * t), rtol=0, atol=1e-9)
