"""Physical effects: each a small equinox module whose torques the model sums."""

from ._base import AbstractEffect, Motion, Parameter, positive_power
from ._stiffness import CubicStiffness
from ._stribeck import StribeckFriction
from ._viscous import ViscousFriction

__all__ = [
    "AbstractEffect",
    "CubicStiffness",
    "Motion",
    "Parameter",
    "StribeckFriction",
    "ViscousFriction",
    "positive_power",
]
