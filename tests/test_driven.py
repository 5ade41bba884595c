"""The driven joint (issue 5): JAX simulator against the independent reference, fits.

The reference is ``hdid.reference.logs.simulate_driven`` (numpy/scipy, event-driven, shares
no code with hdid's JAX simulator); the shipped log ``driven_csf8.csv`` was made by it, quantized to the 4000-count
motor encoder and a 2**19-count output encoder.
"""

from __future__ import annotations

import json

import jax
import jax.numpy as jnp
import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import hdid
from hdid._simulation._driven import DrivenJoint, simulate_driven
from hdid._models._positional import PositionalError
from hdid.cli import main
from hdid.reference import logs as DRV

from synthetic import SYNTH


DRIVEN = SYNTH / "driven_csf8.csv"
FREE = SYNTH / "csf8_paper.csv"
TRUTH = json.loads((SYNTH / "truth.json").read_text())["driven_csf8.csv"]
P = TRUTH["params"]
STEP = TRUTH["step_rad"]
OUT_STEP = TRUTH["output_step_rad"]
PHYSICAL = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v", "inertia", "tau_fout")


def true_joint() -> DrivenJoint:
    model = hdid.Model.default().replace(**{k: P[k] for k in PHYSICAL if k != "tau_fout"})
    return DrivenJoint(model, P["tau_fout"], PositionalError(P["pos_a0"], P["pos_a"], P["pos_b"]))


def test_simulator_matches_the_independent_reference_on_every_shipped_run():
    log = hdid.read_log(DRIVEN)
    joint = true_joint()
    for run, meta in zip(log.runs, TRUTH["runs"]):
        ref = DRV.simulate_driven(P, run.time, run.motor_torque, run.load_torque,
                                  theta0=meta["theta0"], omega0=meta["omega0"])
        sim = simulate_driven(joint, run.time, run.motor_torque, run.load_torque,
                              meta["theta0"], meta["omega0"], full_output=True)
        # Within 0.1 encoder count: the fit compares with readings rounded to one count,
        # so an error far below the rounding noise (σ = 0.29 count) is invisible to it.
        err = np.max(np.abs(np.asarray(sim["theta"]) - ref["theta"]))
        assert err < 0.1 * STEP, (run.name, err / STEP)
        err_out = np.max(np.abs(np.asarray(sim["theta_out"]) - ref["theta_out_clean"]))
        assert err_out < 0.1 * OUT_STEP, (run.name, err_out / OUT_STEP)
        # The output friction's sign (stick/slide logic) agrees at every sample.
        assert np.array_equal(np.asarray(sim["output_direction"]), ref["fout_sign"])


def test_twist_inverts_the_spring_with_the_right_derivative():
    joint = true_joint()
    tau = jnp.array([-1.3, -0.2, 0.0, 0.05, 1.25])
    d = joint.twist(tau)
    np.testing.assert_allclose(joint.spring_torque(d), tau, atol=1e-12)
    np.testing.assert_allclose(np.asarray(d), DRV.inverse_stiffness(np.asarray(tau), P["k1"], P["k2"]),
                               rtol=1e-12, atol=1e-15)

    def f(k1, k2):
        return joint.replace(k1=k1, k2=k2).twist(1.1)

    g = jax.grad(f, argnums=(0, 1))(P["k1"], P["k2"])
    for i, (h, arg) in enumerate(((1e-3, "k1"), (1e2, "k2"))):
        up = dict(k1=P["k1"], k2=P["k2"])
        dn = dict(up)
        up[arg] += h
        dn[arg] -= h
        fd = (f(**up) - f(**dn)) / (2 * h)
        # central difference error ~ h²·f''' ≪ 1e-6 relative here
        assert float(g[i]) == pytest.approx(float(fd), rel=1e-6)


def test_simulate_driven_sticks_exactly_below_capacity():
    joint = true_joint()
    t = np.arange(0, 0.2, 0.004)
    capacity = P["tau_s"] + P["tau_fout"] / 100
    out = simulate_driven(joint, t, np.full(t.size, 0.99 * capacity), None, 0.3, 0.0, full_output=True)
    assert np.all(np.asarray(out["theta"]) == 0.3)
    out = simulate_driven(joint, t, np.full(t.size, 1.01 * capacity), None, 0.3, 0.0, full_output=True)
    assert np.asarray(out["theta"])[-1] > 0.3


@pytest.fixture(scope="module")
def driven_fit():
    return hdid.fit_driven(DRIVEN)


def _within(result, name, truth, n_std=5.0):
    p = result.parameters[name]
    # 5 reported standard errors: the std comes from the quantization σ = step/√12 of
    # independent readings; rounding errors of neighbouring readings of a smooth
    # trajectory are not independent, so the true scatter can be ~2× the reported one.
    assert abs(p.value - truth) <= n_std * p.std, (name, p.value, truth, p.std)


