"""The floor-level rule's effect on the independent suite's verdicts (a stated subset).

    taskset -c 1 python benchmarks/diagnose_floor_rule.py [--seeds 8801,9803]

The rule (:func:`hdid._diagnosis._verdict._rivals`): a strong candidate of another family
that, like the best, brings the residual to the floor is a rival unless the likelihood
alone favours the best by 10. It only acts where the best is strong and reaches the floor
and a strong candidate of another family also does, more than ΔBIC 10 behind (else it
was a rival already). So only those logs of ``benchmarks/results/diagnose_independent.json``
can change verdict; every other log's verdict is the same by construction (and no
``adequate`` verdict changes: the false-alarm rates of ``calibration/diagnose_rates.py``
stand). Each affected log is made again (the suite's draw) and diagnosed with the
candidates that matter — every strong one of the stored record (the first run refitted
only the best and its floor-level rivals: on a log already ``ambiguous`` by a rival within
ΔBIC 10 that rival was then missing, rows 9802/9902) — with ``design=False`` (the verdict
only); the stored full-suite verdict is the "before".
Results: benchmarks/results/diagnose_floor_rule.{json,md}, the load next to each row.
"""

from __future__ import annotations

import argparse
import json
import os
import time

import numpy as np
from _common import RESULTS, run_meta

import diagnose_independent as di
from hdid.reference import logs

FAMILY = {"ripple": "position-periodic", "kinematic_error": "position-periodic"}
NAME = "diagnose_floor_rule"


def affected(records):
    """Stored records where the rule can act: (record, candidate keys to refit)."""
    out = []
    for r in records:
        c = [x for x in r.get("candidates") or [] if x["delta_bic"] < -10]
        if not c or c[0]["rms_after_floor"] > 1.3 or c[0].get("adequate_after") is False:
            continue
        b = c[0]
        fam = FAMILY.get(b["effect"], b["effect"])
        riv = [x for x in c[1:] if FAMILY.get(x["effect"], x["effect"]) != fam
               and x["rms_after_floor"] <= 1.3 and x["delta_bic"] - b["delta_bic"] >= 10]
        if riv:  # every strong candidate: the stored verdict's own rivals are among them
            out.append((r, [x["effect"] for x in c],
                        min(x["delta_bic"] for x in riv) - b["delta_bic"]))
    # the smallest ΔBIC gaps first (the likeliest to change): a partial run holds those
    return [(r, k) for r, k, _ in sorted(out, key=lambda x: x[2])]


def main(argv=None) -> int:
    import hdid

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", help="only these seeds (comma-separated)")
    args = ap.parse_args(argv)
    stored = json.loads((RESULTS / "diagnose_independent.json").read_text())["records"]
    todo = affected(stored)
    if args.seeds:
        want = {int(s) for s in args.seeds.split(",")}
        todo = [(r, k) for r, k in todo if r["seed"] in want]
    import sys

    res = {"meta": run_meta(command="python " + " ".join(["benchmarks/diagnose_floor_rule.py",
                                                          *sys.argv[1:]])), "rows": []}
    for rec, keys in todo:
        design, seed, name = rec["design"], rec["seed"], rec["hidden"]
        truth, des = di.draw(design, seed)
        hp = (di.hidden_params(name, truth, des, np.random.default_rng(seed + 10_000))
              if name != "none" else {})
        kw = logs.reference_kwargs(name, truth, **hp) if name != "none" else None
        df = logs.make_log(truth, **{k: v for k, v in des.items() if k != "gear_factor"},
                          seed=seed, hidden=kw)
        t = time.perf_counter()
        d = hdid.diagnose(df, candidates=keys, design=False)
        row = {"design": design, "seed": seed, "hidden": name, "candidates": keys,
               "before": {"verdict": rec["verdict"], "named": rec["named"]},
               "after": {"verdict": d.verdict, "named": di._named(d), "summary": d.summary},
               "table": [(c.key, c.delta_bic, c.rms_after_rad / d.floor_rad)
                         for c in d.candidates if c.error is None],
               "wall_s": time.perf_counter() - t, "load1": os.getloadavg()[0]}
        res["rows"].append(row)
        print(design, seed, name, rec["named"], "->", row["after"]["named"],
              f"{row['wall_s']:.0f}s load {row['load1']:.1f}", flush=True)
        _write(res)
    _write(res)
    return 0


def render_only() -> None:
    """Re-write the md from the JSON (after a hand-added ``meta.note``)."""
    res = json.loads((RESULTS / f"{NAME}.json").read_text())
    (RESULTS / f"{NAME}.md").write_text(render(res))


def _write(res):
    (RESULTS / f"{NAME}.json").write_text(json.dumps(res, indent=1, default=float) + "\n")
    (RESULTS / f"{NAME}.md").write_text(render(res))


def render(res) -> str:
    m = res["meta"]
    L = ["# The floor-level rule on the independent suite (affected logs only)", "",
         f"{m.get('cpu', '')}; src {m.get('src', '')}; `{m.get('command', '')}`. "
         "Before: the stored full-suite verdict (benchmarks/results/diagnose_independent.md); "
         "after: diagnose with the candidates listed, design=False. "
         "Every other log of the suite cannot change verdict (module docstring).", "",
         *([m["note"], ""] if m.get("note") else []),
         "| design | seed | hidden | candidates | before | after | ΔBIC (RMS/floor) after | s | load |",
         "|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        tab = ", ".join(f"{k} {b:.1f} ({x:.2f})" for k, b, x in r["table"])
        L.append(f"| {r['design']} | {r['seed']} | {r['hidden']} | {', '.join(r['candidates'])} "
                 f"| {r['before']['named']} | {r['after']['named']} | {tab} | "
                 f"{r['wall_s']:.0f} | {r['load1']:.1f} |")
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    raise SystemExit(main())
