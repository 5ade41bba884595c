"""Is the truth of a calibration log consistent with hdid's model? (issue 17)

For each log of a ``posterior_sbc.py`` result file: regenerate it (the independent
simulator, same design and seed), fit it freely, and fit it with the seven physical
parameters held at the truth (release times and set-up offsets refitted). Δχ² = data χ²
(q²/12 units, the fit's weights) at the truth minus the free fit's. A truth consistent with
hdid's model gives ≈ χ²₇ (95 % point 14.07); far above it, the simulator and the model
disagree at that truth (no sampler can cover it); below zero, the multistart fit ended in a
poorer basin than the truth's. Coverage misses of the calibration are printed beside it.

    python benchmarks/posterior_truth_chi2.py benchmarks/results/posterior_sbc_tau50.json \
        [--seeds 10600-10619,9600-9609] [--name posterior_truth_chi2]

Writes ``benchmarks/results/NAME.{json,md}``.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import argparse
import json
import os
import time
from pathlib import Path

RESULTS = Path(__file__).resolve().parent / "results"
PHYSICAL = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v")
POOLED = ("k1", "k2", "tau_c", "tau_s", "c_v", "stick_band_halfwidth_rad")
CHI2_7_95 = 14.07


def _seeds(text):
    out = set()
    for part in text.split(","):
        a, _, b = part.partition("-")
        out.update(range(int(a), int(b or a) + 1))
    return out


def data_chi2(fit):
    import numpy as np

    p = fit.problem
    r = np.asarray(fit.predict()) - np.asarray(p.theta)
    return float(np.sum(np.asarray(p.weight) * r * r) / (float(p.step) ** 2 / 12))


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("sbc_json", type=Path)
    ap.add_argument("--seeds", default=None, help="e.g. 10600-10619,9600-9609 (default: all)")
    ap.add_argument("--name", default="posterior_truth_chi2")
    args = ap.parse_args(argv)
    import hdid

    hdid.configure()
    gen = _common.import_generate()
    logs = json.loads(args.sbc_json.read_text())["logs"]
    want = _seeds(args.seeds) if args.seeds else None
    rows = []
    for log in logs:
        if "quantities" not in log or (want is not None and log["seed"] not in want):
            continue
        t = dict(log["truth_params"])
        d = dict(gen.RICH_DESIGN if log["design"] == "rich" else gen.PAPER_DESIGN)
        d["seed"] = log["seed"]
        df, _ = gen.make_log(t, **d, return_truth=True)
        t0 = time.perf_counter()
        free = hdid.fit(df, inertia=t["inertia"])
        held = hdid.fit(df, inertia=t["inertia"], fix={n: t[n] for n in PHYSICAL})
        row = {"design": log["design"], "seed": log["seed"], "chi2_free": data_chi2(free),
               "chi2_truth": data_chi2(held), "fit_s": time.perf_counter() - t0,
               "load": [round(x, 2) for x in os.getloadavg()],
               "misses": [n for n in POOLED if not log["quantities"][n]["cover95"]],
               "truth": {n: t[n] for n in PHYSICAL},
               "free_fit": {n: float(free.values[n]) for n in PHYSICAL}}
        row["delta_chi2"] = row["chi2_truth"] - row["chi2_free"]
        rows.append(row)
        print(row["design"], row["seed"], f"{row['delta_chi2']:.2f}", row["misses"], flush=True)
    res = {"source": str(args.sbc_json), "chi2_7_95": CHI2_7_95, "rows": rows}
    (RESULTS / f"{args.name}.json").write_text(json.dumps(res, indent=1))
    L = [f"# Δχ² of the truth under hdid's model (`{args.sbc_json.name}`)\n",
         "Data χ² (q²/12 units) with the 7 physical parameters held at the truth (release "
         "times, offsets refitted) minus the free fit's; consistent truths ≈ χ²₇ (95 % point "
         f"{CHI2_7_95}). One process, loads per row in the JSON.\n",
         "| design | seed | Δχ² | truth v_s | truth δ | calibration misses (95 %) |",
         "|---|---|---|---|---|---|"]
    for r in rows:
        flag = " **(> χ²₇ 95 %)**" if r["delta_chi2"] > CHI2_7_95 else (" (< 0)" if r["delta_chi2"] < 0 else "")
        L.append(f"| {r['design']} | {r['seed']} | {r['delta_chi2']:.1f}{flag} | "
                 f"{r['truth']['v_s']:.3g} | {r['truth']['delta']:.2f} | "
                 f"{', '.join(r['misses']) or '–'} |")
    (RESULTS / f"{args.name}.md").write_text("\n".join(L) + "\n")


if __name__ == "__main__":
    main()
