"""The numbers hdid gives on every shipped log, to lock them through a restructuring.

Issue 20 (architecture) moves every file; its rule is "same numbers before and after".
``python tests/reference_numbers.py --write`` records, at one commit, the fits of every
shipped log (free-motion fits, the driven fit, the joint fit and the EMPS real log) into
``tests/data/reference_numbers.json`` (``--write NAME …`` re-records some, after a change
that is meant to move numbers; ``_recorded_at`` keeps each case's commit);
``tests/test_reference_numbers.py`` refits them and compares every number.

Two tolerances (``compare``):

- default (CI, any CPU): ``|a − b| ≤ 1e-3 · scale``. For a fitted parameter the scale is its
  standard error σ: the optimiser stops at a relative cost change of 1e-8 (``_fit.py``,
  rtol = atol = 1e-8); with a cost of ~25 (χ² units) that leaves ~2.5e-7 of χ², i.e.
  ≈ √2.5e-7 ≈ 5e-4 σ along the flattest direction — so a thousandth of σ is what another
  CPU's arithmetic may move, and far below anything a user could read. For every other
  number the scale is the largest magnitude among its siblings (the same matrix, list or
  table), so near-zero entries of a covariance matrix are judged on the matrix's scale.
- exact (``HDID_REFERENCE_EXACT=1``, same machine as the recording): relative 1e-10 — a
  pure move of code does not change one floating-point operation.

In default mode a multistart start that the recording marks *not converged* is compared
by its cost only (``starts/costs``, ``starts/dchi2_to_best``), not by where it stopped
(``starts/parameter_values/*/i``, ``starts/iterations/i``, ``starts/converged/i``): such
a start was stopped by the schedule part-way along a path through a flat valley, and that
path depends on the order of XLA's sums, hence on the cores the process may use. Measured
(2026-11-25): the hidden-hysteresis log fitted in a process pinned to one core moved
start 1's k1 from 1009 to 985 and ran start 3 to convergence in 58 iterations instead of
stopping it after 312, with the result (start 0, converged) unchanged; the 2-core CI run
matches the 2-core recording. Exact mode compares them all.

Not recorded: wall times, versions, file hashes, module paths of effect classes (they move
by design), the posterior (issue 17 changes its sampler) and ``diagnose`` (issue 19 changes
its rules).
"""

from __future__ import annotations

import json
import math
import re
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SYN = ROOT / "data" / "synthetic"
EMPS = ROOT.parent / "shared" / "data" / "real" / "emps"  # never copied into the repository
STORE = Path(__file__).resolve().parent / "data" / "reference_numbers.json"

#: Keys never compared: time, provenance, and code locations that move by design.
SKIP = {"wall_time_s", "hdid_version", "input", "inputs", "source", "model", "options",
        "schema_version"}
DEFAULT_RTOL = 1e-3
EXACT_RTOL = 1e-10


def _cases():
    """name → callable returning a result's ``to_dict()``."""
    import hdid

    free = {
        "csf8_paper": lambda: hdid.fit(SYN / "csf8_paper.csv"),
        "csf8_paper_counts": lambda: hdid.fit(SYN / "csf8_paper_counts.csv", counts_per_rev=4000),
        "csf8_rich_1khz": lambda: hdid.fit(SYN / "csf8_rich_1khz.csv"),
        "hidden_hysteresis_1khz": lambda: hdid.fit(SYN / "hidden_hysteresis_1khz.csv"),
        "emps_train": lambda: hdid.fit_driven(EMPS / "emps_train.csv", _emps_model()),
        "driven_csf8": lambda: hdid.fit_driven(SYN / "driven_csf8.csv"),
        "joint_paper_driven": lambda: hdid.fit_joint(
            [SYN / "csf8_paper.csv", SYN / "driven_csf8.csv"]),
    }
    return {k: (lambda f=f: f().to_dict()) for k, f in free.items()}


def _emps_model():
    """``hdid fit emps_train.csv --ratio 1 --add torque_offset``, as the CLI builds it."""
    import hdid

    model = hdid.Model.default().with_ratio(1.0)
    return model.with_effect(hdid.effects.library(model.float_values())["torque_offset"])


