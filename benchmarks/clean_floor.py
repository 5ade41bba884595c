"""Clean logs of an independent simulator (``tests/independent.py``), broad plant per log:
how many fits end above 1.5× the quantization floor ``step/√12`` (a poorer optimum).

    taskset -c 1 python benchmarks/clean_floor.py rich --seeds 0:200 [--append] [--label after]
    PYTHONPATH=<other tree>/src taskset -c 1 python benchmarks/clean_floor.py rich --label before --append
    python benchmarks/clean_floor.py --report
"""

import argparse
import json
import math
import os
import subprocess
import sys
import time
from collections import Counter
from pathlib import Path

import numpy as np
from _common import RESULTS, ROOT

import hdid

sys.path.insert(0, str(ROOT / "tests"))
import independent as ind  # noqa: E402  (pure numpy/scipy, no hdid)

OUT = RESULTS / "clean_floor.json"
#: a fit above this multiple of the quantization floor has not reached the floor
ABOVE = 1.5
K2_CATALOG = 6.5e7
DESIGNS = {"paper": dict(amps=[0.157, -0.157, 0.157, -0.157], rate=250.0, duration=0.5, setups=list("AABB")),
           "rich": dict(amps=[0.157, -0.157, 0.12, -0.12, 0.08, -0.08, 0.05, -0.05], rate=1000.0, duration=0.3,
                        setups=list("AAAABBBB"))}
SEED_BASE = {"paper": 330000, "rich": 331000}


def draw_plant(rng: np.random.Generator) -> ind.Plant:
    """One broad plant (the ranges: benchmarks/README.md)."""
    N = 100.0
    k1, k2 = 940.0 * rng.uniform(0.6, 1.4), K2_CATALOG * rng.uniform(0.0, 2.0)
    tau_s = k1 / N**2 * rng.uniform(0.012, 0.040)  # the wave generator's stiffness times a small angle
    tau_c = tau_s / rng.uniform(1.1, 2.0)
    v_s = math.exp(rng.uniform(math.log(2.0), math.log(20.0)))
    delta = rng.uniform(0.8, 3.0)
    c_v = 1.8e-5 * math.exp(rng.uniform(-0.5, 0.5) * math.log(10.0))
    return ind.Plant(inertia=7e-7, ratio=N, k1=k1, k2=k2, tau_c=tau_c, tau_s=tau_s, v_s=v_s, delta=delta, c_v=c_v)


def make(design: str, seed: int):
    """``(DataFrame, truth)`` of log ``seed`` of ``design``."""
    d, rng = DESIGNS[design], np.random.default_rng(SEED_BASE[design] + seed)
    plant = draw_plant(rng)
    offsets = {s: float(rng.uniform(-0.03, 0.03)) for s in sorted(set(d["setups"]))}
    phases = rng.uniform(0.0, 1.0, len(d["amps"]))
    return ind.make_log(plant, d["amps"], rate=d["rate"], duration=d["duration"], hold=0.04,
                        setups=d["setups"], offsets=offsets, counts_per_rev=4000, release_phase=list(phases), seed=seed)


def fit_one(design: str, seed: int) -> dict:
    df, truth = make(design, seed)
    t0, row = time.perf_counter(), {"design": design, "seed": seed, "truth": truth["params"]}
    try:
        r = hdid.fit(df, resolution=truth["resolution"], ratio=100.0)
    except Exception as exc:  # a failed fit is a row too
        return row | {"error": f"{type(exc).__name__}: {exc}"[:300], "ratio": math.nan,
                      "wall_s": time.perf_counter() - t0}
    return row | {"wall_s": time.perf_counter() - t0, "ratio": r.rms_residual_rad / r.quantization_floor_rad,
                  "values": r.values, "limits": getattr(r, "limits", None),
                  "restarted_from": getattr(r, "restarted_from", None), "n_warnings": len(r.warnings)}


#: Rows at or below this ratio keep no truth or fitted values in the results file (the
#: truth is redrawn from the seed; the fit is at the floor): the file stays small.
KEEP_DETAIL_ABOVE = 1.2


