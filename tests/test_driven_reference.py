"""The independent driven-joint reference (``hdid.reference.logs.simulate_driven``) against
analytic solutions.

Tolerances: the reference integrates with DOP853 at rtol 1e-10, atol 1e-12 and locates
velocity zeros to ~1e-15 s, so on O(1) rad trajectories the angle is right to ~1e-10 rad;
asserts use 1e-9 rad (10x margin) unless stated otherwise next to them.
"""

from __future__ import annotations

import ast
import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from scipy.optimize import brentq

from hdid.reference import logs as DRV

ROOT = Path(__file__).resolve().parents[1]
SYNTH = ROOT / "data" / "synthetic"

N = 100.0
I = 7e-7
H = 0.004  # 250 Hz
BASE = dict(k1=940.0, k2=6.5e7, tau_c=2.5e-3, tau_s=4.5e-3, v_s=5.0, delta=1.0, c_v=1.8e-5,
            inertia=I, tau_fout=0.05, pos_a0=0.0, pos_a=[], pos_b=[])
FRICTIONLESS = BASE | dict(tau_c=0.0, tau_s=0.0, c_v=0.0, tau_fout=0.0)
COULOMB = BASE | dict(tau_c=2.5e-3, tau_s=2.5e-3, c_v=0.0, tau_fout=0.05)  # C = 3.0 mN m
C_COULOMB = 2.5e-3 + 0.05 / N
ATOL = 1e-9  # rad; see the module docstring


def times(n: int) -> np.ndarray:
    return np.arange(n) * H


# ------------------------------------------------------------------ (a) frictionless


@pytest.mark.parametrize("omega0", [0.0, -3.0])
def test_frictionless_constant_torque_is_a_parabola(omega0):
    t = times(40)
    tau = 1.2e-3
    r = DRV.simulate_driven(FRICTIONLESS, t, np.full(t.size, tau), theta0=0.4, omega0=omega0)
    a = tau / I
    np.testing.assert_allclose(r["theta"], 0.4 + omega0 * t + 0.5 * a * t**2, rtol=0, atol=ATOL)
    # omega ~ 1e2 rad/s, relative accuracy 1e-10 -> 1e-8 rad/s
    np.testing.assert_allclose(r["omega"], omega0 + a * t, rtol=0, atol=1e-7)


def test_frictionless_zero_order_hold_and_linear_load():
    """Piecewise parabolas for a ZOH torque; a cubic for a linearly ramped load."""
    t = times(30)
    tau = np.where(np.arange(t.size) % 7 < 3, 2e-3, -1.5e-3)
    r = DRV.simulate_driven(FRICTIONLESS, t, tau, theta0=-1.0)
    th, w = [-1.0], [0.0]
    for k in range(t.size - 1):
        a = tau[k] / I
        th.append(th[-1] + w[-1] * H + 0.5 * a * H * H)
        w.append(w[-1] + a * H)
    np.testing.assert_allclose(r["theta"], th, rtol=0, atol=ATOL)
    # load linear between samples (not held): theta = (tau_d - L0/N) t^2/2I - b t^3/(6 N I)
    L0, b = 0.3, 8.0
    load = L0 + b * t
    r = DRV.simulate_driven(FRICTIONLESS, t, np.full(t.size, 5e-3), load)
    expect = (5e-3 - L0 / N) * t**2 / (2 * I) - b * t**3 / (6 * N * I)
    np.testing.assert_allclose(r["theta"], expect, rtol=0, atol=ATOL)


# ------------------------------------------------------------------ (b) Coulomb only


def test_coulomb_above_capacity_reduced_acceleration():
    t = times(30)
    for tau in (4.0e-3, -6.0e-3):
        r = DRV.simulate_driven(COULOMB, t, np.full(t.size, tau), theta0=2.0)
        a = (tau - math.copysign(C_COULOMB, tau)) / I
        np.testing.assert_allclose(r["theta"], 2.0 + 0.5 * a * t**2, rtol=0, atol=ATOL)
        assert np.all(r["direction"] == np.sign(tau))
        # output friction: 0 at the first sample (no motion yet), then along the motion
        assert r["fout_sign"][0] == 0 and np.all(r["fout_sign"][1:] == np.sign(tau))


