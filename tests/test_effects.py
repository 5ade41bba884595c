"""Library effects against independent numpy implementations run in the reference simulator.

Each effect of ``hdid.effects`` is written a second time, from its equation, in
``hdid.reference.logs.HIDDEN`` for the event-driven scipy reference. The JAX simulator with
the effect must reproduce the reference trajectory: this checks both codes at once.
"""

from __future__ import annotations

import numpy as np
import pytest

import hdid
from hdid.effects import AbstractEffect, library
from hdid.reference import logs, simulate_reference

TRUTH = {k: v for k, v in logs.TRUTH_CSF8.items() if k not in ("ratio", "inertia")}
INERTIA = logs.TRUTH_CSF8["inertia"]
STEP = 2 * np.pi / 4000
T = np.arange(0.0, 0.5, 0.004)
IN_LIBRARY = [k for k, v in logs.HIDDEN.items() if v["library"] is not None]


@pytest.mark.parametrize("name", IN_LIBRARY)
def test_effect_matches_reference_implementation(name):
    entry = logs.HIDDEN[name]
    effect = library({**TRUTH, **entry["truth"]})[entry["library"]]
    model = hdid.Model.default(inertia=INERTIA, **TRUTH).with_effect(effect)
    for theta0 in (0.157, -0.157, 0.08):
        jax_theta = np.asarray(hdid.simulate(model, T, theta0, 0.0013))
        ref = simulate_reference(T, theta0=theta0, t_release=0.0013, inertia=INERTIA, **TRUTH,
                                 **logs.reference_kwargs(name, TRUTH))
        base = simulate_reference(T, theta0=theta0, t_release=0.0013, inertia=INERTIA, **TRUTH)
        # The base scheme is within 0.042 of a count of the reference (simulator_schemes
        # benchmark); the effects add kinks (dead zone, segment corners) and state, so
        # allow 0.1 count: ten times below what a fit can resolve.
        assert np.max(np.abs(jax_theta - ref)) < 0.1 * STEP, name
        # ... and the effect is far from negligible, so the comparison means something.
        assert np.max(np.abs(ref - base)) > 3 * STEP, name


def test_library_effects_are_final_components_with_documented_parameters():
    lib = library(hdid.Model.default().float_values())
    for key, effect in lib.items():
        assert isinstance(effect, AbstractEffect)
        assert "Residual mark" in type(effect).__doc__, key
        for p in effect.parameters:
            assert p.unit and p.doc, (key, p.name)


def test_dahl_state_is_exact_for_monotone_motion():
    # the closed form from an anchor, stepped in pieces, equals one step (a semigroup)
    e = library({"f_h": 1e-3, "sigma_h": 0.1})["hysteresis"]
    s0 = e.init_state(np.float64(0.157))
    one = e.update_state(s0, 0.157, 0.05)
    mid = e.update_state(e.update_state(s0, 0.157, 0.1), 0.1, 0.05)
    np.testing.assert_allclose(np.asarray(one[1]), np.asarray(mid[1]), rtol=1e-12)
    # saturates at −f_h after a long move down
    far = e.update_state(s0, 0.157, -10.0)
    assert float(far[1]) == pytest.approx(-1e-3, rel=1e-9)


def test_asymmetric_friction_shifts_the_stick_band():
    base = hdid.Model.default()
    lib = library({**base.float_values(), "asym": 0.3})
    lo, hi = (float(x) for x in base.with_effect(lib["asymmetric_friction"]).stick_band())
    lo0, hi0 = (float(x) for x in base.stick_band())
    # net-torque band [−0.7·tau_s, 1.3·tau_s]: the band moves towards −θ (spring torque
    # −k·θ balances +1.3·tau_s at θ < 0) and keeps its width to first order in k
    assert lo < lo0 and hi < hi0
    assert (hi - lo) == pytest.approx(hi0 - lo0, rel=0.05)


# -- gravity and asymmetric viscous friction (issue 16): independent numpy/scipy oracles --

def _motion(theta, omega, direction, ratio):
    from hdid.effects import Motion

    f = lambda x: np.asarray(x, dtype=float)  # noqa: E731
    return Motion(theta=f(theta), omega=f(omega), direction=f(direction), ratio=ratio)


def _scales(**kw):
    base = dict(ratio=50.0, inertia=1e-6, k_wg=4e-5, amplitude=30.0, speed=200.0, torque=1e-4)
    return hdid.effects.Scales(**{**base, **kw})


