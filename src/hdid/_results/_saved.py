"""A fit's results as a file that can be reused: the JSON written by ``hdid fit --json`` and
:meth:`FitResult.save`, read back by :meth:`FitResult.load` and ``hdid simulate --from``.

The JSON carries, next to the numbers of the report, what is needed to reuse them: the
model's structure (each effect's class and field values, the gear ratio, the inertia), the
parameters' correlation and covariance matrices, the hdid version, the input file's SHA-256
and the options of the fit. Its schema is ``hdid/schema/fit.schema.json`` (:func:`schema`).
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import json
import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from .._errors import HdidError
from ._summaries import ParameterEstimate, RunSummary, StartSummary
from .._models._model import Model

#: Version of the JSON layout; raised when a field changes meaning or goes away.
SCHEMA_VERSION = 1


#: The JSON files hdid writes, each with its schema in ``hdid/schema/<kind>.schema.json``.
SCHEMA_KINDS = ("fit", "driven", "diagnose", "design")


def schema(kind: str = "fit") -> dict:
    """The JSON Schema (draft 2020-12) of a JSON file hdid writes, shipped with the
    package: ``"fit"`` (``hdid fit --json``, :meth:`FitResult.save`), ``"driven"`` (a
    driven or joint fit), ``"diagnose"`` (``hdid diagnose --json``) or ``"design"``
    (``hdid design --json``, :meth:`DesignResult.save`)."""
    from importlib.resources import files

    if kind not in SCHEMA_KINDS:
        raise ValueError(f"schema {kind!r}: choose one of {', '.join(SCHEMA_KINDS)}")
    return json.loads(files("hdid").joinpath(f"schema/{kind}.schema.json").read_text())


def finite(obj):
    """JSON has no NaN/inf: write them as null (numpy scalars and arrays as Python's)."""
    if isinstance(obj, np.ndarray):
        obj = obj.tolist()
    if isinstance(obj, np.generic):
        obj = obj.item()
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {k: finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [finite(v) for v in obj]
    return obj


def sha256(path) -> str | None:
    """SHA-256 of a file's bytes, or None when ``path`` is not a readable file."""
    try:
        if not os.path.isfile(path):
            return None
        h = hashlib.sha256()
        with open(path, "rb") as fh:
            for chunk in iter(lambda: fh.read(1 << 20), b""):
                h.update(chunk)
        return h.hexdigest()
    except (OSError, TypeError, ValueError):
        return None


def hdid_version() -> str:
    from .._version import __version__

    return __version__


def model_structure(model) -> dict[str, Any]:
    """Effects (class, module, parameters, field values), gear ratio and inertia."""
    effects = []
    for e in model.effects:
        cls = type(e)
        values: dict[str, Any] = {}
        for f in dataclasses.fields(e):
            if not f.init:
                continue
            v = getattr(e, f.name)
            try:
                values[f.name] = float(v)
            except (TypeError, ValueError):
                values[f.name] = repr(v)
        effects.append({
            "name": e.name,
            "class": cls.__name__,
            "module": cls.__module__,
            "library": cls.__module__.startswith("hdid."),
            "parameters": [p.name for p in e.parameters],
            "fields": values,
        })
    return {"gear_ratio": float(model.ratio), "inertia": float(model.inertia), "effects": effects}


def model_from_structure(d: dict, classes: dict | None = None):
    """Rebuild the :class:`~hdid.Model` that :func:`model_structure` described.

    ``classes`` maps class names to your own effect classes (those not in hdid)."""
    effects = []
    for e in d["effects"]:
        cls = (classes or {}).get(e["class"])
        if cls is None:
            if not e.get("library", str(e.get("module", "")).startswith("hdid.")):
                raise HdidError(
                    f"effect {e['name']!r} is your own class {e['class']} (module "
                    f"{e['module']}); pass it: FitResult.load(path, effects={{'{e['class']}': "
                    f"{e['class']}}})"
                )
            try:  # a library class by its public name (its file may have moved)
                from .. import effects as library

                cls = getattr(library, e["class"], None) or getattr(
                    importlib.import_module(e["module"]), e["class"])
            except (ImportError, AttributeError):
                raise HdidError(
                    f"effect {e['name']!r}: class {e['class']} is not in this hdid "
                    f"({hdid_version()}); the file was written by hdid {d.get('hdid_version', '?')}"
                ) from None
        effects.append(cls(**e["fields"]))
    return Model(effects=tuple(effects), inertia=d["inertia"], ratio=d["gear_ratio"])


def free_names(result) -> list[str]:
    return [n for n, p in result.parameters.items() if not p.fixed]


def correlation_matrix(result) -> tuple[list[str], np.ndarray]:
    """Free parameters and their full (symmetric) correlation matrix."""
    names = free_names(result)
    c = np.eye(len(names))
    for i, a in enumerate(names):
        for j, b in enumerate(names):
            if i != j:
                c[i, j] = result.correlation.get((a, b), result.correlation.get((b, a), np.nan))
    return names, c


def covariance_matrix(result) -> tuple[list[str], np.ndarray]:
    """Free parameters and their covariance in physical units, ``r_ij·σ_i·σ_j``
    (the linearised covariance behind the report's std; inf where undetermined)."""
    names, c = correlation_matrix(result)
    s = np.array([result.parameters[n].std for n in names], dtype=float)
    with np.errstate(invalid="ignore"):
        cov = c * np.outer(s, s)
    return names, cov


def provenance(result) -> dict[str, Any]:
    """Where a fit came from and what it was: layout and hdid version, the input file and
    its SHA-256, the options as given, the model's structure, and the free parameters'
    full correlation and covariance matrices. The same fields in the fit, driven and
    diagnose JSON (for a diagnosis, those of its base fit)."""
    names, corr = correlation_matrix(result)
    _, cov = covariance_matrix(result)
    units = [result.parameters[n].unit for n in names]
    source = result.source
    digest = getattr(result, "input_sha256", None) or sha256(source)
    return {
        "schema_version": SCHEMA_VERSION,
        "hdid_version": getattr(result, "hdid_version", None) or hdid_version(),
        "input": {"path": source, "sha256": digest},
        "options": dict(getattr(result, "options", None) or {}),
        "model": model_structure(result.model),
        "correlation": {"parameters": names, "matrix": corr.tolist()},
        "covariance": {"parameters": names, "units": units, "matrix": cov.tolist()},
    }


def extras(result) -> dict[str, Any]:
    """What the fit JSON holds beyond the report: see the module docstring."""
    return {
        **provenance(result),
        "resolution_known": bool(result.resolution_known),
        "sample_period_s": float(result.sample_period),
    }


def save(result, path) -> None:
    Path(path).write_text(json.dumps(finite(result.to_dict()), indent=2) + "\n")


def load(path, effects: dict | None, cls):
    """A ``cls`` (:class:`~hdid.FitResult`) from its JSON (without the log: no
    predict/plot). The class comes from :meth:`FitResult.load`: this module is below the
    results and does not import them."""
    return load_complete(path, lambda: _load(path, effects, cls), "fit",
                         "hdid fit LOG.csv --json or FitResult.save",
                         (KeyError, TypeError, IndexError))


def load_complete(path, load, what: str, how: str,
                  missing=(KeyError, TypeError, ValueError, IndexError)):
    """``load()``, or the one-line error of a saved ``what`` file that lacks a field its
    loader needs (a field missing or of the wrong type), saying how to write one."""
    try:
        return load()
    except missing as exc:
        raise HdidError(f"{path}: not a complete hdid {what} JSON ({type(exc).__name__}: "
                        f"{exc}); write it with {how}") from None


def _load(path, effects, FitResult):

    try:
        d = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise HdidError(f"{path}: cannot read it as hdid fit JSON ({exc})") from None
    if not isinstance(d, dict) or "model" not in d or "parameters" not in d:
        raise HdidError(
            f"{path}: not the JSON of one hdid fit (written by `hdid fit --json` or "
            "FitResult.save; a batch JSON is a list: load its entries one by one)"
        )
    if d.get("kind") in ("driven", "joint") or "verdict" in d:
        what = f"a {d['kind']} fit" if "kind" in d else "a diagnosis (hdid diagnose --json)"
        raise HdidError(
            f"{path}: the JSON of {what}; FitResult.load and hdid simulate --from read the "
            "JSON of a free-motion fit (hdid fit LOG.csv --json)"
        )
    if d.get("schema_version", 0) > SCHEMA_VERSION:
        raise HdidError(f"{path}: written by a newer hdid ({d.get('hdid_version')}); upgrade hdid")

    def num(x, default=math.nan):
        return default if x is None else float(x)

    params = {
        n: ParameterEstimate(name=n, value=num(p["value"]),
                             std=0.0 if p["fixed"] else num(p["std"], math.inf),
                             unit=p["unit"], fixed=p["fixed"], note=p.get("note", ""))
        for n, p in d["parameters"].items()
    }
    run_fields = {f.name for f in dataclasses.fields(RunSummary)}
    runs = [RunSummary(**{k: (num(v) if isinstance(v, (int, float)) or v is None else v)
                          for k, v in r.items() if k in run_fields}) for r in d["runs"]]
    for r in runs:
        r.n_samples, r.stuck_at_end = int(r.n_samples), bool(r.stuck_at_end)
    st = d["starts"]
    starts = StartSummary(
        costs=np.array([num(c, math.inf) for c in st["costs"]]),
        converged=np.array(st["converged"], dtype=bool),
        steps=np.array(st["iterations"]),
        values={n: np.array([num(x) for x in v]) for n, v in st.get("parameter_values", {}).items()},
        best=int(st.get("best", int(np.argmin([num(c, math.inf) for c in st["costs"]])))),
    )
    names = d["correlation"]["parameters"]
    corr = np.array([[num(x) for x in row] for row in d["correlation"]["matrix"]]).reshape(len(names), len(names))
    resolution = num(d.get("resolution"), num(d["quantization_floor_rad"]) * math.sqrt(12))
    kwargs = dict(
        source=d["source"],
        model=model_from_structure(d["model"], effects),
        parameters=params,
        derived={k: (num(v["value"]), num(v["std"], math.inf)) for k, v in d["derived"].items()},
        runs=runs,
        setups={s: num(v["offset"]) for s, v in d["setups"].items()},
        rms_residual_rad=num(d["rms_residual_rad"]),
        resolution_rad=resolution,
        resolution_known=bool(d.get("resolution_known", True)),
        sample_period=num(d.get("sample_period_s")),
        n_effective=num(d["effective_observations"]),
        n_unknowns=int(d["unknowns"]),
        noise_scale=num(d["noise_scale_vs_quantization"]),
        correlation={(a, b): float(corr[i, j]) for i, a in enumerate(names)
                     for j, b in enumerate(names) if i < j},
        warnings=list(d["warnings"]),
        starts=starts,
        problem=None,
        u=np.zeros(0),
        covariance=np.zeros((0, 0)),
        labels=[],
        band_bracket=tuple(d["stick_band_bracket_rad"]) if d.get("stick_band_bracket_rad") else None,
        wall_time_s=num(d.get("wall_time_s")),
        input_sha256=d.get("input", {}).get("sha256"),
        options=d.get("options") or {},
        hdid_version=d.get("hdid_version"),
    )
    # Fields added to FitResult later and written under their own name (forward compatible).
    for f in dataclasses.fields(FitResult):
        if f.name not in kwargs and f.name in d:
            kwargs[f.name] = d[f.name]
    kwargs = {k: v for k, v in kwargs.items() if k in {f.name for f in dataclasses.fields(FitResult)}}
    kwargs["first_reading_held"] = tuple(kwargs.get("first_reading_held") or ())
    result = FitResult(**kwargs)
    # the limit checks are attributes the fit sets (hdid._fitting._fit.nested_check)
    result.limits, result.restarted_from = list(d.get("limits") or []), d.get("restarted_from")
    return result