@pytest.mark.parametrize("params", [COULOMB, BASE], ids=["coulomb", "stribeck"])
def test_below_capacity_stays_exactly_put(params):
    t = times(25)
    C = DRV.capacity(params)
    # at, and below, the capacity |tau_d - tau_l/N| <= tau_s + tau_fout/N, with a load
    load = np.linspace(-0.2, 0.2, t.size)
    for net in (C, -C, 0.9 * C, 0.0):
        # F(t) = net exactly at the samples and between them (tau_l/N compensated... at the
        # samples; in between F moves by at most the load step/N, kept inside the capacity)
        tau = net + load / N
        if abs(net) == C:  # F is linear in t within each interval; keep it on the boundary
            tau, load_used = np.full(t.size, net), None
        else:
            load_used = load
        r = DRV.simulate_driven(params, t, tau, load_used, theta0=0.7)
        assert np.all(r["theta"] == 0.7)  # exactly: no integration while stuck
        assert np.all(r["omega"] == 0.0) and np.all(r["direction"] == 0)
        assert r["stick_intervals"] == [(0.0, None)] and r["reversals"] == 0


# ------------------------------------------------------------------ (c) stick and reversal


def test_stick_then_breakaway_by_the_load_hand_calculation():
    """Coulomb only. Accelerate with A, brake with B (|B| < C): stop and stick; a load ramp
    makes F = B - tau_l/N reach -C mid-interval: break away negative, theta ~ (t - t_b)^3."""
    t = times(40)
    A, B = 3.5e-3, -1.0e-3
    tau = np.where(t < 0.04 - 1e-12, A, B)
    slope = 4.5  # N m/s from t = 0.06
    load = np.where(t > 0.06, slope * (t - 0.06), 0.0)
    r = DRV.simulate_driven(COULOMB, t, tau, load, theta0=0.0)

    a1 = (A - C_COULOMB) / I
    w1 = a1 * 0.04
    th1 = 0.5 * a1 * 0.04**2
    a2 = (B - C_COULOMB) / I
    t_stop = 0.04 - w1 / a2
    th_stop = th1 - w1**2 / (2 * a2)
    t_break = 0.06 + (-C_COULOMB - B) * -N / slope  # B - slope (t - 0.06)/N = -C
    assert t_break == pytest.approx(0.06 + 0.2 / 4.5, abs=1e-15)
    assert 0.104 < t_break < 0.108  # inside an interval, not at a sample
    # independent root of |F(t)| - C on that interval (brentq on the linear load)
    root = brentq(lambda x: abs(B - slope * (x - 0.06) / N) - C_COULOMB, 0.104, 0.108,
                  xtol=1e-16, rtol=1e-15)
    assert root == pytest.approx(t_break, abs=1e-14)

    (s0, e0), (s1, e1) = r["stick_intervals"]
    assert s0 == 0.0 and e0 == 0.0  # breaks away at the first sample (A > C)
    assert s1 == pytest.approx(t_stop, abs=1e-12)  # event time: brentq to ~1e-15 s
    assert e1 == pytest.approx(t_break, abs=1e-14)  # closed form of a linear F
    assert r["reversals"] == 1

    before = t <= 0.04 + 1e-12
    np.testing.assert_allclose(r["theta"][before], 0.5 * a1 * t[before] ** 2, rtol=0, atol=ATOL)
    stuck = (t > t_stop) & (t <= t_break)
    assert np.all(r["theta"][stuck] == r["theta"][stuck][0])
    assert r["theta"][stuck][0] == pytest.approx(th_stop, abs=ATOL)
    after = t > t_break
    # after breakaway: I w' = B - tau_l(t)/N + C = -(slope/N)(t - t_b)
    expect = th_stop - slope / (6 * N * I) * (t[after] - t_break) ** 3
    np.testing.assert_allclose(r["theta"][after], expect, rtol=0, atol=ATOL)
    # output friction: last sliding value (+) while stuck, then (-)
    assert np.all(r["fout_sign"][1:][before[1:]] == 1)
    assert np.all(r["fout_sign"][stuck] == 1) and np.all(r["fout_sign"][after] == -1)
    assert np.all(r["direction"][stuck] == 0)