def test_driven_fit_recovers_stiffness_friction_inertia_and_positional_error(driven_fit):
    r = driven_fit
    for name in PHYSICAL:
        _within(r, name, P[name])
    # Absolute scale: the inertia is identified (known motor torque), to far better than
    # the ±30 % a datasheet gives; stiffness from the twist to better than 1 %.
    assert r.parameters["inertia"].std / P["inertia"] < 1e-3
    assert r.parameters["k1"].std / P["k1"] < 0.01
    pe = r.positional
    assert pe["order"] == len(P["pos_a"])  # BIC picks the true order 3
    truth = {"pos_a0": P["pos_a0"]}
    truth |= {f"pos_a{n + 1}": v for n, v in enumerate(P["pos_a"])}
    truth |= {f"pos_b{n + 1}": v for n, v in enumerate(P["pos_b"])}
    for name, value in truth.items():
        c = pe["coefficients"][name]
        assert abs(c["value"] - value) <= 5 * c["std"], (name, c, value)
    # Both residuals at their quantization floors (1.3×: see diagnose's ADEQUATE margin).
    assert r.rms["wg_rad"] <= 1.3 * r.rms["wg_floor_rad"]
    assert r.rms["kinematic_rad"] <= 1.3 * r.rms["kinematic_floor_rad"]
    assert not r.warnings


def test_driven_fit_splits_the_kinematic_error_as_in_fig_3(driven_fit):
    c = driven_fit.curves()
    w = c["weight"] > 0
    total = c["positional"] + c["flexibility"]
    resid = (c["kinematic_error"] - total)[w]
    # The two parts are each much larger than what is left (the split is not vacuous).
    assert np.std(c["flexibility"][w]) > 20 * np.std(resid)
    assert np.std(c["positional"][w]) > 10 * np.std(resid)
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, (a1, a2) = plt.subplots(2)
    assert driven_fit.plot(ax=a1) is a1
    assert driven_fit.plot_kinematic_error(ax=a2) is a2
    plt.close(fig)
    d = driven_fit.to_dict()
    json.dumps(d)
    assert d["positional_error"]["order"] == 3
    assert set(d["positional_error"]["coefficients"]["pos_b2"]) == {"value", "std"}


@pytest.fixture(scope="module")
def wg_only_fit():
    """The shipped driven log with theta_out dropped, the output friction given (the log
    cannot see it: held either way, here at its true value)."""
    wg_only = pd.read_csv(DRIVEN).drop(columns=["theta_out"])
    return wg_only, hdid.fit_driven(wg_only, fix={"tau_fout": P["tau_fout"]})


def test_joint_fit_fixes_what_neither_log_fixes_alone(wg_only_fit):
    """A driven log without an output encoder and a free-motion log: the driven log
    cannot see the spring (eq. 9 has none), the free-motion log sees it only relative
    to the inertia (its free-inertia fit reports k1 undetermined: test_fit's
    test_free_inertia_without_added_inertia_has_no_small_error_bar, on the same log).
    Together they give k1 absolutely."""
    # The driven fit alone: what it holds follows from the log's columns (no theta_out:
    # the spring and tau_fout are held, whatever tau_fout is held at), so the fit shared
    # with the floor test below shows it.
    df, wg_only = wg_only_fit
    assert wg_only.parameters["k1"].fixed  # held, with a note saying why
    assert any("no output angle" in n for n in wg_only.notes)
    joint = hdid.fit_joint([FREE, df])
    k1 = joint.parameters["k1"]
    assert not k1.fixed and np.isfinite(k1.std)
    _within(joint, "k1", P["k1"])
    _within(joint, "inertia", P["inertia"])
    assert "free_motion[0]_rad" in joint.rms
    assert joint.rms["free_motion[0]_rad"] <= 1.3 * joint.rms["free_motion[0]_floor_rad"]


def test_cli_fits_a_driven_log_and_writes_positional_error(tmp_path):
    # A short piece of the shipped log (run 1, its first 0.4 s: two 0.2 s windows, as in
    # test_json_schema and test_result_protocol) keeps this CLI check fast; the science
    # is tested above. In process (click's runner): the command's whole path from its
    # arguments to the JSON runs inside `main`; what a real process adds (its exit
    # status, no traceback) test_cli checks once per path.
    df = pd.read_csv(DRIVEN)
    path = tmp_path / "run1.csv"
    df[(df["run"] == df["run"].iloc[0]) & (df["time"] < 0.4)].to_csv(path, index=False)
    before = path.read_bytes()
    out = tmp_path / "d.json"
    res = CliRunner().invoke(main, ["fit", str(path), "--order", "3", "--json", str(out), "-q"])
    assert res.exception is None, repr(res.exception)
    assert res.exit_code == 0, res.output
    d = json.loads(out.read_text())
    assert d["kind"] == "driven"
    assert d["positional_error"]["order"] == 3
    assert d["parameters"]["inertia"]["std"] > 0
    assert set(d["positional_error"]["coefficients"]) == {
        "pos_a0", "pos_a1", "pos_a2", "pos_a3", "pos_b1", "pos_b2", "pos_b3"}
    assert path.read_bytes() == before


