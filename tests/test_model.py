"""The effect interface and the model: composition, parameters, user-written effects."""

from __future__ import annotations

from typing import ClassVar

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hdid
from hdid import AbstractEffect, Model, Parameter
from hdid.effects import CubicStiffness, Motion, StribeckFriction, ViscousFriction

T = np.arange(100) / 1000.0


def test_default_model_parameters_and_units():
    m = Model.default()
    specs = m.parameter_specs()
    assert list(specs) == ["k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v", "inertia"]
    assert specs["k1"].unit == "N m/rad" and specs["inertia"].unit == "kg m^2"
    assert m.values()["k1"] == 940.0
    assert m.replace(k1=1000.0).values()["k1"] == 1000.0
    with pytest.raises(KeyError, match="k9"):
        m.replace(k9=1.0)


def test_torques_sum_like_multiterm():
    m = Model.default()
    motion = Motion(theta=jnp.asarray(0.1), omega=jnp.asarray(2.0), direction=jnp.asarray(1.0), ratio=100.0)
    states = m.init_state(jnp.asarray(0.1))
    total = m.torque(motion, states)
    parts = sum(e.torque(motion, None) for e in m.effects)
    assert float(total) == pytest.approx(float(parts), rel=1e-14)
    # Spring: -(k1 d + k2 d^3)/N with d = θ/N.
    d = 0.1 / 100
    assert float(m.effect("stiffness").torque(motion, None)) == pytest.approx(-(940 * d + 6.5e7 * d**3) / 100)
    # At rest the friction's sliding part vanishes; its static capacity is tau_s.
    rest = Motion(theta=jnp.asarray(0.1), omega=jnp.zeros(()), direction=jnp.zeros(()), ratio=100.0)
    assert float(m.effect("stribeck").torque(rest, None)) == 0.0
    assert float(m.holding_torque(rest, states)) == pytest.approx(4.5e-3)


def test_effects_switch_on_and_off():
    m = Model.default()
    no_visc = m.without("viscous")
    assert no_visc.effect_names == ("stiffness", "stribeck")
    assert "c_v" not in no_visc.parameter_specs()
    back = no_visc.with_effect(ViscousFriction(c_v=1e-5))
    assert back.effect_names == ("stiffness", "stribeck", "viscous")
    with pytest.raises(KeyError, match="backlash"):
        m.without("backlash")
    with pytest.raises(ValueError, match="clashes"):
        Model(effects=(CubicStiffness(k1=1.0, k2=0.0), StribeckFriction(tau_c=1.0, tau_s=1.0, v_s=1.0, delta=1.0),
                       _Clash(k1=1.0)), inertia=1e-6)


class _Clash(AbstractEffect):
    k1: float
    name: ClassVar[str] = "clash"
    parameters: ClassVar = (Parameter("k1", "N m/rad", "duplicate name"),)

    def torque(self, motion, state):
        return jnp.zeros(())


class Cogging(AbstractEffect):
    """The README's user-written effect, verbatim in spirit: one small class."""

    amplitude: float = hdid.effects.parameter("N m", "cogging torque", transform="identity", scale=1e-3)
    name: ClassVar[str] = "cogging"

    def torque(self, motion, state):
        return -self.amplitude * jnp.sin(24 * motion.theta)  # 24 cogging cycles per rev


def test_user_effect_changes_the_motion_and_is_differentiable():
    base = Model.default()
    model = base.with_effect(Cogging(amplitude=2e-4))
    assert "amplitude" in model.parameter_specs()
    a = np.asarray(hdid.simulate(base, T, 0.157, 0.0005))
    b = np.asarray(hdid.simulate(model, T, 0.157, 0.0005))
    assert np.max(np.abs(a - b)) > 1e-4  # 0.2 mNm against ~3 mNm friction moves the rest point
    sens = jax.jacfwd(lambda amp: hdid.simulate(model.replace(amplitude=amp), T, 0.157, 0.0005))(2e-4)
    assert np.all(np.isfinite(np.asarray(sens))) and np.max(np.abs(np.asarray(sens))) > 0


