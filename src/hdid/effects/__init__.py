"""Physical effects: each a small equinox module whose torques the model sums."""

from ._base import (
    AbstractEffect,
    AbstractFriction,
    AbstractSpring,
    Motion,
    Parameter,
    ScalePrior,
    Scales,
    StartValues,
    order_of_magnitude,
    parameter,
    positive_power,
    same_parameter,
)
from ._candidate import Candidate
from ._reading import AbstractReading
from ._registry import keys, registry
from .asymmetric_friction import AsymmetricStribeckFriction
from .asymmetric_viscous import AsymmetricViscousFriction
from .back_emf import BackEmfBraking
from .backlash import FreePlayStiffness
from .coulomb import CoulombFriction
from .gravity import Gravity
from .gravity_friction import GravityLoadFriction
from .hysteresis import DahlHysteresis
from .kinematic_error import KinematicErrorStiffness
from .linear_stiffness import LinearStiffness
from .load_friction import LoadDependentFriction
from .reading_age import ReadingAge
from .ripple import PositionRipple
from .soft_windup import ThreeSegmentStiffness
from .stiffness import CubicStiffness
from .stribeck import StribeckFriction
from .torque_offset import TorqueOffset
from .viscous import ViscousFriction


def __getattr__(name: str):
    """Any registry effect's class by its class name (``hdid.effects.Cogging``): a new
    library file or an installed plugin needs no edit here to be reachable."""
    if name.startswith("__"):
        raise AttributeError(name)
    for cls in registry().values():
        if cls.__name__ == name:
            return cls
    raise AttributeError(f"module 'hdid.effects' has no attribute {name!r}")


def library(values: dict[str, float]) -> dict[str, AbstractEffect]:
    """Effects that ``--add NAME`` can add — every effect of the registry (this package's
    files and the installed plugins', :func:`~hdid.effects._registry.registry`) — with
    starting values taken from ``values`` (a fitted or default model's) by each effect's
    ``start_from``.

    An effect whose ``name`` is already in the model (``"stiffness"``, ``"stribeck"``)
    replaces it.
    """
    return {key: cls.start_from(values) for key, cls in registry().items()}


__all__ = [
    "AbstractEffect",
    "AbstractFriction",
    "AbstractReading",
    "AbstractSpring",
    "ArmGravity",
    "AsymmetricStribeckFriction",
    "AsymmetricViscousFriction",
    "BackEmfBraking",
    "Candidate",
    "CoulombFriction",
    "CubicStiffness",
    "DahlHysteresis",
    "FreePlayStiffness",
    "Gravity",
    "GravityLoadFriction",
    "KinematicErrorStiffness",
    "LinearStiffness",
    "LoadDependentFriction",
    "keys",
    "library",
    "registry",
    "Motion",
    "Parameter",
    "PositionRipple",
    "ReadingAge",
    "ScalePrior",
    "Scales",
    "StartValues",
    "StribeckFriction",
    "ThreeSegmentStiffness",
    "TorqueOffset",
    "ViscousFriction",
    "parameter",
    "positive_power",
    "same_parameter",
]
