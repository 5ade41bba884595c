"""Validation of the event-driven reference simulator against analytic solutions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hdid.reference import (
    reference_trajectory,
    simulate_reference,
    simulate_reference_dense,
    stick_band_halfwidth,
)

N = 100.0
K1 = 940.0
INERTIA = 7.0e-7
K_WG = K1 / N**2  # linear stiffness seen at the WG [Nm/rad]
OMEGA_N = math.sqrt(K_WG / INERTIA)

CSF8 = dict(k1=940.0, k2=6.5e7, tau_c=2.5e-3, tau_s=4.5e-3, v_s=5.0, delta=1.0, c_v=1.8e-5,
            inertia=7.0e-7)


# ---------------------------------------------------------------- analytic solutions


def damped_oscillator(t, theta0, t_release, k, c, inertia):
    """Underdamped linear oscillator released from rest."""
    wn = math.sqrt(k / inertia)
    zeta = c / (2.0 * math.sqrt(k * inertia))
    wd = wn * math.sqrt(1.0 - zeta**2)
    tau = np.clip(np.asarray(t, dtype=float) - t_release, 0.0, None)
    envelope = theta0 * np.exp(-zeta * wn * tau)
    return envelope * (np.cos(wd * tau) + zeta * wn / wd * np.sin(wd * tau))


def coulomb_oscillator(t, theta0, t_release, k, tau_c, inertia):
    """Piecewise-analytic linear spring + Coulomb friction released from rest.

    Returns the trajectory at ``t`` and the list of (time, angle) of the successive rest
    instants (extrema) after the release.
    """
    wn = math.sqrt(k / inertia)
    half = math.pi / wn
    band = tau_c / k
    t = np.asarray(t, dtype=float)
    out = np.full(t.shape, float(theta0))
    extrema = []
    t0, th0 = float(t_release), float(theta0)
    while abs(th0) > band:
        s = -math.copysign(1.0, th0)  # sliding direction: towards the spring's zero
        c = -s * tau_c / k  # centre of this half-cycle
        m = (t > t0) & (t <= t0 + half)
        out[m] = c + (th0 - c) * np.cos(wn * (t[m] - t0))
        t0, th0 = t0 + half, 2.0 * c - th0
        out[t > t0] = th0
        extrema.append((t0, th0))
    return out, extrema


# ---------------------------------------------------------------- (a) viscous only


def test_linear_viscous_matches_damped_oscillator():
    c_v = 0.05 * 2.0 * math.sqrt(K_WG * INERTIA)  # 5 % of critical
    t_rel = 0.0123
    t = np.linspace(0.0, 0.3, 6001)
    theta = simulate_reference(t, theta0=0.157, t_release=t_rel, k1=K1, k2=0.0, tau_c=0.0,
                               tau_s=0.0, v_s=5.0, delta=1.0, c_v=c_v, inertia=INERTIA)
    exact = damped_oscillator(t, 0.157, t_rel, K_WG, c_v, INERTIA)
    assert np.max(np.abs(theta - exact)) < 1e-9
    assert np.all(theta[t <= t_rel] == 0.157)


def test_viscous_only_reverses_at_every_extremum():
    c_v = 0.1 * 2.0 * math.sqrt(K_WG * INERTIA)
    traj = reference_trajectory(0.1, theta0=-0.1, t_release=0.0, k1=K1, k2=0.0, tau_c=0.0,
                                tau_s=0.0, v_s=1.0, delta=1.0, c_v=c_v, inertia=INERTIA)
    zeta = 0.1
    wd = OMEGA_N * math.sqrt(1 - zeta**2)
    n_expected = int(0.1 // (math.pi / wd))
    assert not traj.stuck
    assert traj.n_events == n_expected
    np.testing.assert_allclose(np.diff(traj.reversal_times), math.pi / wd, rtol=1e-9)
    signs = np.sign(traj.reversal_angles)
    assert np.all(signs[1:] == -signs[:-1])


# ---------------------------------------------------------------- (b) Coulomb


@pytest.mark.parametrize("theta0", [0.157, -0.157, 0.0931])
def test_linear_coulomb_piecewise_analytic(theta0):
    tau_c = 1.0e-3
    t_rel = 0.0077
    t = np.linspace(0.0, 0.2, 8001)
    traj = reference_trajectory(0.2, theta0=theta0, t_release=t_rel, k1=K1, k2=0.0,
                                tau_c=tau_c, tau_s=tau_c, v_s=5.0, delta=1.0, c_v=0.0,
                                inertia=INERTIA)
    theta, omega = traj.evaluate(t)
    exact, extrema = coulomb_oscillator(t, theta0, t_rel, K_WG, tau_c, INERTIA)
    assert np.max(np.abs(theta - exact)) < 1e-9

    # successive extrema fall by exactly 2·tau_c/k, each half-cycle lasts pi/omega_n
    amps = np.abs(np.r_[theta0, traj.reversal_angles])
    np.testing.assert_allclose(-np.diff(amps), 2 * tau_c / K_WG, rtol=1e-8)
    np.testing.assert_allclose(np.diff(np.r_[t_rel, traj.reversal_times]), math.pi / OMEGA_N,
                               rtol=1e-9)
    # alternate sides, stop at the first extremum inside the band |theta| <= tau_c/k
    band = tau_c / K_WG
    assert np.all(np.abs(traj.reversal_angles[:-1]) > band)
    assert abs(traj.theta_rest) <= band
    assert traj.stuck and traj.n_events == len(extrema)
    np.testing.assert_allclose(traj.reversal_angles, [e[1] for e in extrema], atol=1e-10)
    assert np.all(omega[t >= traj.t_stick] == 0.0)


# ---------------------------------------------------------------- (c) sticking


def test_stuck_state_holds_exactly_for_one_second():
    traj = reference_trajectory(0.2, theta0=0.157, t_release=0.01, **CSF8)
    assert traj.stuck
    t = traj.t_stick + np.linspace(0.0, 1.0, 2001)
    theta = simulate_reference(t, theta0=0.157, t_release=0.01, **CSF8)
    assert np.all(theta == traj.theta_rest)
    tt, th, om = simulate_reference_dense(traj.t_stick + 1.0, theta0=0.157, t_release=0.01,
                                          dt=1e-4, **CSF8)
    late = tt >= traj.t_stick
    assert np.all(th[late] == traj.theta_rest) and np.all(om[late] == 0.0)
    # the rest point lies inside the stick band, and the previous extremum outside it
    band = stick_band_halfwidth(CSF8["k1"], CSF8["k2"], CSF8["tau_s"])
    assert abs(traj.theta_rest) <= band
    assert np.all(np.abs(traj.reversal_angles[:-1]) > band)


def test_release_inside_band_never_moves():
    band = stick_band_halfwidth(CSF8["k1"], CSF8["k2"], CSF8["tau_s"])
    t = np.linspace(0.0, 1.0, 251)
    theta0 = 0.999 * band
    theta = simulate_reference(t, theta0=theta0, t_release=0.04, **CSF8)
    assert np.all(theta == theta0)
    theta = simulate_reference(t, theta0=-1.001 * band, t_release=0.04, **CSF8)
    assert theta[-1] != -1.001 * band


def test_symmetry_of_plus_minus_releases():
    t = np.arange(125) / 250.0
    plus = simulate_reference(t, theta0=0.157, t_release=0.0413, **CSF8)
    minus = simulate_reference(t, theta0=-0.157, t_release=0.0413, **CSF8)
    np.testing.assert_allclose(plus, -minus, atol=1e-12)
    gap = plus[-1] - minus[-1]
    assert 0.06 < gap < 0.08  # the paper's ~0.07 rad band between rest points


# ---------------------------------------------------------------- (d) release timing


def test_release_between_samples():
    fs = 250.0
    t = np.arange(125) / fs
    t_rel = 0.0413  # between samples 10 (0.040) and 11 (0.044)
    theta = simulate_reference(t, theta0=0.157, t_release=t_rel, **CSF8)
    before = t <= t_rel
    assert np.all(theta[before] == 0.157)
    assert theta[11] < 0.157 - 1e-6
    # time invariance: same trajectory as a release at 0 evaluated at t - t_rel
    shifted = simulate_reference(t[~before] - t_rel, theta0=0.157, t_release=0.0, **CSF8)
    np.testing.assert_allclose(theta[~before], shifted, atol=1e-9)


def test_release_exactly_on_a_sample_and_after_the_last_sample():
    t = np.arange(50) / 250.0
    theta = simulate_reference(t, theta0=0.1, t_release=t[10], **CSF8)
    assert np.all(theta[:11] == 0.1) and theta[11] != 0.1
    theta = simulate_reference(t, theta0=0.1, t_release=1.0, **CSF8)
    assert np.all(theta == 0.1)


# ---------------------------------------------------------------- extras


def test_constant_extra_torque_equals_shifted_spring_zero():
    tau_e = 1.2e-3
    shift = tau_e / K_WG  # linear spring: equilibrium moves to +shift
    p = dict(k1=K1, k2=0.0, tau_c=2e-3, tau_s=3e-3, v_s=4.0, delta=1.5, c_v=1e-5,
             inertia=INERTIA)
    t = np.linspace(0.0, 0.15, 1501)
    with_extra = simulate_reference(t, theta0=0.12, t_release=0.01,
                                    extra_torque=lambda th, w: tau_e, **p)
    shifted = simulate_reference(t, theta0=0.12 - shift, t_release=0.01, **p) + shift
    np.testing.assert_allclose(with_extra, shifted, atol=1e-9)


@pytest.mark.parametrize("delta", [0.5, 1.0, 2.0])
def test_stribeck_exponents_converge(delta):
    p = dict(CSF8, delta=delta)
    t = np.linspace(0.0, 0.1, 1001)
    fine = simulate_reference(t, theta0=0.157, t_release=0.003, **p)
    coarse = simulate_reference(t, theta0=0.157, t_release=0.003, rtol=1e-8, atol=1e-11, **p)
    assert np.all(np.isfinite(fine))
    assert np.max(np.abs(fine - coarse)) < 1e-6


def test_zeno_guard_sticks_after_max_events():
    traj = reference_trajectory(1.0, theta0=0.1, t_release=0.0, k1=K1, k2=0.0, tau_c=0.0,
                                tau_s=0.0, v_s=1.0, delta=1.0, c_v=1e-6, inertia=INERTIA,
                                max_events=3)
    assert traj.stuck and traj.events[-1][2] == "zeno-stick"
    assert traj.n_events == 4


def test_stick_band_halfwidth():
    # linear: tau_s·N²/k1
    assert stick_band_halfwidth(940.0, 0.0, 4.5e-3) == pytest.approx(4.5e-3 * 1e4 / 940.0,
                                                                     rel=1e-14)
    for k1, k2, ts in [(940.0, 6.5e7, 4.5e-3), (2700.0, 1e8, 6e-3), (0.0, 6.5e7, 4e-3),
                       (940.0, -1e7, 2e-3)]:
        tb = stick_band_halfwidth(k1, k2, ts)
        d = tb / N
        assert tb > 0
        assert (k1 * d + k2 * d**3) / N == pytest.approx(ts, rel=1e-12)
    assert stick_band_halfwidth(940.0, 6.5e7, 0.0) == 0.0
    assert stick_band_halfwidth(940.0, -1e9, 1.0) == math.inf