def test_gravity_torque_and_start_against_numpy():
    rng = np.random.default_rng(16)
    for ratio in (1.0, 50.0, 100.0):
        mgl = 0.3
        e = library({"mgl": mgl})["gravity"]
        assert e.name == "gravity" and type(e).__name__ == "Gravity"
        for theta, omega, s in zip(rng.uniform(-3, 3, 20) * ratio, rng.normal(0, 5, 20),
                                   rng.choice([-1.0, 0.0, 1.0], 20)):
            got = float(e.torque(_motion(theta, omega, s, ratio), None))
            # output torque −mgl·sin(θ/N), reflected to the WG by 1/N; nothing else
            assert got == pytest.approx(-mgl * np.sin(theta / ratio) / ratio, rel=1e-13, abs=1e-300)
        assert float(e.holding_torque(_motion(0.1, 0.0, 0.0, ratio), None)) == 0.0
    (p,) = type(e).parameters
    s = _scales()
    # small swings: the pendulum's output stiffness is mgl, so it starts at k_wg·N²
    assert p.start(s) == pytest.approx(s.k_wg * s.ratio**2) and p.transform == "log"


def test_absolute_gravity_torque_against_numpy():
    # A driven log's angles have no zero at the hanging position: the driven fit's gravity
    # is −(mgl/N)·sin(θ/N − theta_g) (the published G(θ) = A·sin(θ − θ₀) of a robot joint,
    # as a torque on the drive); at theta_g = 0 it is the free-motion Gravity exactly.
    from hdid.effects.gravity import AbsoluteGravity, Gravity

    rng = np.random.default_rng(17)
    for ratio in (1.0, 100.0):
        for mgl, theta_g in ((111.5, 1.563), (3.1, -2.9), (0.3, 0.0)):
            e = AbsoluteGravity(mgl=mgl, theta_g=theta_g)
            plain = Gravity(mgl=mgl)
            for theta, omega in zip(rng.uniform(-4, 4, 10) * ratio, rng.normal(0, 5, 10)):
                m = _motion(theta, omega, 0.0, ratio)
                want = -mgl * np.sin(theta / ratio - theta_g) / ratio
                assert float(e.torque(m, None)) == pytest.approx(want, rel=1e-12, abs=1e-14)
                if theta_g == 0.0:
                    assert float(e.torque(m, None)) == float(plain.torque(m, None))
    assert AbsoluteGravity.of(Gravity(mgl=2.0), 0.5) == AbsoluteGravity(mgl=2.0, theta_g=0.5)
    assert [p.name for p in AbsoluteGravity.parameters] == ["mgl", "theta_g"]


@pytest.mark.parametrize("ratio", [1.0, 50.0])
def test_gravity_pendulum_against_the_independent_simulator(ratio):
    # A pendulum with Stribeck friction, no spring, simulated by hdid and by the
    # event-driven scipy code of tests/independent.py (which shares no code with hdid).
    import independent as ind

    I_out, mgl = 2.5e-3, 0.1
    plant = ind.Plant(inertia=I_out / ratio**2, ratio=ratio, mgl=mgl, tau_c=0.04 * mgl / ratio,
                      tau_s=0.07 * mgl / ratio, v_s=0.05 * ratio, delta=1.0,
                      c_v=0.002 * mgl / ratio**2)
    effects = (library({"mgl": mgl})["gravity"],
               library({"tau_c": plant.tau_c, "tau_s": plant.tau_s, "v_s": plant.v_s,
                        "delta": 1.0})["stribeck"],
               library({"c_v": plant.c_v})["viscous"])
    model = hdid.Model(effects=effects, inertia=plant.inertia, ratio=ratio)
    t = np.arange(0.0, 5.0, 0.01)  # 100 Hz, ~5 swings of 1.0 Hz, then stuck
    theta0 = 0.6 * ratio
    ref = ind.trajectory(plant, theta0, 6.0)
    theta_ref, _ = ref(t - 0.0037)
    theta = np.asarray(hdid.simulate(model, t, theta0, 0.0037))
    assert ref.stuck_at is not None and ref.stuck_at[0] < 4.5  # sticks inside the log
    step = ratio * 2 * np.pi / 4096  # a 4096-count output encoder
    # RK4 with 0.5 ms substeps on a 1 Hz swing plus split steps at the reversals: far
    # below a tenth of a count; without gravity's 1/N or with sin→linear it is off by
    # many counts (a 0.6 rad swing: sin is 6 % below linear)
    assert np.max(np.abs(theta - theta_ref)) < 0.1 * step
    # ... and its rest point is off the spring-free zero, a real stick
    assert abs(theta[-1]) > 3 * step