class Hysteresis(AbstractEffect):
    """An effect with internal state: one elasto-plastic (Maxwell-slip) element."""

    k_h: float
    f_h: float
    name: ClassVar[str] = "slip1"
    parameters: ClassVar = (
        Parameter("k_h", "N m/rad", "element stiffness at the WG"),
        Parameter("f_h", "N m", "element slip torque"),
    )

    def init_state(self, theta0):
        return jnp.zeros(())

    def update_state(self, state, theta_old, theta_new):
        z = state + (theta_new - theta_old)
        lim = self.f_h / self.k_h
        return jnp.clip(z, -lim, lim)

    def torque(self, motion, state):
        return -self.k_h * state


def test_stateful_effect_runs_in_the_simulator():
    m = Model.default().with_effect(Hysteresis(k_h=0.02, f_h=1e-3))
    assert m.replace(f_h=2e-3).values()["f_h"] == 2e-3
    theta = np.asarray(hdid.simulate(m, T, 0.157, 0.0005))
    assert np.all(np.isfinite(theta))
    base = np.asarray(hdid.simulate(Model.default(), T, 0.157, 0.0005))
    assert np.max(np.abs(theta - base)) > 1e-3


def test_stick_band_matches_cubic_solution():
    m = Model.default()
    lo, hi = (float(x) for x in m.stick_band())
    d = hi / 100
    # (k1 d + k2 d^3)/N = tau_s at the band edge.
    assert (940 * d + 6.5e7 * d**3) / 100 == pytest.approx(4.5e-3, rel=1e-10)
    assert lo == pytest.approx(-hi, rel=1e-12)


@pytest.mark.slow
def test_fit_with_a_user_effect_recovers_it(tmp_path):
    # A log simulated with cogging (hdid's own simulator: this checks the plumbing of a
    # user effect through the fit, not the physics, which test_simulate checks), rich
    # design: 1 kHz, four amplitudes each way.
    from hdid._simulation._synthetic import synthesize

    truth = Model.default().with_effect(Cogging(amplitude=4e-4))
    path = tmp_path / "cog.csv"
    synthesize(path, amplitudes=[0.157, -0.157, 0.12, -0.12, 0.08, -0.08, 0.05, -0.05],
               rate=1000.0, duration=0.25, model=truth, seed=5)
    start = Model.default().with_effect(Cogging(amplitude=1e-4))
    res = hdid.fit(path, model=start)
    a = res.parameters["amplitude"]
    # Quantized, noiseless: the fit should land within its own 3σ (plus 5 % for the
    # quantization bias seen on friction terms) and the residual at the floor.
    assert abs(a.value - 4e-4) < 3 * a.std + 0.05 * 4e-4, (a.value, a.std)
    assert res.rms_residual_rad < 1.3 * res.quantization_floor_rad


def test_the_spring_is_found_by_its_type_not_by_a_name():
    """Springs are an abstract type (issue 20: no code dispatches on the slot string
    "stiffness"): every library spring is an AbstractSpring, the model finds its spring
    by type, a pendulum has none, and the driven joint takes a user's spring subclass
    while refusing an effect that merely calls itself "stiffness"."""
    from hdid.effects import registry

    springs = {k for k, cls in registry().items() if issubclass(cls, hdid.AbstractSpring)}
    assert springs == {"stiffness", "backlash", "kinematic_error", "linear_stiffness",
                       "soft_windup"}
    base = Model.default()
    assert isinstance(base.spring, CubicStiffness)
    values = base.float_values()
    free_play = base.with_effect(registry()["backlash"].start_from(values))
    assert type(free_play.spring).__name__ == "FreePlayStiffness"
    assert base.without("stiffness").spring is None

    class Soft(hdid.AbstractSpring):
        k: float
        parameters: ClassVar = (Parameter("k", "N m/rad", "a user's linear spring"),)

        def torque(self, motion, state):
            return -self.k * motion.theta / motion.ratio**2

    class Impostor(AbstractEffect):
        k: float
        name: ClassVar[str] = "stiffness"
        parameters: ClassVar = (Parameter("k", "N m/rad", "not a spring type"),)

        def torque(self, motion, state):
            return -self.k * motion.theta / motion.ratio**2

    rest = base.without("stiffness").effects
    joint = hdid.DrivenJoint(Model(effects=(Soft(k=900.0),) + rest, inertia=7e-7), 0.05,
                             hdid.PositionalError.zeros(0))
    # T_k(d) at the output of a linear spring: k·d
    assert float(joint.spring_torque(1e-3)) == pytest.approx(900.0 * 1e-3, rel=1e-12)
    with pytest.raises(ValueError, match="AbstractSpring"):
        hdid.DrivenJoint(Model(effects=(Impostor(k=900.0),) + rest, inertia=7e-7), 0.05,
                         hdid.PositionalError.zeros(0))