def test_reversal_without_sticking():
    """Coulomb only: moving at w0 > 0, a torque -D with D > C stops it and drives it back."""
    t = times(20)
    D = 5e-3
    w0 = 20.0
    r = DRV.simulate_driven(COULOMB, t, np.full(t.size, -D), theta0=0.0, omega0=w0)
    a_brake = (-D - C_COULOMB) / I
    t_stop = -w0 / a_brake
    th_stop = -w0**2 / (2 * a_brake)
    a_back = (-D + C_COULOMB) / I
    expect = np.where(t < t_stop, w0 * t + 0.5 * a_brake * t**2,
                      th_stop + 0.5 * a_back * (t - t_stop) ** 2)
    np.testing.assert_allclose(r["theta"], expect, rtol=0, atol=ATOL)
    assert r["reversals"] == 1 and r["stick_intervals"] == []  # it never sticks
    (t_ev, kind, th_ev, s_ev), (t_ev2, kind2, _, s_ev2) = r["events"]
    assert (kind, s_ev, kind2, s_ev2) == ("stop", 1, "slide", -1) and t_ev == t_ev2
    assert t_ev == pytest.approx(t_stop, abs=1e-12)  # event located by brentq to ~1e-15 s
    assert th_ev == pytest.approx(th_stop, abs=ATOL)


def test_stribeck_breakaway_uses_static_capacity():
    """tau_s > tau_c: a torque between the sliding and the static level keeps it stuck; above
    tau_s + tau_fout/N it breaks away at once and accelerates (friction drops to tau_c)."""
    t = times(10)
    C = DRV.capacity(BASE)
    assert C == pytest.approx(4.5e-3 + 0.05 / N)
    stuck = DRV.simulate_driven(BASE, t, np.full(t.size, 0.999 * C))
    assert np.all(stuck["theta"] == 0.0)
    moving = DRV.simulate_driven(BASE, t, np.full(t.size, 1.001 * C))
    assert np.all(np.diff(moving["theta"]) > 0) and moving["omega"][-1] > 20.0


# ------------------------------------------------------------------ (d) eq. 8


def test_output_angle_eq8():
    params = BASE | dict(pos_a0=3e-4, pos_a=[3e-5, 1.5e-4, -2.5e-5], pos_b=[-2e-5, 1.6e-4, 2e-5])
    t = times(120)
    load = 1.2 * np.sin(2 * np.pi * 1.5 * t)
    u = np.where(t < 0.2, 5.5e-3, np.where(t < 0.3, 0.0, -5.5e-3))
    tau = u + load / N
    r = DRV.simulate_driven(params, t, tau, load, theta0=1.3)
    th = r["theta"]
    pos = 1.5e-4 + sum(a * np.cos(n * th) + b * np.sin(n * th) for n, a, b in
                       zip((1, 2, 3), params["pos_a"], params["pos_b"]))
    np.testing.assert_allclose(r["positional_error"], pos, rtol=0, atol=1e-18)
    tau_out = load + 0.05 * r["fout_sign"]
    d = r["twist"]
    # the cubic inverse: T_k(d) reproduces the torque to float64 rounding (~1e-15 N m)
    np.testing.assert_allclose(940.0 * d + 6.5e7 * d**3, tau_out, rtol=0, atol=1e-14)
    assert np.max(np.abs(d)) > 1.1e-3  # the cubic range is reached (k2 d^3 ~ 9 % of torque)
    np.testing.assert_allclose(r["theta_out_clean"], -th / N + d + pos, rtol=0, atol=1e-16)
    assert set(np.unique(r["fout_sign"])) == {-1, 0, 1}


def test_inverse_stiffness_against_brentq():
    for tau in (-1.7, -0.3, -1e-9, 0.0, 2e-6, 0.8, 1.25):
        want = 0.0 if tau == 0 else brentq(lambda d: 940 * d + 6.5e7 * d**3 - tau, -1e-2, 1e-2,
                                          xtol=1e-30, rtol=1e-15)
        assert DRV.inverse_stiffness(tau, 940.0, 6.5e7) == pytest.approx(want, rel=1e-13,
                                                                          abs=1e-24)
    assert DRV.inverse_stiffness(0.47, 940.0, 0.0) == 0.47 / 940.0


# ------------------------------------------------------------------ (e) the shipped log


