"""Physical effects: each a small equinox module whose torques the model sums."""

from ._base import AbstractEffect, Motion, Parameter, positive_power
from ._freeplay import FreePlayStiffness
from ._stiffness import CubicStiffness
from ._stribeck import StribeckFriction
from ._viscous import ViscousFriction

def library(values: dict[str, float]) -> dict[str, AbstractEffect]:
    """Effects that ``--add NAME`` can add, built from starting ``values`` (a model's)."""
    v = values
    return {
        "backlash": FreePlayStiffness(k1=v.get("k1", 940.0), k2=v.get("k2", 6.5e7),
                                      backlash=v.get("backlash", 0.01)),
        "stiffness": CubicStiffness(k1=v.get("k1", 940.0), k2=v.get("k2", 6.5e7)),
        "stribeck": StribeckFriction(tau_c=v.get("tau_c", 3e-3), tau_s=v.get("tau_s", 4.5e-3),
                                     v_s=v.get("v_s", 3.0), delta=v.get("delta", 1.0)),
        "viscous": ViscousFriction(c_v=v.get("c_v", 2e-5)),
    }


__all__ = [
    "AbstractEffect",
    "CubicStiffness",
    "FreePlayStiffness",
    "library",
    "Motion",
    "Parameter",
    "StribeckFriction",
    "ViscousFriction",
    "positive_power",
]