def test_the_friction_law_is_found_by_its_type_not_by_a_name():
    """Dry friction laws are an abstract type as springs are (issue 20): the library's
    (Stribeck, Coulomb, asymmetric) are AbstractFriction, the model finds its law by type
    and a user effect that merely calls itself "stribeck" is not taken for one."""
    from hdid.effects import registry

    laws = {k for k, cls in registry().items() if issubclass(cls, hdid.AbstractFriction)}
    assert laws == {"stribeck", "coulomb", "asymmetric_friction"}
    base = Model.default()
    assert type(base.friction) is hdid.StribeckFriction
    values = base.float_values()
    coulomb = base.with_effect(registry()["coulomb"].start_from(values))
    assert type(coulomb.friction) is hdid.CoulombFriction and len(coulomb.effects) == 3
    assert base.without("stribeck").friction is None

    class Impostor(AbstractEffect):
        f: float
        name: ClassVar[str] = "stribeck"
        parameters: ClassVar = (Parameter("f", "N m", "not a friction type"),)

        def torque(self, motion, state):
            return -self.f * motion.direction

    assert base.with_effect(Impostor(f=1e-3)).friction is None


def test_parameters_are_declared_once_on_their_fields():
    """A parameter is declared once, as its field (issue 20): ``parameters`` is collected
    from the fields in their order, a reused declaration keeps its metadata, and declaring
    a parameter twice (field and class variable) is refused."""
    import dataclasses

    from hdid.effects import FreePlayStiffness, parameter, registry

    for key, cls in registry().items():
        fields = [f.name for f in dataclasses.fields(cls)]
        assert "parameters" not in fields, key  # a class variable, not a field
        assert [p.name for p in cls.parameters] == [n for n in fields if n in
                                                    {p.name for p in cls.parameters}], key
    assert FreePlayStiffness.parameters[:2] == CubicStiffness.parameters

    class Drag(AbstractEffect):
        c_d: float = parameter("N m s^2/rad^2", "quadratic drag", start=lambda s: 1e-9)
        name: ClassVar[str] = "drag"

        def torque(self, motion, state):
            return -self.c_d * motion.omega * jnp.abs(motion.omega)

    (p,) = Drag.parameters
    assert (p.name, p.unit, p.transform) == ("c_d", "N m s^2/rad^2", "log")
    model = Model.default().with_effect(Drag(c_d=2e-9))
    assert model.parameter_specs()["c_d"] is p and float(model.values()["c_d"]) == 2e-9
    with pytest.raises(TypeError, match="declare each parameter once"):
        class Twice(AbstractEffect):
            c_d: float = parameter("N m s^2/rad^2", "quadratic drag")
            name: ClassVar[str] = "twice"
            parameters: ClassVar = (Parameter("c_d", "N m s^2/rad^2", "quadratic drag"),)

            def torque(self, motion, state):
                return jnp.zeros(())


def test_model_joint_and_positional_error_share_one_parameter_set():
    """A free-motion model, a driven joint and its positional error are parameter sets of
    one kind (issue 20): values by name, a float copy, replace, and the same clear error
    for a name they do not have."""
    from hdid._models._parameter_set import AbstractParameterSet

    joint = hdid.DrivenJoint.default(order=2)
    for obj in (Model.default(), joint, joint.positional):
        assert isinstance(obj, AbstractParameterSet)
        name = obj.names()[-1]
        again = obj.replace(**{name: 0.5})
        assert again.float_values()[name] == 0.5 and list(again.names()) == list(obj.names())
        with pytest.raises(KeyError, match=rf"unknown parameter\(s\) \['nope'\]; this {type(obj).__name__} has"):
            obj.replace(nope=1.0)
