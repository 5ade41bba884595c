"""Two ``posterior_sbc.py`` result files on the same seeds, log by log (issue 17, ``post6``).

Run::

    python benchmarks/posterior_sbc_pair.py A.json B.json [--labels plain,friction] > out.md
    python benchmarks/posterior_sbc_pair.py --split RUN.json   # RUN_plain.json, RUN_friction.json

``--split``: one ``posterior_sbc.py --coordinates plain,friction`` file into one file per
coordinates (then pair those; ``posterior_sbc.py --render`` renders each).

Per seed: R-hat max, ESS bulk/tail min, τ_max, chain length in τ_max, wall time, the
independence move's acceptance and how many of the six checked quantities the 95 %
interval holds; then pooled coverage and convergence counts under both criteria of the
issue: arviz (R-hat ≤ 1.01 and bulk/tail ESS ≥ 400 everywhere) and the ensemble one
(chain ≥ 50 τ_max and bulk/tail ESS ≥ 400 everywhere). Only seeds present in both.
"""

from __future__ import annotations

import json
import statistics
import sys

CHECKED = ("k1", "k2", "tau_c", "tau_s", "c_v", "stick_band_halfwidth_rad")


def _cp(k, n, a=0.05):
    from scipy.stats import beta

    lo = beta.ppf(a / 2, k, n - k + 1) if k > 0 else 0.0
    hi = beta.ppf(1 - a / 2, k + 1, n - k) if k < n else 1.0
    return lo, hi


def split(path):
    from pathlib import Path

    res = json.load(open(path))
    for c in sorted({r.get("coordinates") for r in res["logs"]} - {None}):
        out = dict(res, logs=[r for r in res["logs"] if r.get("coordinates") == c])
        Path(path).with_name(Path(path).stem + f"_{c}.json").write_text(json.dumps(out, indent=1))


def main(argv):
    if argv[0] == "--split":
        return split(argv[1])
    labels = ["A", "B"]
    if "--labels" in argv:
        i = argv.index("--labels")
        labels = argv[i + 1].split(",")
        argv = argv[:i] + argv[i + 2:]
    runs = [{r["seed"]: r for r in json.load(open(p))["logs"] if "error" not in r} for p in argv[:2]]
    seeds = sorted(set(runs[0]) & set(runs[1]))
    print(f"# Paired: {labels[0]} ({argv[0]}) vs {labels[1]} ({argv[1]}), {len(seeds)} seeds\n")
    print("| seed | " + " | ".join(f"{l}: R-hat / ESS b,t / τ_max / steps÷τ / s / indep. acc. / 95 % held"
                                   for l in labels) + " |")
    print("|---|---|---|")
    stats = {l: {"arviz": 0, "tau50": 0, "cover": 0, "n": 0, "tau": [], "s": [],
                 "per": {q: 0 for q in CHECKED}} for l in labels}
    for s in seeds:
        cells = []
        for l, R in zip(labels, runs):
            r = R[s]
            ess = min(r["ess_bulk_min"], r["ess_tail_min"])
            k = r["steps"] / r["tau_max"]
            held = sum(r["quantities"][q]["cover95"] for q in CHECKED)
            st = stats[l]
            st["arviz"] += r["rhat_max"] <= 1.01 and ess >= 400
            st["tau50"] += k >= 50 and ess >= 400
            st["cover"] += held
            st["n"] += 1
            st["tau"].append(r["tau_max"])
            st["s"].append(r["posterior_s"])
            for q in CHECKED:
                st["per"][q] += r["quantities"][q]["cover95"]
            acc = r["move_acceptance"].get("independence (mixture)", float("nan"))
            cells.append(f"{r['rhat_max']:.3f} / {r['ess_bulk_min']:.0f},{r['ess_tail_min']:.0f} / "
                         f"{r['tau_max']:.0f} / {k:.0f} / {r['posterior_s']:.0f} / {acc:.3f} / {held}")
        print(f"| {s} | " + " | ".join(cells) + " |")
    print()
    for l in labels:
        st = stats[l]
        n = st["n"]
        lo, hi = _cp(st["cover"], 6 * n)
        print(f"- **{l}**: converged (arviz) {st['arviz']}/{n}; (≥ 50 τ and ESS ≥ 400) "
              f"{st['tau50']}/{n}; pooled 95 % coverage {st['cover']}/{6 * n} = "
              f"{100 * st['cover'] / (6 * n):.1f} % [{100 * lo:.1f}, {100 * hi:.1f}] ("
              + ", ".join(f"{q.replace('stick_band_halfwidth_rad', 'band')} {c}/{n}"
                          for q, c in st["per"].items())
              + f"); τ_max median {statistics.median(st['tau']):.0f}; "
              f"sample_posterior median {statistics.median(st['s']):.0f} s")


if __name__ == "__main__":
    main(sys.argv[1:])