def test_gravity_small_swing_period_in_hdid():
    # 2π·sqrt(I_out/mgl) for a 0.01 rad (output) frictionless swing, through hdid.simulate
    I_out, mgl, ratio = 2.5e-3, 0.1, 50.0
    model = hdid.Model(effects=(library({"mgl": mgl})["gravity"],), inertia=I_out / ratio**2,
                       ratio=ratio)
    T0 = 2 * np.pi * np.sqrt(I_out / mgl)
    t = np.linspace(0.0, 3.3 * T0, 6601)
    theta = np.asarray(hdid.simulate(model, t, 0.01 * ratio, 0.0))
    i = np.nonzero((theta[:-1] < 0) & (theta[1:] >= 0))[0]
    tc = t[i] - theta[i] * (t[i + 1] - t[i]) / (theta[i + 1] - theta[i])
    # amplitude correction A²/16 = 6e-6; linear interpolation on T0/2000 and RK4 keep
    # the error below 1e-6 relative, a stiffness error of 0.1 % would show 5e-4
    np.testing.assert_allclose(np.diff(tc), T0 * (1 + 0.01**2 / 16), rtol=2e-6)


def test_asymmetric_viscous_torque_and_starts_against_numpy():
    e = library({"c_vp": 3e-5, "c_vn": 1e-5})["asymmetric_viscous"]
    assert type(e).__name__ == "AsymmetricViscousFriction" and e.name == "viscous"
    for omega, s in ((2.0, 1.0), (0.3, 1.0), (-2.0, -1.0), (-0.7, -1.0)):
        expected = -(3e-5 if s > 0 else 1e-5) * omega
        assert float(e.torque(_motion(0.1, omega, s, 100.0), None)) == pytest.approx(expected, rel=1e-13)
    assert float(e.torque(_motion(0.1, 0.0, 0.0, 100.0), None)) == 0.0  # zero at rest
    assert float(e.holding_torque(_motion(0.1, 0.0, 0.0, 100.0), None)) == 0.0
    # symmetric coefficients: the library's ViscousFriction exactly
    sym = library({"c_vp": 2e-5, "c_vn": 2e-5})["asymmetric_viscous"]
    v = library({"c_v": 2e-5})["viscous"]
    for omega, s in ((1.5, 1.0), (-1.5, -1.0)):
        m = _motion(0.0, omega, s, 100.0)
        assert float(sym.torque(m, None)) == pytest.approx(float(v.torque(m, None)), rel=1e-14)
    sc = _scales()
    for p in type(e).parameters:
        assert p.start(sc) == pytest.approx(0.05 * 2 * np.sqrt(sc.k_wg * sc.inertia))


def test_asymmetric_viscous_half_swing_decay_in_hdid():
    # Linear spring + direction-dependent viscous friction only: a half-swing in
    # direction s (from one turning point to the next) ends at exp(−π·ζ_s/sqrt(1−ζ_s²))
    # of its starting amplitude, ζ_s = c_vs/(2·sqrt(k·I)) (the damped oscillator's
    # closed form, applied to each half with its own coefficient).
    k1, ratio, inertia = 940.0, 100.0, 7e-7
    k = k1 / ratio**2
    c_crit = 2 * np.sqrt(k * inertia)
    zp, zn = 0.08, 0.02
    model = hdid.Model(effects=(library({"k1": k1})["linear_stiffness"],
                                library({"c_vp": zp * c_crit, "c_vn": zn * c_crit})["asymmetric_viscous"]),
                       inertia=inertia, ratio=ratio)
    t = np.arange(0.0, 0.06, 1e-5)  # ~3.5 periods of 58 Hz, fine enough to find the peaks
    theta = np.asarray(hdid.simulate(model, t, -0.157, 0.0))
    peaks = [i for i in range(1, len(t) - 1)
             if abs(theta[i]) >= abs(theta[i - 1]) and abs(theta[i]) > abs(theta[i + 1])]
    amps = np.r_[0.157, np.abs(theta[peaks])]
    ratios = amps[1:] / amps[:-1]
    # from −0.157 the first half-swing goes in +θ (c_vp), then −θ (c_vn), alternating
    dec = lambda z: np.exp(-np.pi * z / np.sqrt(1 - z**2))  # noqa: E731
    expected = np.array([dec(zp) if j % 2 == 0 else dec(zn) for j in range(len(ratios))])
    assert len(ratios) >= 5
    # peaks located on a 10 µs grid (at most (ω·dt/2)²/2 ≈ 2e-6 relative low) and RK4: 1e-4;
    # the two factors differ by 17 %, and a symmetric mean c_v would be 8 % off each
    np.testing.assert_allclose(ratios, expected, rtol=1e-4)