def _slim(row: dict) -> dict:
    """A row as stored: floats to 6 digits; the truth, the values and each limit's whole
    record only where the fit missed the floor (or raised), else each limit's Δχ²."""
    keep = "error" in row or not row.get("ratio", math.inf) <= KEEP_DETAIL_ABOVE
    rnd = lambda v: float(f"{v:.6g}") if isinstance(v, float) else (  # noqa: E731
        {k: rnd(x) for k, x in v.items()} if isinstance(v, dict) else v)
    out = {k: rnd(v) for k, v in row.items() if keep or k not in ("truth", "values", "limits")}
    if not keep and isinstance(row.get("limits"), list):  # each limit's Δχ² to the fit
        out["limits"] = {x["limit"]: rnd(x.get("dchi2")) for x in row["limits"]}
    return out


def _save(rows: list[dict]) -> None:
    OUT.write_text('{"rows": [\n' + ",\n".join(json.dumps(_slim(r), default=float) for r in rows) + "\n]}\n")
    OUT.with_suffix(".md").write_text(render(rows))


def render(rows: list[dict]) -> str:
    out = ["# Clean logs from an independent simulator: fits above 1.5× the floor", "",
           "See `benchmarks/clean_floor.py` for the plant ranges and designs. One row per (label, design); a fit "
           f"counts as *above* when its RMS residual exceeds {ABOVE}× the quantization floor (step/√12), *error* "
           "when it raised.", "", "| label | design | logs | above 1.5× | rate | errors | median ratio | max ratio "
           "| median wall [s] | load (1 min) | limit restarts that won |",
           "|---|---|---|---|---|---|---|---|---|---|---|"]
    groups: dict = {}
    for r in rows:
        groups.setdefault((r.get("label", "?"), r["design"]), []).append(r)
    for (label, design), g in sorted(groups.items()):
        ratio, err = np.array([x["ratio"] for x in g], dtype=float), sum("error" in x for x in g)
        above = int(np.sum(ratio[np.isfinite(ratio)] > ABOVE))
        won = Counter(x["restarted_from"] for x in g if x.get("restarted_from"))
        loads = [x.get("load1") for x in g if x.get("load1") is not None]
        out.append(f"| {label} | {design} | {len(g)} | {above} | {100 * above / len(g):.1f} % | {err} | "
                   f"{np.nanmedian(ratio):.3f} | {np.nanmax(ratio):.3f} | {np.median([x['wall_s'] for x in g]):.1f} | "
                   f"{np.median(loads) if loads else math.nan:.2f} | "
                   f"{', '.join(f'{k} {v}' for k, v in sorted(won.items())) or '—'} |")
    out += ["", "Logs above 1.5× (label, design, seed: ratio):", ""]
    out += [f"- {r.get('label')}, {r['design']}, {r['seed']}: {r['ratio']:.3f} {r.get('error', '')}"
            for r in rows if not r["ratio"] <= ABOVE]
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("designs", nargs="*", default=["paper", "rich"])
    ap.add_argument("--seeds", default="0:200", help="first:stop, or log indices comma-separated (e.g. earlier misses)")
    ap.add_argument("--label", default="after")
    ap.add_argument("--append", action="store_true", help="keep the rows already stored")
    ap.add_argument("--report", action="store_true", help="only rewrite the .md")
    a = ap.parse_args(argv)
    rows = json.loads(OUT.read_text())["rows"] if OUT.exists() else []
    if a.report:
        _save(rows)
        return 0
    if not a.append:
        rows = [r for r in rows if r.get("label") != a.label]
    src = Path(hdid.__file__).parent
    head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=src, capture_output=True, text=True).stdout.strip()
    seeds = range(*map(int, a.seeds.split(":"))) if ":" in a.seeds else [int(x) for x in a.seeds.split(",")]
    for seed in seeds:
        for design in a.designs:
            if any(r.get("label") == a.label and r["design"] == design and r["seed"] == seed for r in rows):
                continue
            rows.append(row := fit_one(design, seed) | dict(label=a.label, hdid=str(src), commit=head,
                                                             load1=os.getloadavg()[0]))
            print(f"{a.label} {design} {seed}: ratio {row['ratio']:.3f} {row['wall_s']:.1f} s load {row['load1']:.2f} "
                  f"{row.get('restarted_from') or ''} {row.get('error', '')}", flush=True)
            _save(rows)
    _save(rows)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