def test_cli_driven_current_without_torque_constant_is_one_line(tmp_path):
    df = pd.read_csv(DRIVEN).rename(columns={"motor_torque": "motor_current"})
    path = tmp_path / "current.csv"
    df.to_csv(path, index=False)
    # in process (the CLI's error path runs inside `main`; test_cli checks the real
    # process once per error path): one line, exit 2, nothing escaping
    res = CliRunner().invoke(main, ["fit", str(path)])
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 2
    assert res.stderr.count("\n") == 1 and "torque" in res.stderr and "Traceback" not in res.stderr


def test_without_load_variation_the_spring_is_reported_undetermined():
    """With no load torque the twist only flips by ±T_k⁻¹(tau_fout): the data fix
    tau_fout/k1 and tau_c + tau_fout/N, not k1, tau_fout or tau_c each. The fit must say
    so (infinite std and a note), not print a confident k1."""
    import copy

    design = copy.deepcopy(DRV.DRIVEN_DESIGN)
    for run in design["runs"]:
        run["load"] = (0.0,) + tuple(run["load"][1:])
    df, _ = DRV.make_driven_log(DRV.TRUTH_DRIVEN_CSF8, design)
    r = hdid.fit_driven(df, order=3)
    for name in ("k1", "tau_fout", "tau_c"):
        assert np.isinf(r.parameters[name].std), name
    assert np.isfinite(r.parameters["inertia"].std)  # still fixed by the known torque
    assert any("spring is not determined" in n for n in r.notes)


def test_free_motion_fit_refuses_a_driven_log_with_a_pointer():
    with pytest.raises(hdid.LogError, match="driven log"):
        hdid.fit(DRIVEN)
    table = hdid.fit_many([FREE, DRIVEN], vectorize=False)
    assert "driven log" in str(table["error"].iloc[1])
    assert not isinstance(table["error"].iloc[0], str)


# ------------------------------------------------------------- real logs (issue 16)


def _axis(*effects, inertia=95.0):
    """A linear axis in SI units (ratio 1: metres, kilograms, newtons)."""
    return DrivenJoint(hdid.Model(effects=(hdid.CubicStiffness(k1=1e6, k2=0.0),) + effects,
                                  inertia=inertia, ratio=1.0), 0.0, PositionalError.zeros(0))


def test_torque_offset_against_the_closed_form_viscous_solution():
    """``I θ̈ = F − tau_0 − c·θ̇`` with a constant drive force F has the closed form
    ``θ(t) = θ0 + (A/c)·t + (ω0 − A/c)·(I/c)·(1 − e^{−ct/I})``, ``A = F − tau_0`` (the
    oracle; it shares no code with hdid). RK4 at 0.5 ms on a 0.47 s time constant is
    exact to ~1e-13 of the travel: 1e-9 m absolute on ~0.1 m."""
    I, c, F, tau_0, th0, om0 = 95.0, 203.5, 60.0, -3.16, 0.01, -0.05
    joint = _axis(hdid.ViscousFriction(c_v=c), hdid.TorqueOffset(tau_0=tau_0), inertia=I)
    t = np.arange(400) * 1e-3
    sim = np.asarray(simulate_driven(joint, t, np.full(t.size, F), None, th0, om0))
    A = F - tau_0
    exact = th0 + (A / c) * t + (om0 - A / c) * (I / c) * (1 - np.exp(-c * t / I))
    np.testing.assert_allclose(sim, exact, rtol=0, atol=1e-9)
    # Without the offset the same force gives a different motion (the test can fail).
    assert np.max(np.abs(exact - (th0 + (F / c) * t + (om0 - F / c) * (I / c)
                                  * (1 - np.exp(-c * t / I))))) > 1e-3