def test_coulomb_is_stribeck_at_equal_levels_and_decays_linearly_in_hdid():
    # Stribeck with tau_s = tau_c is Coulomb friction for any v_s, delta (torque and hold)
    c = library({"tau_c": 3e-3})["coulomb"]
    assert type(c).__name__ == "CoulombFriction" and c.name == "stribeck"
    s = hdid.StribeckFriction(tau_c=3e-3, tau_s=3e-3, v_s=0.7, delta=1.6)
    for omega, d in ((2.0, 1.0), (0.01, 1.0), (-5.0, -1.0)):
        m = _motion(0.1, omega, d, 100.0)
        assert float(c.torque(m, None)) == pytest.approx(float(s.torque(m, None)), rel=1e-14)
    rest = _motion(0.1, 0.0, 0.0, 100.0)
    assert float(c.holding_torque(rest, None)) == float(s.holding_torque(rest, None))
    # Linear spring k + Coulomb friction (the classical closed form): every half-swing
    # loses exactly 2·tau_c/k of amplitude at the undamped period; the motion stops at
    # the first turning point inside the stick band |θ| ≤ tau_c/k.
    k1, ratio, inertia, tau_c = 940.0, 100.0, 7e-7, 2e-3
    k = k1 / ratio**2
    model = hdid.Model(effects=(library({"k1": k1})["linear_stiffness"],
                                library({"tau_c": tau_c})["coulomb"]),
                       inertia=inertia, ratio=ratio)
    t = np.arange(0.0, 0.08, 1e-5)
    theta = np.asarray(hdid.simulate(model, t, 0.157, 0.0))
    peaks = [i for i in range(1, len(t) - 1)
             if abs(theta[i]) >= abs(theta[i - 1]) and abs(theta[i]) > abs(theta[i + 1])]
    amps = np.abs(theta[peaks])
    n = np.arange(1, len(amps) + 1)
    expected = 0.157 - 2 * n * tau_c / k
    assert len(amps) >= 3
    # the peak sits on a 10 µs grid: (ω·dt)²/2 ≈ 6e-6 of the amplitude, RK4 far below;
    # a 10 % error in tau_c would move the last peak by 0.004 rad
    np.testing.assert_allclose(amps, expected, rtol=0, atol=2e-5 * 0.157)
    # the last moving peak lies outside the band, so the next turning point is the rest
    assert expected[-1] > tau_c / k
    rest = abs(theta[-1])
    assert rest <= tau_c / k
    assert abs(rest - abs(0.157 - 2 * (len(amps) + 1) * tau_c / k)) < 2e-5 * 0.157
    assert np.ptp(theta[-200:]) == 0.0  # stuck, not creeping


def test_gravity_friction_torque_and_candidate_against_numpy():
    from hdid.effects.gravity_friction import GravityLoadFriction

    rng = np.random.default_rng(28)
    for ratio in (1.0, 50.0):
        e = library({"c_g": 0.07})["gravity_friction"]
        assert isinstance(e, GravityLoadFriction) and e.name == "gravity_friction"
        for theta, omega, s in zip(rng.uniform(-3, 3, 20) * ratio, rng.normal(0, 5, 20),
                                   rng.choice([-1.0, 0.0, 1.0], 20)):
            m = _motion(theta, omega, s, ratio)
            # sliding: −s·c_g·|sin(θ/N)|/N, opposing the motion; at rest none, and it holds
            # the same amount (a dry friction whose level follows the gravity torque)
            want = 0.07 * abs(np.sin(theta / ratio)) / ratio
            assert float(e.torque(m, None)) == pytest.approx(-s * want, rel=1e-13, abs=1e-300)
            assert float(e.holding_torque(m, None)) == pytest.approx(want, rel=1e-13)
    # its start follows the pendulum's m·g·l (a tenth), never a catalog number
    assert float(library({"mgl": 2.0})["gravity_friction"].c_g) == pytest.approx(0.2)
    # diagnose tries it only on a model that holds a pendulum
    cand = [c for c in hdid.effects._candidate.candidates(hdid.effects.registry())
            if c.key == "gravity_friction"][0]
    pendulum = hdid.Model.default(inertia=1e-3, ratio=1.0).without("stiffness").with_effect(
        library({"mgl": 1.0})["gravity"])
    assert cand.applies(pendulum) and not cand.applies(hdid.Model.default())
    assert not cand.applies(pendulum.with_effect(e))


