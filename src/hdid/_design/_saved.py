"""A design's result as a file: :meth:`DesignResult.save` writes ``to_dict()`` as strict
JSON (schema ``hdid/schema/design.schema.json``); :meth:`DesignResult.load` rebuilds the
result from it — the same report, the same JSON and the same plot.

JSON has no NaN or infinity: they are written as ``null``, and ``non_finite`` maps the
JSON pointer (RFC 6901) of each such ``null`` to ``"nan"``, ``"inf"`` or ``"-inf"``, so
that load restores the exact value (an undetermined std is ``inf``, a quantity not
computed ``nan``: the report prints them differently). A file without that map (written
before it existed) reads ``null`` as ``inf`` in stds, scores and separations, and as
``nan`` elsewhere."""

from __future__ import annotations

import json
import math
from pathlib import Path

from .._errors import HdidError
from ._candidates import Experiment
from ._check import CheckResult
from ._fisher import Prediction

#: what writes a design file (the fix named by every error)
_WRITERS = "hdid design --json or DesignResult.save"

#: the other hdid files, told apart by a field only they have: (test, what, loader)
_OTHERS = (
    (lambda d: d.get("kind") in ("driven", "joint"), "a driven or joint fit",
     "DrivenFitResult.load"),
    (lambda d: "verdict" in d, "a diagnosis", "Diagnosis.load"),
    (lambda d: "model" in d and "parameters" in d, "a fit", "FitResult.load"),
)


def non_finite(d) -> dict[str, str]:
    """``{JSON pointer: "nan" | "inf" | "-inf"}`` of every non-finite float in ``d``."""
    out: dict[str, str] = {}

    def walk(x, at: str) -> None:
        if isinstance(x, float) and not math.isfinite(x):
            out[at] = repr(x)
        elif isinstance(x, dict):
            for k, v in x.items():
                walk(v, f"{at}/{str(k).replace('~', '~0').replace('/', '~1')}")
        elif isinstance(x, (list, tuple)):
            for i, v in enumerate(x):
                walk(v, f"{at}/{i}")

    walk(d, "")
    return out


def save(result, path) -> None:
    try:
        Path(path).write_text(json.dumps(result.to_dict(), indent=2, allow_nan=False) + "\n")
    except OSError as exc:
        raise HdidError(f"{path}: cannot write ({exc.strerror or exc})") from None


def load(path, cls, version: int):
    path = Path(path)
    if not path.is_file():
        raise HdidError(f"{path}: no such file (a design JSON, written by {_WRITERS})")
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError, UnicodeDecodeError) as exc:
        raise HdidError(f"{path}: cannot read it as a design JSON ({exc}); write one with "
                        f"{_WRITERS}") from None
    if not isinstance(d, dict) or d.get("kind") != "design":
        other = next(((w, f) for test, w, f in _OTHERS if isinstance(d, dict) and test(d)), None)
        which = f"the JSON of {other[0]}: load it with {other[1]}" if other else "not hdid's JSON"
        raise HdidError(f"{path}: not a design file ({which}); a design file is written by "
                        f"{_WRITERS}")
    if not isinstance(d.get("schema_version"), int) or d["schema_version"] > version:
        raise HdidError(f"{path}: a design file of layout {d.get('schema_version')!r} (hdid "
                        f"{d.get('hdid_version')}); this hdid reads layout {version} or older: "
                        "upgrade hdid")
    try:
        _restore(d, d.get("non_finite") or {})
        preds = [_prediction(c) for c in d["candidates"]]
        return cls(
            source=d["source"], criterion=d["criterion"], targets=tuple(d["targets"]),
            values=_floats(d["values"], math.nan), derived=_floats(d["derived"], math.nan),
            predictions=preds,
            ranking=[(int(r["index"]), _num(r["score"])) for r in d["ranking"]],
            noise_rad=_num(d.get("noise_beyond_quantization_rad"), math.nan),
            check=None if d.get("check") is None else _check(d["check"]),
            warnings=list(d.get("warnings", [])),
            wall_time_s=_num(d.get("wall_time_s"), math.nan))
    except KeyError as exc:
        raise HdidError(f"{path}: a design file without the field {exc}; write it again with "
                        f"{_WRITERS}") from None
    except (TypeError, ValueError, IndexError, AttributeError, HdidError) as exc:
        raise HdidError(f"{path}: a design file with a bad field ({exc}); write it again "
                        f"with {_WRITERS}") from None


def _restore(d: dict, marks: dict) -> None:
    """Put each ``non_finite`` value back where the file has its ``null``."""
    for pointer, text in marks.items():
        keys = [k.replace("~1", "/").replace("~0", "~") for k in pointer.split("/")[1:]]
        if not keys:
            continue
        node = d
        for k in keys[:-1]:
            node = node[int(k)] if isinstance(node, list) else node[k]
        last = int(keys[-1]) if isinstance(node, list) else keys[-1]
        if node[last] is None:
            node[last] = float(text)


def _num(x, default: float = math.inf) -> float:
    return default if x is None else float(x)


def _floats(d: dict, default: float = math.inf) -> dict[str, float]:
    return {k: _num(v, default) for k, v in d.items()}


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
        prior_ratio=_floats(c.get("posterior_over_prior", {}), math.nan),
        derived_std=_floats(c.get("derived_std", {})), names=tuple(std),
        n_effective=_num(c.get("n_effective"), math.nan),
        sigma=_num(c.get("noise_rad"), math.nan),
        error=c.get("error"), honesty=list(c.get("linearisation", [])),
        separation=None if c.get("expected_2lnlr") is None else (
            _num(c["expected_2lnlr"]["a_true"]), _num(c["expected_2lnlr"]["b_true"])),
        separation_kind=(c.get("expected_2lnlr") or {}).get("value_kind"))


def _check(c: dict) -> CheckResult:
    q = c["quantities"]

    def column(key: str) -> dict[str, float]:  # a null without a mark: not computed
        return {k: float(v[key]) for k, v in q.items() if v.get(key) is not None}

    return CheckResult(
        experiment=c["experiment"], n_logs=int(c["n_logs"]), n_fitted=int(c["n_fitted"]),
        mean=column("mean"), spread=column("spread"), truth=column("truth"),
        predicted={k: _num(v.get("predicted")) for k, v in q.items()},
        failures=list(c.get("failures", [])), above_floor=int(c.get("fits_above_floor", 0)),
        seconds=_num(c.get("seconds"), math.nan))