def test_torque_offset_shifts_the_breakaway_torques():
    """At rest the offset adds to what friction must hold: with Coulomb friction S and
    tau_0 = S the axis holds a drive force 1.5·S (net 0.5·S ≤ S) but slides backwards
    under −0.5·S (net −1.5·S), then with ``I θ̈ = −0.5·S`` (hand calculation)."""
    S, I = 20.0, 95.0
    fric = hdid.StribeckFriction(tau_c=S, tau_s=S, v_s=0.01, delta=1.0)
    joint = _axis(fric, hdid.TorqueOffset(tau_0=S), inertia=I)
    t = np.arange(100) * 1e-3
    held = np.asarray(simulate_driven(joint, t, np.full(t.size, 1.5 * S), None, 0.02, 0.0))
    assert np.all(held == 0.02)
    back = np.asarray(simulate_driven(joint, t, np.full(t.size, -0.5 * S), None, 0.02, 0.0))
    np.testing.assert_allclose(back, 0.02 - 0.5 * (0.5 * S / I) * t**2, rtol=0, atol=1e-12)


def test_first_order_hold_against_the_cubic_of_a_torque_ramp():
    """A torque sampled from the ramp ``a + b·t`` and interpolated linearly (FOH) is the
    ramp itself, so a frictionless inertia follows ``θ0 + ω0·t + a·t²/2I + b·t³/6I``
    exactly (the oracle); the zero-order hold lags it by half a sample of torque."""
    I, a, b, th0, om0 = 7e-7, 1e-3, -0.02, 0.3, 2.0
    model = hdid.Model(effects=(hdid.CubicStiffness(k1=940.0, k2=0.0),), inertia=I, ratio=100.0)
    joint = DrivenJoint(model, 0.0, PositionalError.zeros(0))
    t = np.arange(60) * 0.004
    tau = a + b * t
    exact = th0 + om0 * t + a * t**2 / (2 * I) + b * t**3 / (6 * I)
    foh = np.asarray(simulate_driven(joint, t, tau, None, th0, om0, input_hold="foh"))
    # RK4 integrates a cubic exactly: only rounding remains (θ ~ 1e2 rad here).
    np.testing.assert_allclose(foh, exact, rtol=0, atol=1e-9)
    zoh = np.asarray(simulate_driven(joint, t, tau, None, th0, om0))
    assert np.max(np.abs(zoh - exact)) > 1e-3
    with pytest.raises(ValueError, match="input_hold"):
        simulate_driven(joint, t, tau, None, th0, om0, input_hold="cubic")


def test_input_hold_rule():
    from hdid._fitting._driven_fit import input_hold_for

    class L:
        torque_constant = None

    assert input_hold_for(L()) == "zoh"
    L.torque_constant = 0.05
    assert input_hold_for(L()) == "foh"
    assert input_hold_for(L(), "zoh") == "zoh"
    with pytest.raises(ValueError, match="input_hold"):
        input_hold_for(L(), "linear")


def test_driven_start_is_scale_free():
    """The same physical run in other units (angle ×0.001, torque ×1000: a linear axis
    in metres and newtons looks like this next to a CSF-8 in rad and N m) must give the
    same physics: inertia and c_v scale by 1e6, tau_c by 1e3. With the old absolute
    1 rad/s speed threshold no sample of the rescaled log entered the equation-error
    start, which then began from CSF-8 defaults six orders of magnitude off. Tolerance: 2 % — both fits stop at the solver's
    statistical tolerance, far below the 5-std agreement with the truth tested above."""
    df = pd.read_csv(DRIVEN).drop(columns=["theta_out"])
    df = df[df["run"] == df["run"].iloc[0]]
    a, b = 1e-3, 1e3
    scaled = df.assign(theta=df["theta"] * a, motor_torque=df["motor_torque"] * b,
                       load_torque=df["load_torque"] * b)
    r0 = hdid.fit_driven(df, order=0)
    r1 = hdid.fit_driven(hdid.read_log(scaled, resolution=STEP * a), order=0)
    for name, f in (("inertia", b / a), ("c_v", b / a), ("tau_c", b)):
        v0, v1 = r0.parameters[name].value, r1.parameters[name].value
        assert v1 / f == pytest.approx(v0, rel=0.02), (name, v0, v1 / f)


def test_driven_fit_without_the_output_encoder_reaches_the_floor(wg_only_fit):
    # The shipped driven log with theta_out dropped, the output friction given (the log
    # cannot see it): the free WG friction and inertia must describe the WG readings to
    # their quantization floor (1.3×: diagnose's ADEQUATE margin). Measured before the
    # fix: 2.0× — the Stribeck fit inherited the residual scale its Coulomb start had set
    # at a χ² of 7.7e8, so its statistical stop ended it early.
    _, r = wg_only_fit
    assert r.rms["wg_rad"] <= 1.3 * r.rms["wg_floor_rad"], r.notes
    for name in ("tau_c", "tau_s", "c_v"):
        est = r.parameters[name]
        assert abs(est.value - P[name]) <= 3 * est.std, (name, est, P[name])