def test_shipped_log_on_encoder_grids_and_reproducible():
    df = pd.read_csv(SYNTH / "driven_csf8.csv")
    truth = json.loads((SYNTH / "truth.json").read_text())["driven_csf8.csv"]
    assert list(df.columns) == ["time", "run", "theta", "theta_out", "motor_torque",
                                "load_torque"]
    step, out_step = truth["step_rad"], truth["output_step_rad"]
    assert step == 2 * math.pi / 4000 and out_step == 2 * math.pi / 2**19
    # values written with 15 significant digits: on the grid to ~1e-9 of a count
    for col, q in (("theta", step), ("theta_out", out_step)):
        x = df[col].to_numpy() / q
        assert np.max(np.abs(x - np.rint(x))) < 1e-6
    p = truth["params"]
    for key, value in DRV.TRUTH_DRIVEN_CSF8.items():
        assert p[key] == value
    # the design: several speeds, reversals, revolutions, cubic twist range
    runs = truth["runs"]
    assert len(runs) == 4 and all(1.5 <= r["duration"] + 1 / truth["fs"] <= 2.0 for r in runs)
    assert all(30 < r["max_abs_omega"] < 100 and r["reversals"] >= 2 for r in runs)
    assert all(r["revolutions_travelled"] > 4 for r in runs)
    assert all(r["twist_range"][1] - r["twist_range"][0] > 2e-3 for r in runs)
    # the first 0.3 s of run 1 from the file's own torques reproduce its readings
    sel = df[df["run"] == 1].iloc[:75]
    r = DRV.simulate_driven(p, sel["time"].to_numpy(), sel["motor_torque"].to_numpy(),
                            sel["load_torque"].to_numpy(), theta0=runs[0]["theta0"])
    np.testing.assert_array_equal(np.rint(r["theta"] / step),
                                  np.rint(sel["theta"].to_numpy() / step))
    np.testing.assert_array_equal(np.rint(r["theta_out_clean"] / out_step),
                                  np.rint(sel["theta_out"].to_numpy() / out_step))


def test_make_driven_log_small_design_on_grids():
    design = {"fs": 500.0, "seed": 3, "counts_per_rev": 1024, "output_counts_per_rev": 2**16,
              "runs": [{"segments": [(0.02, "hold", 0.0), (0.05, "ramp", (0.0, 6e-3)),
                                     (0.12, "hold", 3.6e-3)], "load": (0.8, 2.0, "sine")}]}
    df, truth = DRV.make_driven_log(BASE, design)
    assert len(df) == 60 and truth["seed"] == 3
    for col, cpr in (("theta", 1024), ("theta_out", 2**16)):
        x = df[col].to_numpy() / (2 * math.pi / cpr)
        assert np.max(np.abs(x - np.rint(x))) < 1e-9  # computed k*q: float rounding only
    # feed-forward: the motor torque is u + (mean load over the interval)/N
    load = df["load_torque"].to_numpy()
    u = df["motor_torque"].to_numpy()[:-1] - 0.5 * (load[:-1] + load[1:]) / N
    assert np.all(u[:10] == pytest.approx(0.0, abs=1e-18))


#: What the reference modules may import: numpy, scipy, pandas and a few standard modules.
ALLOWED = {"__future__", "collections", "copy", "dataclasses", "math", "numpy", "pandas", "scipy"}


def _foreign_imports(source: str) -> set[str]:
    """The imports of a module of ``hdid.reference`` that leave it: anything outside
    :data:`ALLOWED` (``jax``, ``hdid``, …) and relative imports above the package."""
    out = set()
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            out |= {a.name for a in node.names if a.name.split(".")[0] not in ALLOWED}
        elif isinstance(node, ast.ImportFrom):
            module = node.module or ""
            if node.level > 1 or (node.level == 0 and module.split(".")[0] not in ALLOWED):
                out.add("." * node.level + module)
    return out


def test_reference_is_independent_of_hdid():
    # every module of hdid.reference: the simulators and the log generators built on them
    package = Path(DRV.__file__).parent
    found = {p.name: _foreign_imports(p.read_text()) for p in sorted(package.glob("*.py"))}
    assert {"_driven.py", "_driven_log.py", "_hidden.py", "_logs.py", "logs.py"} <= set(found)
    assert not {name: bad for name, bad in found.items() if bad}
    # and the check refuses what it must (an upward import, hdid, jax); sibling imports pass
    planted = "import jax.numpy\nfrom .. import _config\nfrom hdid.effects import x\nfrom ._spring import y\n"
    assert _foreign_imports(planted) == {"jax.numpy", "..", "hdid.effects"}