@pytest.mark.parametrize("ratio", [1.0, 50.0])
def test_gravity_friction_half_swings_in_hdid_against_the_energy_balance(ratio):
    # A pendulum with Coulomb friction tau and gravity-load friction c_g only: from a turning
    # point a to the next, b, on the other side of the hanging angle, the work of friction
    # equals the potential energy lost (output angles):
    #   mgl·(cos b − cos a) = tau·|b − a| + c_g·((1 − cos a) + (1 − cos b))
    # (∫|sin x| dx across zero). Solved for b by scipy's brentq, swing after swing, and
    # compared with the turning points hdid.simulate finds.
    from scipy.optimize import brentq

    mgl, I_out, tau, c_g = 1.5, 0.05, 0.02, 0.25
    model = hdid.Model(effects=(library({"mgl": mgl})["gravity"],
                                library({"tau_c": tau / ratio})["coulomb"],
                                library({"c_g": c_g})["gravity_friction"]),
                       inertia=I_out / ratio**2, ratio=ratio)
    t = np.arange(0.0, 3.0, 2e-4)  # ~3 half-swings of a 0.87 Hz pendulum
    x = np.asarray(hdid.simulate(model, t, -1.3 * ratio, 0.0)) / ratio
    peaks = [i for i in range(1, len(t) - 1) if (x[i] - x[i - 1]) * (x[i + 1] - x[i]) < 0
             and abs(x[i + 1] - x[i - 1]) > 0]
    got = np.abs(x[peaks])
    a, want = -1.3, []
    for _ in range(len(got)):
        # |b − a| = |a| + |b|: the swing crosses the hanging angle
        f = lambda B: (mgl * (np.cos(B) - np.cos(a)) - tau * (abs(a) + B)  # noqa: E731
                       - c_g * (2 - np.cos(a) - np.cos(B)))
        b = brentq(f, 1e-9, abs(a))
        want.append(b)
        a = b
    assert len(got) >= 3
    # turning points on a 0.2 ms grid: at most θ̈·dt²/8 ≈ 1e-7 rad low; RK4 far below. Without
    # c_g the first turning point would be 0.16 rad farther out (1.30 → 1.13 instead of 0.97)
    np.testing.assert_allclose(got, want, rtol=0, atol=2e-6)


def test_back_emf_torque_against_numpy_and_a_coasting_flywheel_in_hdid():
    rng = np.random.default_rng(29)
    e = library({"c_e": 0.12, "w_e": 4.0})["back_emf"]
    assert type(e).__name__ == "BackEmfBraking" and e.name == "back_emf"
    for theta, omega, s in zip(rng.uniform(-3, 3, 30), rng.normal(0, 6, 30),
                               rng.choice([-1.0, 0.0, 1.0], 30)):
        got = float(e.torque(_motion(theta, omega, s, 1.0), None))
        # a brake with a dead zone: nothing below 4 rad/s, 0.12 N m per rad/s above it
        want = -np.sign(omega) * 0.12 * max(abs(omega) - 4.0, 0.0)
        assert got == pytest.approx(want, rel=1e-13, abs=1e-300)
        assert float(e.holding_torque(_motion(theta, 0.0, 0.0, 1.0), None)) == 0.0
    # A flywheel (no spring, no friction) let go at omega0 > w_e: I·ω̇ = −c_e·(ω − w_e), so
    #   ω = w_e + (ω0 − w_e)·exp(−t/τ), θ = w_e·t + (ω0 − w_e)·τ·(1 − exp(−t/τ)), τ = I/c_e,
    # and once slower than w_e nothing brakes it (ω never falls below w_e)
    inertia, omega0 = 0.03, 9.0
    model = hdid.Model(effects=(e,), inertia=inertia, ratio=1.0)
    t = np.linspace(0.0, 2.0, 401)
    theta = np.asarray(hdid.simulate(model, t, 0.0, 0.0, omega0=omega0))
    tau = inertia / 0.12
    want = 4.0 * t + (omega0 - 4.0) * tau * (1 - np.exp(-t / tau))
    # RK4 with 0.5 ms substeps on a 0.25 s time constant: (h/τ)^4 ≈ 2e-11 relative per step
    np.testing.assert_allclose(theta, want, rtol=0, atol=1e-8)
    cand = [c for c in hdid.effects._candidate.candidates(hdid.effects.registry())
            if c.key == "back_emf"][0]
    assert not cand.applies(hdid.Model.default())  # a drop's candidate: a model with gravity


