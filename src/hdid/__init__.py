"""hdid — identify the physics of a harmonic drive from encoder logs.

Heavy modules (jax, equinox) load on first use so that ``hdid --help`` stays fast.
Importing hdid changes no process-wide setting: hdid's own calls compute in float64
(thread-local); :func:`hdid.configure` sets up a whole process (the CLI calls it).
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING

from ._version import __version__

_LAZY = {
    "fit": "._fitting._fit",
    "fit_many": "._fitting._batch",
    "sample_posterior": "._posterior",
    "PosteriorResult": "._posterior",
    "FitResult": "._results._result",
    "Model": "._models._model",
    "DEFAULT_INERTIA": "._models._model",
    "DEFAULT_RATIO": "._models._model",
    "simulate": "._simulation._simulate",
    "read_log": "._log",
    "write_log": "._log",
    "Log": "._log",
    "Run": "._log",
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
    "diagnose": "._diagnosis._diagnose",
    "design": "._design._design",
    "DesignResult": "._design._result",
    "Diagnosis": "._diagnosis._diagnose",
    "model_ladder": "._diagnosis._ladder",
    "fit_driven": "._fitting._driven_fit",
    "fit_joint": "._fitting._driven_fit",
    "DrivenFitResult": "._results._driven_result",
    "DrivenJoint": "._simulation._driven",
    "simulate_driven": "._simulation._driven",
    "PositionalError": "._models._positional",
    "configure": "._config",
    "save_figure": "._results._plot",
    "bare_figures": "._results._plot",
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
    from ._fitting._batch import fit_many
    from ._config import configure
    from ._posterior import PosteriorResult, sample_posterior
    from ._diagnosis._diagnose import Diagnosis, diagnose
    from ._diagnosis._ladder import model_ladder
    from ._design._design import design
    from ._design._result import DesignResult
    from ._simulation._driven import DrivenJoint, simulate_driven
    from ._fitting._driven_fit import fit_driven, fit_joint
    from ._results._driven_result import DrivenFitResult
    from ._models._positional import PositionalError
    from ._fitting._fit import fit
    from ._log import Log, Run, read_log, write_log
    from ._models._model import DEFAULT_INERTIA, DEFAULT_RATIO, Model
    from ._results._result import FitResult
    from ._simulation._simulate import simulate
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
