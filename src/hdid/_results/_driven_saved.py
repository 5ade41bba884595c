"""A driven or joint fit's JSON read back: :meth:`hdid.DrivenFitResult.load`.

The file is what :meth:`~hdid.DrivenFitResult.save` and ``hdid fit DRIVEN.csv --json``
write (schema ``hdid/schema/driven.schema.json``). The fitted joint comes back whole (the
WG model from its structure, the output friction, the positional error's coefficients);
the log does not, so what was computed from it (the units check, the kinematic-error
split, the input hold) is kept as the file gives it, and the figures of the runs need a
refit.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np

from .._errors import HdidError
from ._saved import SCHEMA_VERSION, load_complete, model_from_structure
from ._summaries import ParameterEstimate


def _num(x, default: float = math.nan) -> float:
    """A JSON number back to float: ``null`` (a NaN or infinity written) as ``default``."""
    return default if x is None else float(x)


def _covariance(block: dict) -> tuple[list[str], np.ndarray]:
    """Names and covariance; ``null`` on the diagonal is an undetermined variance (inf),
    elsewhere a product with one (NaN): the correlation the result derives is the same."""
    names = list(block["parameters"])
    m = np.array([[_num(x) for x in row] for row in block["matrix"]], dtype=float)
    m = m.reshape(len(names), len(names))
    diag = np.diag(m).copy()
    np.fill_diagonal(m, np.where(np.isnan(diag), math.inf, diag))
    return names, m


def _joint(d: dict, effects):
    from .._models._positional import PositionalError
    from .._simulation._driven import DrivenJoint

    model = model_from_structure(d["model"], effects)
    order = int(d["model"]["positional_error_order"])
    coeffs = (d.get("positional_error") or {}).get("coefficients") or {}
    if coeffs:
        c = {n: _num(v["value"]) for n, v in coeffs.items()}
        pos = PositionalError(c["pos_a0"], [c[f"pos_a{n}"] for n in range(1, order + 1)],
                              [c[f"pos_b{n}"] for n in range(1, order + 1)])
    else:  # no output angle logged: the order was set, its coefficients not fitted
        pos = PositionalError.zeros(order)
    return DrivenJoint(model, float(d["model"]["output_friction_tau_fout"]), pos)


def load(path, effects: dict | None, cls):
    """A ``cls`` (:class:`~hdid.DrivenFitResult`) from its JSON; see the module docstring."""
    try:
        d = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise HdidError(f"{path}: cannot read it as hdid driven-fit JSON ({exc})") from None
    if not isinstance(d, dict) or d.get("kind") not in ("driven", "joint"):
        raise HdidError(f"{path}: not the JSON of an hdid driven or joint fit (written by "
                        "`hdid fit DRIVEN.csv --json` or DrivenFitResult.save); a free-motion "
                        "fit's is read by FitResult.load")
    if d.get("schema_version", 0) > SCHEMA_VERSION:
        raise HdidError(f"{path}: written by a newer hdid ({d.get('hdid_version')}); upgrade hdid")
    return load_complete(path, lambda: _load(d, effects, cls), "driven-fit",
                         "hdid fit DRIVEN.csv --json or DrivenFitResult.save")


def _load(d: dict, effects, cls):
    params = {
        n: ParameterEstimate(name=n, value=_num(p["value"]),
                             std=0.0 if p["fixed"] else _num(p["std"], math.inf),
                             unit=p["unit"], fixed=bool(p["fixed"]), note=p.get("note", ""))
        for n, p in d["parameters"].items()
    }
    positional = dict(d.get("positional_error") or {})
    if "bic" in positional:  # JSON keys are strings; the orders are integers
        positional["bic"] = {int(k): _num(v) for k, v in positional["bic"].items()}
    names, cov = _covariance(d["covariance"])
    inputs = d.get("inputs") or [d["input"]]
    return cls(
        source=d["source"], kind=d["kind"], joint=_joint(d, effects), parameters=params,
        positional=positional, rms={k: _num(v) for k, v in d["rms"].items()},
        correlation={tuple(k.split("~", 1)): _num(v) for k, v in d["correlations"].items()},
        warnings=list(d["warnings"]), notes=list(d["notes"]),
        data=None, problem=None, u=np.zeros(0), covariance=np.zeros((0, 0)), labels=[],
        order_bic=positional.get("bic") or None, chi2_reduced=_num(d.get("chi2_reduced")),
        wall_time_s=_num(d.get("wall_time_s")), sources=[i["path"] for i in inputs],
        covariance_names=names, parameter_covariance=cov,
        input_sha256={i["path"]: i["sha256"] for i in inputs},
        options=dict(d.get("options") or {}), hdid_version=d.get("hdid_version"),
        saved={"units_problem": d.get("units_problem"),
               "kinematic_split": d.get("kinematic_error_split") or {},
               "input_hold": d["model"].get("input_hold", "zoh")},
    )