# -- the reading's age (a measurement-side component) ---------------------------------------
AGE_I, AGE_K, AGE_C = 1e-3, 0.4, 4e-4        # kg m², N m/rad, N m s/rad: 20 rad/s, ζ = 0.01
AGE_STEP = 2 * np.pi / 4096                  # a 12-bit encoder [rad]


def _damped(t, theta0):
    """Closed-form free decay of ``I·θ̈ = −k·θ − c·θ̇`` from rest at ``theta0`` (t ≥ 0)."""
    wn = np.sqrt(AGE_K / AGE_I)
    z = AGE_C / (2 * np.sqrt(AGE_K * AGE_I))
    wd = wn * np.sqrt(1 - z**2)
    t = np.maximum(t, 0.0)
    return theta0 * np.exp(-z * wn * t) * (np.cos(wd * t) + z * wn / wd * np.sin(wd * t))


def _held_log(period, phases, seed=3):
    """Two runs polled at ~100 Hz (jittered timestamps) from a device that samples every
    ``period`` s and returns its last sample: numpy's ``(t − φ) mod P`` for the age."""
    import pandas as pd

    rng = np.random.default_rng(seed)
    rows = []
    for r, (phi, theta0) in enumerate(zip(phases, (0.5, -0.4))):
        t = np.arange(0.0, 2.0, 0.01) + rng.normal(0, 4e-4, 200)
        t[0] = 0.0
        sampled = t - np.mod(t - phi, period)
        theta = np.where(sampled < 0.2, theta0, _damped(sampled - 0.2, theta0))
        rows.append(pd.DataFrame({"time": t, "theta": np.round(theta / AGE_STEP) * AGE_STEP,
                                  "run": f"r{r}"}))
    return pd.concat(rows, ignore_index=True)


@pytest.fixture(scope="module")
def aged_fits():
    from hdid.effects import LinearStiffness, ReadingAge, ViscousFriction

    period, phases = 0.007, (0.0031, 0.0007)
    log = _held_log(period, phases)
    model = hdid.Model(effects=(LinearStiffness(k1=AGE_K), ViscousFriction(c_v=AGE_C)),
                       inertia=AGE_I, ratio=1.0)
    fix = ["k1", "c_v"]
    plain = hdid.fit(log, model, fix=fix, n_starts=2)
    aged = hdid.fit(log, model.with_effect(ReadingAge(sample_period=period,
                                                      phases=np.array(phases))),
                    fix=fix, n_starts=2)
    return plain, aged, period, phases


def test_reading_age_prediction_against_numpy(aged_fits):
    _, aged, period, phases = aged_fits
    prob = aged.problem
    _, t_release, theta0_enc, offset = prob.unpack_np(aged.u)
    pred = np.asarray(prob.predict(aged.u))
    times = np.asarray(prob.times)
    for r, phi in enumerate(phases):
        n = aged.runs[r].n_samples
        t = times[r, :n]
        held = t - np.mod(t - phi, period)                    # the oracle's sampled instants
        th0 = theta0_enc[r] - offset[prob.setup_index[r]]
        oracle = offset[prob.setup_index[r]] + np.where(
            held < t_release[r], th0, _damped(held - t_release[r], th0))
        # as for the torque effects above: within 0.1 count of the exact solution (the fit's
        # RK4 substeps accumulate ~0.02 count over 2 s here); a reading taken at its
        # timestamp instead would be off by ω·a, up to 70 mrad = 45 counts
        assert np.max(np.abs(pred[r, :n] - oracle)) < 0.1 * AGE_STEP
    # the per-run Jacobian path (_runs_predict) and the plain path agree
    np.testing.assert_allclose(np.asarray(prob._runs_residuals(prob._local(aged.u))).ravel(),
                               np.asarray(prob.data_residuals(aged.u)), atol=1e-9)


