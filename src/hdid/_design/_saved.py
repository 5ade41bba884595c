"""A design's result as a file: :meth:`DesignResult.save` writes ``to_dict()`` as JSON
(schema ``hdid/schema/design.schema.json``); :meth:`DesignResult.load` rebuilds the
result from it — the same report and the same JSON. ``null`` in the file (JSON has no
infinity) reads back as ``inf``: an undetermined std, or a score with a target left
undetermined."""

from __future__ import annotations

import json
import math
from pathlib import Path

from .._errors import HdidError
from ._candidates import Experiment
from ._check import CheckResult
from ._fisher import Prediction


def save(result, path) -> None:
    try:
        Path(path).write_text(json.dumps(result.to_dict(), indent=2, allow_nan=False) + "\n")
    except OSError as exc:
        raise HdidError(f"{path}: cannot write ({exc.strerror or exc})") from None


def load(path, cls):
    path = Path(path)
    if not path.is_file():
        raise HdidError(f"{path}: no such file (a design JSON from hdid design --json)")
    try:
        d = json.loads(path.read_text())
    except (ValueError, UnicodeDecodeError) as exc:
        raise HdidError(f"{path}: not a JSON file ({exc})") from None
    if not isinstance(d, dict) or d.get("kind") != "design":
        raise HdidError(f"{path}: not a design file of hdid (written by hdid design --json or "
                        "DesignResult.save); load it with the type that wrote it")
    try:
        preds = [_prediction(c) for c in d["candidates"]]
        return cls(
            source=d["source"], criterion=d["criterion"], targets=tuple(d["targets"]),
            values=_floats(d["values"]), derived=_floats(d["derived"]), predictions=preds,
            ranking=[(int(r["index"]), _num(r["score"])) for r in d["ranking"]],
            noise_rad=_num(d.get("noise_beyond_quantization_rad")),
            check=None if d.get("check") is None else _check(d["check"]),
            warnings=list(d.get("warnings", [])), wall_time_s=_num(d.get("wall_time_s")))
    except (KeyError, TypeError, ValueError, HdidError) as exc:
        raise HdidError(f"{path}: a design file with a missing or bad field ({exc})") from None


def _num(x) -> float:
    return math.inf if x is None else float(x)


def _floats(d: dict) -> dict[str, float]:
    return {k: _num(v) for k, v in d.items()}


def _prediction(c: dict) -> Prediction:
    e = c["experiment"]
    exp = Experiment(
        name=e["name"], amplitudes=tuple(e["amplitudes"]), rate=e["rate_hz"],
        duration=e["duration_s"], hold=e["hold_s"], resolution=e["resolution_rad"],
        added_inertia=tuple(e["added_inertia"]), setups=tuple(e["setups"]),
        offsets=e["offsets"], note=e["note"], releases=tuple(e.get("releases") or ()))
    std = _floats(c["std"])
    return Prediction(
        experiment=exp, std=std, std_data=_floats(c.get("std_data_only", {})),
        prior_ratio=_floats(c.get("posterior_over_prior", {})),
        derived_std=_floats(c.get("derived_std", {})), names=tuple(std),
        n_effective=_num(c.get("n_effective")), sigma=_num(c.get("noise_rad")),
        error=c.get("error"), honesty=list(c.get("linearisation", [])),
        separation=None if c.get("expected_2lnlr") is None else (
            _num(c["expected_2lnlr"]["a_true"]), _num(c["expected_2lnlr"]["b_true"])),
        separation_kind=(c.get("expected_2lnlr") or {}).get("value_kind"))


def _check(c: dict) -> CheckResult:
    q = c["quantities"]
    return CheckResult(
        experiment=c["experiment"], n_logs=int(c["n_logs"]), n_fitted=int(c["n_fitted"]),
        mean={k: _num(v.get("mean")) for k, v in q.items()},
        spread={k: _num(v.get("spread")) for k, v in q.items()},
        predicted={k: _num(v.get("predicted")) for k, v in q.items()},
        truth={k: _num(v.get("truth")) for k, v in q.items()},
        failures=list(c.get("failures", [])), above_floor=int(c.get("fits_above_floor", 0)),
        seconds=_num(c.get("seconds")))