def _walk(obj, path, out, scale=None):
    """Flatten ``obj`` into ``out``: path → (value, scale); strings kept as they are."""
    if isinstance(obj, dict):
        if path and path[-1] in SKIP:
            return
        for k, v in obj.items():
            if k in SKIP:
                continue
            if isinstance(v, dict) and "value" in v and "std" in v:
                std = v.get("std")
                ok = isinstance(std, (int, float)) and math.isfinite(std) and std > 0
                val_scale = std if ok else None
                for kk, vv in v.items():
                    _walk(vv, path + (str(k), kk), out, val_scale if kk == "value" else None)
            else:
                _walk(v, path + (str(k),), out)
    elif isinstance(obj, (list, tuple)):
        flat = [x for x in _numbers(obj)]
        sib = max((abs(x) for x in flat if math.isfinite(x)), default=None)
        for i, v in enumerate(obj):
            _walk(v, path + (str(i),), out, sib if scale is None else scale)
    elif isinstance(obj, bool) or obj is None or isinstance(obj, str):
        out["/".join(path)] = (obj, None)
    elif isinstance(obj, (int, float)):
        out["/".join(path)] = (float(obj), scale)
    else:  # pragma: no cover - to_dict() is JSON-like
        raise TypeError(f"{'/'.join(path)}: {type(obj).__name__}")


def _numbers(obj):
    for v in obj:
        if isinstance(v, (list, tuple)):
            yield from _numbers(v)
        elif isinstance(v, (int, float)) and not isinstance(v, bool):
            yield float(v)


def flatten(d: dict) -> dict:
    out: dict = {}
    _walk(d, (), out)
    return out


def _encode(x):
    if isinstance(x, float) and not math.isfinite(x):
        return repr(x)  # "nan", "inf", "-inf": strict JSON
    return x


def _decode(x):
    if x in ("nan", "inf", "-inf"):
        return float(x)
    return x


def record(name: str) -> dict:
    return {k: [_encode(v), s] for k, (v, s) in flatten(_cases()[name]()).items()}


def _unconverged_start_keys(stored: dict) -> set[str]:
    """Keys of where the recording's unconverged starts stopped (see the module's text)."""
    out = set()
    for key, (value, _) in stored.items():
        m = re.fullmatch(r"(.*starts)/converged/(\d+)", key)
        if m and value is False:
            head, i = m.groups()
            out |= {f"{head}/converged/{i}", f"{head}/iterations/{i}"}
            out |= {k for k in stored if re.fullmatch(rf"{re.escape(head)}/parameter_values/[^/]+/{i}", k)}
    return out


def compare(stored: dict, now: dict, exact: bool) -> list[str]:
    """Differences between a stored and a fresh flattening, one line each."""
    bad = []
    rtol = EXACT_RTOL if exact else DEFAULT_RTOL
    path_dependent = set() if exact else _unconverged_start_keys(stored)
    for key in sorted(set(stored) | set(now)):
        if key in path_dependent:
            continue
        if key not in now:
            bad.append(f"{key}: recorded, now missing")
            continue
        if key not in stored:
            bad.append(f"{key}: new, not recorded")
            continue
        (a, sa), (b, _) = stored[key], now[key]
        a, b = _decode(a), _decode(b)
        if isinstance(a, float) and isinstance(b, float):
            if math.isnan(a) or math.isnan(b) or math.isinf(a) or math.isinf(b):
                if not (a == b or (math.isnan(a) and math.isnan(b))):
                    bad.append(f"{key}: {a!r} → {b!r}")
                continue
            scale = sa if (sa is not None and not exact) else max(abs(a), abs(b))
            if abs(a - b) > rtol * scale:
                bad.append(f"{key}: {a!r} → {b!r} (|Δ| {abs(a - b):.3g} > {rtol:g}·{scale:.3g})")
        elif a != b:
            bad.append(f"{key}: {a!r} → {b!r}")
    return bad


def main(argv):
    if argv[:1] != ["--write"]:
        print(__doc__)
        return 2
    names = argv[1:] or list(_cases())
    store = json.loads(STORE.read_text()) if STORE.exists() else {}
    import subprocess

    commit = subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"],
                            capture_output=True, text=True).stdout.strip()
    import time

    STORE.parent.mkdir(exist_ok=True)
    for name in names:
        t0 = time.perf_counter()
        store[name] = record(name)
        print(f"{name}: {len(store[name])} numbers, {time.perf_counter() - t0:.1f} s")
        at = store.get("_recorded_at")
        at = at if isinstance(at, dict) else {k: at for k in store if not k.startswith("_")}
        at[name] = commit
        store["_recorded_at"] = at
        STORE.write_text(json.dumps(store, indent=0, sort_keys=True) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