def test_reading_age_explains_a_sample_and_hold_log(aged_fits):
    plain, aged, period, _ = aged_fits
    floor = aged.quantization_floor_rad
    # the exact model leaves the rounding (≤ 1.0× the floor, measured 0.4–1.0 on exact
    # models) plus the fitted release's slack; without the age the residual is ω·a with a
    # of sd P/√12 = 2 ms at up to 10 rad/s: about 20 mrad, many times the 0.44 mrad floor
    assert aged.rms_residual_rad < 1.5 * floor
    assert plain.rms_residual_rad > 5 * floor


def test_reading_age_scan_finds_the_clock(aged_fits):
    from hdid.effects.reading_age import ReadingAge

    plain, _, period, phases = aged_fits
    found = ReadingAge.from_fit(plain)
    # the scan's frequency grid keeps the phase drift over the motion below P/8: the period
    # within that step (P²/(8·2 s) = 3 µs), each phase within a scan step of P/16 plus the
    # drift, modulo the period
    assert abs(float(found.sample_period) - period) < 3e-6
    for got, want in zip(np.asarray(found.phases), phases):
        d = (got - want + period / 2) % period - period / 2
        assert abs(d) < period / 8


def test_reading_age_from_the_command_line(tmp_path):
    """``hdid fit LOG --add reading_age``: the fit without it, the scan, the fit with it."""
    from synthetic import cli_fit_json

    log = tmp_path / "held.csv"
    _held_log(0.007, (0.0031, 0.0007)).to_csv(log, index=False)
    out, _ = cli_fit_json(log, tmp_path / "fit.json", "--ratio", "1", "--remove", "stribeck",
                          "--add", "linear_stiffness", "--inertia", str(AGE_I),
                          "--add", "reading_age", "-q")
    assert any(w.startswith("reading_age: the device's clock (P = 7 ms") for w in out["warnings"])
    rms = (out["rms"]["wg_rad"] / out["rms"]["wg_floor_rad"] if "rms" in out
           else out["rms_residual_rad"] / out["quantization_floor_rad"])
    # an exact model leaves the rounding (≤ 1.0× the floor) plus the fitted release's slack
    assert rms < 1.5, out["warnings"]


def test_reading_age_is_tried_by_diagnose_only_where_readings_jump(aged_fits):
    from hdid.effects import ReadingAge, registry
    from hdid.effects._candidate import candidates

    plain, aged, period, _ = aged_fits
    cand = next(c for c in candidates(registry()) if c.key == "reading_age")
    assert cand.applies(plain.model) and not cand.applies(aged.model)
    found = cand.variants(plain.model, {}, {"frame": plain.residuals()})
    assert len(found) == 1 and isinstance(found[0][1].reading, ReadingAge)
    assert abs(float(found[0][1].reading.sample_period) - period) < 3e-6   # the scan's step
    # BIC: the period and each run's phase are charged ln n, as fitted parameters
    assert cand.penalty(400) == pytest.approx(3 * np.log(400))
    # a log whose residual is at the rounding floor (the aged fit's) has nothing for it
    assert cand.variants(plain.model, {}, {"frame": aged.residuals()}) == []


def test_reading_age_is_simulated_or_refused_never_ignored(tmp_path):
    """`hdid simulate --from` a fit with the age reads each run at its device's samples (the
    numpy oracle above); a driven fit, which does not model it, says so (one line) instead of
    fitting as if it were absent."""
    from pathlib import Path

    import pandas as pd

    from hdid._simulation._synthetic import synthesize
    from hdid.effects import LinearStiffness, ReadingAge, ViscousFriction

    period, phases, rate, hold = 0.007, np.array([0.0031, 0.0007]), 100.0, 0.2
    base = hdid.Model(effects=(LinearStiffness(k1=AGE_K), ViscousFriction(c_v=AGE_C)),
                      inertia=AGE_I, ratio=1.0)
    model = base.with_effect(ReadingAge(sample_period=period, phases=phases))
    kw = dict(amplitudes=(0.5, -0.4), rate=rate, duration=2.0, hold=hold, counts_per_rev=None,
              seed=5)
    synthesize(tmp_path / "aged.csv", model=model, **kw)
    synthesize(tmp_path / "plain.csv", model=base, **kw)
    aged, plain = (pd.read_csv(tmp_path / f"{n}.csv") for n in ("aged", "plain"))
    rng, t_rel = np.random.default_rng(5), []
    for _ in range(2):  # synthesize's draws: a release instant, then the run's noise
        t_rel.append(hold + rng.uniform(0.0, 1.0) / rate)
        rng.normal(0.0, 0.0, size=int(round(2.0 * rate)))
    for r, (phi, a) in enumerate(zip(phases, (0.5, -0.4))):
        run = aged[aged["run"] == aged["run"].unique()[r]]
        held = run["time"].to_numpy() - np.mod(run["time"].to_numpy() - phi, period)
        oracle = np.where(held < t_rel[r], a, _damped(held - t_rel[r], a))
        # RK4 against the closed form: ~1e-6 rad over 2 s here; the age itself moves the
        # readings by ω·a, up to ~70 mrad (so ignoring it fails by 4 orders of magnitude)
        assert np.max(np.abs(run["theta"].to_numpy() - oracle)) < 1e-4
    assert np.max(np.abs(aged["theta"].to_numpy() - plain["theta"].to_numpy())) > 1e-2
    with pytest.raises(hdid.FitError, match="reading_age"):
        hdid.fit_driven(Path(__file__).resolve().parents[1] / "data" / "synthetic"
                        / "driven_csf8.csv", model)


