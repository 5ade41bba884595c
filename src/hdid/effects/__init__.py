"""Physical effects: each a small equinox module whose torques the model sums."""

from ._asymmetric import AsymmetricStribeckFriction
from ._base import AbstractEffect, Motion, Parameter, Scales, order_of_magnitude, positive_power
from ._freeplay import FreePlayStiffness
from ._gravity import Gravity
from ._hysteresis import DahlHysteresis
from ._kinematic import KinematicErrorStiffness
from ._linear import LinearStiffness
from ._load_friction import LoadDependentFriction
from ._ripple import PositionRipple
from ._segments import ThreeSegmentStiffness
from ._stiffness import CubicStiffness
from ._stribeck import StribeckFriction
from ._torque_offset import TorqueOffset
from ._coulomb import CoulombFriction
from ._viscous import ViscousFriction
from ._viscous_asymmetric import AsymmetricViscousFriction


def library(values: dict[str, float]) -> dict[str, AbstractEffect]:
    """Effects that ``--add NAME`` can add, with starting values taken from ``values``
    (a fitted or default model's) where the effect shares or rescales them.

    An effect whose ``name`` is already in the model (``"stiffness"``, ``"stribeck"``)
    replaces it.
    """
    v = values
    k1 = v.get("k1", v.get("K1", 940.0))
    k2 = v.get("k2", 6.5e7)
    tau_c = v.get("tau_c", 3e-3)
    tau_s = v.get("tau_s", 4.5e-3)
    # the small-swing stiffness at the logged axis, as the caller measured it (diagnose
    # passes the fitted model's); k1/N² with N = 100 only as a last resort
    k_wg = v.get("_k_wg", k1 / 1e4)
    stribeck = dict(tau_c=tau_c, tau_s=tau_s, v_s=v.get("v_s", 3.0), delta=v.get("delta", 1.0))
    return {
        "asymmetric_friction": AsymmetricStribeckFriction(**stribeck, asym=v.get("asym", 0.0)),
        "asymmetric_viscous": AsymmetricViscousFriction(c_vp=v.get("c_vp", v.get("c_v", 2e-5)),
                                                        c_vn=v.get("c_vn", v.get("c_v", 2e-5))),
        "coulomb": CoulombFriction(tau_c=tau_c),
        "backlash": FreePlayStiffness(k1=k1, k2=k2, backlash=v.get("backlash", 0.01)),
        "gravity": Gravity(mgl=v.get("mgl", k1)),
        "hysteresis": DahlHysteresis(f_h=v.get("f_h", 0.2 * tau_c), sigma_h=v.get("sigma_h", k_wg)),
        "kinematic_error": KinematicErrorStiffness(k1=k1, k2=k2, ke_a=v.get("ke_a", 0.0),
                                                   ke_b=v.get("ke_b", 0.0), order=v.get("order", 2.0)),
        "linear_stiffness": LinearStiffness(k1=k1),
        "load_friction": LoadDependentFriction(c_load=v.get("c_load", 0.05 * k_wg)),
        "ripple": PositionRipple(ripple_a=v.get("ripple_a", 0.0), ripple_b=v.get("ripple_b", 0.0),
                                 order=v.get("order", 24.0)),
        "soft_windup": ThreeSegmentStiffness(
            K1=v.get("K1", 0.97 * k1), K2=v.get("K2", 1.06 * k1), K3=v.get("K3", 1.28 * k1),
            T1=v.get("T1", 0.29 * k1 / 940.0), dT12=v.get("dT12", 0.46 * k1 / 940.0)),
        "stiffness": CubicStiffness(k1=k1, k2=k2),
        "stribeck": StribeckFriction(**stribeck),
        "torque_offset": TorqueOffset(tau_0=v.get("tau_0", 0.0)),
        "viscous": ViscousFriction(c_v=v.get("c_v", 2e-5)),
    }


__all__ = [
    "AbstractEffect",
    "AsymmetricStribeckFriction",
    "AsymmetricViscousFriction",
    "CoulombFriction",
    "CubicStiffness",
    "DahlHysteresis",
    "FreePlayStiffness",
    "Gravity",
    "KinematicErrorStiffness",
    "LinearStiffness",
    "LoadDependentFriction",
    "library",
    "Motion",
    "Parameter",
    "PositionRipple",
    "Scales",
    "StribeckFriction",
    "ThreeSegmentStiffness",
    "TorqueOffset",
    "ViscousFriction",
    "positive_power",
]
