"""The public API, locked: what ``dir(hdid)`` offers and how each callable is called.

Issue 20 moves every module; a user's code must not notice. A change here is a change of
the public API: make it on purpose, in this file and in the README, never by accident.
(After pyhf's ``tests/test_public_api.py``.)
"""

from __future__ import annotations

import inspect
import subprocess
import sys

import hdid

PUBLIC = [
    "AbstractEffect", "AbstractFriction", "AbstractSpring", "AsymmetricStribeckFriction", "AsymmetricViscousFriction",
    "CoulombFriction", "CubicStiffness", "DEFAULT_INERTIA", "DEFAULT_RATIO", "DahlHysteresis",
    "DesignResult", "Diagnosis", "DrivenFitResult", "DrivenJoint", "FitError", "FitResult",
    "FreePlayStiffness", "Gravity", "HdidError", "KinematicErrorStiffness",
    "LinearStiffness", "LoadDependentFriction", "Log", "LogError", "Model", "Motion",
    "Parameter", "PositionRipple", "PositionalError", "PosteriorResult", "Run", "Scales", "StribeckFriction",
    "ThreeSegmentStiffness", "TorqueOffset", "ViscousFriction", "__version__", "bare_figures",
    "configure", "design", "diagnose", "effects", "fit", "fit_driven", "fit_joint", "fit_many", "model_ladder", "read_log",
    "sample_posterior", "save_figure", "simulate", "simulate_driven", "write_log",
]

#: The first arguments of each public function, by position, then the keywords a user may
#: pass. Added keywords are fine (append them here); renamed or removed ones break users.
CALLS = {
    "fit": ["log", "model"],
    "fit_many": ["logs"],
    "fit_driven": ["log", "model"],
    "fit_joint": ["logs", "model"],
    "diagnose": ["log", "model"],
    "model_ladder": ["log", "models"],
    "read_log": ["source"],
    "write_log": ["path", "runs"],
    "simulate": ["model", "times", "theta0", "t_release"],
    "simulate_driven": ["joint", "times", "motor_torque", "load_torque"],
    "sample_posterior": ["fit"],
    "design": ["fit", "candidates"],
}
KEYWORDS = {
    "fit": {"inertia", "fix", "free_inertia", "inertia_prior", "release_time",
            "counts_per_rev", "ratio", "resolution", "n_starts", "max_substep", "max_steps",
            "start_from_model", "nested"},
    "fit_driven": {"order", "max_order", "fix", "counts_per_rev", "torque_constant",
                   "output_counts_per_rev", "max_substep", "max_steps", "input_hold"},
    "sample_posterior": {"seed", "progress", "prior", "default_prior", "log"},
    "design": {"targets", "criterion", "check", "check_candidate", "seed"},
    "fit_many": {"progress", "vectorize", "band_bracket", "workers", "client", "executor",
                 "chunk_size"},
}


def test_dir_is_the_public_api():
    assert sorted(dir(hdid)) == sorted(PUBLIC)
    for name in PUBLIC:
        assert getattr(hdid, name) is not None, name


def test_public_functions_keep_their_calls():
    for name, positional in CALLS.items():
        params = inspect.signature(getattr(hdid, name)).parameters
        names = list(params)
        assert names[: len(positional)] == positional, (name, names)
        missing = KEYWORDS.get(name, set()) - set(names)
        assert not missing, f"hdid.{name} lost keyword(s) {sorted(missing)}"


def test_every_figure_is_drawn_into_ax_and_never_saved():
    """One plotting convention (lmfit's ``plot(ax=None)``): every figure method takes the
    axes to draw into as the keyword ``ax`` and no path (saving is ``hdid.save_figure``)."""
    from hdid._posterior import PosteriorResult

    methods = [getattr(cls, m) for cls in (hdid.FitResult, hdid.DrivenFitResult,
                                           hdid.Diagnosis, PosteriorResult, hdid.DesignResult)
               for m in dir(cls) if m.startswith("plot")]
    assert len(methods) >= 8
    for f in methods:
        params = inspect.signature(f).parameters
        assert "path" not in params and "axes" not in params, f.__qualname__
        assert params["ax"].kind is inspect.Parameter.KEYWORD_ONLY, f.__qualname__
        assert params["ax"].default is None, f.__qualname__


def test_version_comes_from_the_installed_package():
    from importlib.metadata import version

    assert hdid.__version__ == version("hdid")


def test_bare_import_loads_no_numerics():
    """``import hdid`` stays instant: JAX, equinox and matplotlib load on first use."""
    code = ("import sys, hdid; hdid.__version__; "
            "print(sorted(m for m in ('jax', 'equinox', 'matplotlib', 'pandas') if m in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]", out.stdout