# -- the request jitter of a sample-and-hold reading ------------------------------------------
def test_reading_age_jitter_is_the_mean_sample_instant():
    """``ReadingAge(jitter=j).sample_times`` against a Monte-Carlo oracle: numpy draws each
    request's arrival ``t + d``, ``d`` uniform on ``[−j/2, j/2]``, and averages the device's
    last sample before it; ``j = 0`` is the plain sawtooth exactly."""
    from hdid.effects import ReadingAge

    period, phase, jitter = 0.008, 0.0013, 0.003
    t = np.linspace(0.2, 0.26, 241)
    rng = np.random.default_rng(5)
    d = rng.uniform(-jitter / 2, jitter / 2, (20000, 1))
    oracle = np.mean(phase + period * np.floor((t + d - phase) / period), axis=0)
    got = np.asarray(ReadingAge(sample_period=period, phases=np.array([phase]),
                                jitter=jitter).sample_times(t[None, :]))[0]
    # the oracle's mean of a two-valued draw (P apart) has sd ≤ P/2/√20000 = 28 µs: 5 sd
    assert np.max(np.abs(got - oracle)) < 5 * 0.5 * period / np.sqrt(20000)
    assert np.all(np.diff(got) >= 0) and np.all(got <= t + 1e-15)
    plain = np.asarray(ReadingAge(sample_period=period, phases=np.array([phase]))
                       .sample_times(t[None, :]))[0]
    np.testing.assert_array_equal(plain, phase + period * np.floor((t - phase) / period))


def test_reading_age_scan_finds_the_request_jitter():
    """A device clock of 7 ms read by a host whose requests arrive with a 2.5 ms uniform
    spread: the scan (on a residual frame built from the closed-form motion, no fit) names
    the spread and explains the flipped readings better than the plain sawtooth."""
    import pandas as pd

    from hdid.effects._age_scan import scan

    period, jitter = 0.007, 0.0025
    rng = np.random.default_rng(11)
    rows = []
    for r, (phi, theta0) in enumerate(zip((0.0031, 0.0007), (0.5, -0.4))):
        t = np.arange(0.2, 2.0, 0.01) + rng.normal(0, 4e-4, 180)
        arrive = t + rng.uniform(-jitter / 2, jitter / 2, t.size)
        sampled = phi + period * np.floor((arrive - phi) / period)
        reading = np.round(_damped(sampled - 0.2, theta0) / AGE_STEP) * AGE_STEP
        h = 1e-6
        omega = (_damped(t - 0.2 + h, theta0) - _damped(t - 0.2 - h, theta0)) / (2 * h)
        rows.append(pd.DataFrame({"run": f"r{r}", "t": t, "residual_rad": reading - _damped(t - 0.2, theta0),
                                  "omega": omega, "phase": "moving", "weight": 1.0}))
    frame = pd.concat(rows, ignore_index=True)
    floor = AGE_STEP / np.sqrt(12)
    found = scan(frame, floor=floor, periods=[period], jitters=np.arange(1, 9) / 16)
    # the jitter grid's step is P/16 = 0.44 ms; the draw of 360 arrivals adds little
    assert abs(found.jitter - jitter) <= period / 16
    # the flips cost the plain sawtooth ~ ω²P²·p(1−p) on the ~36 % of readings within j/2 of
    # a step: more than ln n floor² (the BIC's charge for the one more setting) by far
    assert (found.sse_no_jitter - found.sse) / floor**2 > 10 * np.log(len(frame))
    plain = scan(frame, floor=floor, periods=[period])
    assert plain.jitter == 0.0
