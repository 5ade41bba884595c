"""hdid — identify the physics of a harmonic drive from encoder logs.

Heavy modules (jax, equinox) load on first use so that ``hdid --help`` stays fast.
Importing hdid changes no process-wide setting: hdid's own calls compute in float64
(thread-local); :func:`hdid.configure` sets up a whole process (the CLI calls it).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING


def _version() -> str:
    from importlib.metadata import PackageNotFoundError, version

    try:
        return version("hdid")
    except PackageNotFoundError:  # a source tree on sys.path, not installed
        return "0+unknown"


__version__ = _version()

_LAZY = {
    "fit": "._fit",
    "fit_many": "._batch",
    "sample_posterior": "._posterior",
    "FitResult": "._result",
    "Model": "._model",
    "DEFAULT_INERTIA": "._model",
    "DEFAULT_RATIO": "._model",
    "simulate": "._simulate",
    "read_log": "._io",
    "write_log": "._io",
    "Log": "._io",
    "Run": "._io",
    "LogError": "._errors",
    "FitError": "._errors",
    "HdidError": "._errors",
    "AbstractEffect": ".effects",
    "AbstractFriction": ".effects",
    "AbstractSpring": ".effects",
    "Parameter": ".effects",
    "Scales": ".effects",
    "Motion": ".effects",
    "CubicStiffness": ".effects",
    "StribeckFriction": ".effects",
    "ViscousFriction": ".effects",
    "DahlHysteresis": ".effects",
    "FreePlayStiffness": ".effects",
    "AsymmetricStribeckFriction": ".effects",
    "AsymmetricViscousFriction": ".effects",
    "Gravity": ".effects",
    "LoadDependentFriction": ".effects",
    "PositionRipple": ".effects",
    "ThreeSegmentStiffness": ".effects",
    "KinematicErrorStiffness": ".effects",
    "LinearStiffness": ".effects",
    "TorqueOffset": ".effects",
    "CoulombFriction": ".effects",
    "effects": ".effects",
    "diagnose": "._diagnose",
    "Diagnosis": "._diagnose",
    "model_ladder": "._diagnose",
    "fit_driven": "._driven_fit",
    "fit_joint": "._driven_fit",
    "DrivenFitResult": "._driven_result",
    "DrivenJoint": "._driven",
    "simulate_driven": "._driven",
    "PositionalError": "._positional",
    "configure": "._config",
    "save_figure": "._plot",
    "bare_figures": "._plot",
}

#: Public functions that compute with JAX: they run in float64 (thread-local, see
#: :func:`hdid._config.float64`) whatever the caller's JAX precision.
_FLOAT64 = frozenset({
    "fit", "fit_many", "fit_driven", "fit_joint", "simulate", "simulate_driven",
    "diagnose", "model_ladder", "sample_posterior",
})

__all__ = sorted(_LAZY)


def __getattr__(name: str):
    if name in _LAZY:
        module = importlib.import_module(_LAZY[name], __name__)
        value = module if name == "effects" else getattr(module, name)
        if name in _FLOAT64:
            from ._config import float64

            value = float64(value)
        globals()[name] = value
        return value
    raise AttributeError(f"module 'hdid' has no attribute {name!r}")


def __dir__():
    return [*__all__, "__version__"]


if TYPE_CHECKING:  # pragma: no cover
    from . import effects
    from ._errors import FitError, HdidError, LogError
    from ._batch import fit_many
    from ._config import configure
    from ._posterior import sample_posterior
    from ._diagnose import Diagnosis, diagnose, model_ladder
    from ._driven import DrivenJoint, simulate_driven
    from ._driven_fit import fit_driven, fit_joint
    from ._driven_result import DrivenFitResult
    from ._positional import PositionalError
    from ._fit import fit
    from ._io import Log, Run, read_log, write_log
    from ._model import DEFAULT_INERTIA, DEFAULT_RATIO, Model
    from ._result import FitResult
    from ._simulate import simulate
    from .effects import (
        AbstractEffect,
        AbstractFriction,
        AbstractSpring,
        AsymmetricStribeckFriction,
        AsymmetricViscousFriction,
        CoulombFriction,
        CubicStiffness,
        DahlHysteresis,
        FreePlayStiffness,
        Gravity,
        KinematicErrorStiffness,
        LinearStiffness,
        LoadDependentFriction,
        Motion,
        Parameter,
        PositionRipple,
        Scales,
        StribeckFriction,
        ThreeSegmentStiffness,
        TorqueOffset,
        ViscousFriction,
    )
