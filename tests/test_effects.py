"""Library effects against independent numpy implementations run in the reference simulator.

Each effect of ``hdid.effects`` is written a second time, from its equation, in
``data/synthetic/hidden.py`` for the event-driven scipy reference. The JAX simulator with
the effect must reproduce the reference trajectory: this checks both codes at once.
"""

from __future__ import annotations

import numpy as np
import pytest

import hdid
from hdid.effects import AbstractEffect, library
from hdid.reference import simulate_reference

from synthetic import GEN, HID, ROOT

TRUTH = {k: v for k, v in GEN.TRUTH_CSF8.items() if k not in ("ratio", "inertia")}
INERTIA = GEN.TRUTH_CSF8["inertia"]
STEP = 2 * np.pi / 4000
T = np.arange(0.0, 0.5, 0.004)
IN_LIBRARY = [k for k, v in HID.HIDDEN.items() if v["library"] is not None]


@pytest.mark.parametrize("name", IN_LIBRARY)
def test_effect_matches_reference_implementation(name):
    entry = HID.HIDDEN[name]
    effect = library({**TRUTH, **entry["truth"]})[entry["library"]]
    model = hdid.Model.default(inertia=INERTIA, **TRUTH).with_effect(effect)
    for theta0 in (0.157, -0.157, 0.08):
        jax_theta = np.asarray(hdid.simulate(model, T, theta0, 0.0013))
        ref = simulate_reference(T, theta0=theta0, t_release=0.0013, inertia=INERTIA, **TRUTH,
                                 **HID.reference_kwargs(name, TRUTH))
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
