"""``hdid design`` on the shipped paper log: the ranking, the top candidate's predicted
stds, and the prediction checked against the spread of fits of simulated logs.

    taskset -c 1 python benchmarks/design_check.py [--n 30]

1. Fit data/synthetic/csf8_paper.csv (hdid.fit defaults), rank the default candidates by
   the std of tau_c, tau_s, v_s and the band (``targets``).
2. Speed: 20 candidates (the 17 defaults and 3 user ones), cold (first call of the
   process, programs possibly from the store) and warm (second call).
3. Simulate ``--n`` logs of the top candidate and of the paper design at the fit (random
   release phase, the fit's encoder step), fit each with hdid.fit, and compare the
   predicted std with the fits' spread for k1, tau_c, tau_s and the band. Criterion:
   within 25 % (the sample std of 30 values is itself uncertain by 1/sqrt(2*29) = 13 %).
   Where a candidate's linearisation is flagged, the table says so.
Results: benchmarks/results/design_check.{json,md}, the load average next to each timing.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time

from _common import DATA, RESULTS, cpu_model, load, src_fingerprint

QUANTITIES = ("k1", "tau_c", "tau_s", "stick_band_halfwidth_rad")
TARGETS = "tau_c,tau_s,v_s,band"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser()
    ap.add_argument("--n", type=int, default=30)
    args = ap.parse_args(argv)
    import hdid
    from hdid._design import _candidates, _check, _rank

    res = {"benchmark": "design_check", "src": src_fingerprint(), "cpu": cpu_model(),
           "loads": [load("start")], "n": args.n}
    t = time.perf_counter()
    fit = hdid.fit(DATA / "csf8_paper.csv")
    res["fit_s"] = time.perf_counter() - t
    base = _candidates.baseline(fit)
    extra = [dict(name="rate x8", rate=8 * base.rate),
             dict(name="amplitude x1.25", amplitudes=[1.25 * a for a in base.amplitudes]),
             dict(name="repeats x3", repeats=3)]
    cands = _candidates.default_candidates(base, fit.model)[1:] + _candidates.load_candidates(extra, base)
    timings = []
    for label in ("cold", "warm", "warm"):
        res["loads"].append(load(f"before {label}"))
        t = time.perf_counter()
        d20 = hdid.design(fit, cands, targets=TARGETS)
        timings.append({"call": label, "n_candidates": len(d20.predictions),
                        "seconds": time.perf_counter() - t, **load(label)})
    res["speed"] = timings
    d = hdid.design(fit, targets=TARGETS)
    res["report"] = d.report()
    res["ranking"] = [{"candidate": d.predictions[i].experiment.name, "score_ratio": math.exp(s)
                       if math.isfinite(s) else None} for i, s in d.ranking]
    best = d.best
    res["top"] = {"name": best.experiment.name, "describe": best.experiment.describe(),
                  "std": {k: _rank.std_of(best, k) for k in ("tau_c", "tau_s", "v_s",
                                                            "stick_band_halfwidth_rad")},
                  "std_this_log": {k: _rank.std_of(d.current, k) for k in
                                   ("tau_c", "tau_s", "v_s", "stick_band_halfwidth_rad")},
                  "linearisation": best.honesty}
    res["checks"] = []
    for p in (best, d.current):
        names = tuple(dict.fromkeys([*p.names, "stick_band_halfwidth_rad"]))
        pred = {k: _rank.std_of(p, k) for k in names}
        res["loads"].append(load(f"before check {p.experiment.name}"))
        c = _check.run(fit, p.experiment, pred, args.n, seed=1, names=names)
        row = c.to_dict()
        row["linearisation"] = p.honesty
        row["within_25pct"] = {k: (abs(c.ratio(k) - 1.0) <= 0.25 if math.isfinite(c.ratio(k))
                                   else None) for k in QUANTITIES}
        row["load"] = load(f"after check {p.experiment.name}")
        res["checks"].append(row)
        _write(res)
    res["loads"].append(load("end"))
    _write(res)
    print((RESULTS / "design_check.md").read_text())
    return 0


def _write(res):
    (RESULTS / "design_check.json").write_text(json.dumps(res, indent=2, allow_nan=False,
                                                          default=_nan) + "\n")
    (RESULTS / "design_check.md").write_text(render(res))


def _nan(x):
    return None


def _fmt(x):
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "n/a"
    return f"{x:.3g}"


def render(res) -> str:
    L = ["# hdid design on the shipped paper log (data/synthetic/csf8_paper.csv)", "",
         f"src {res['src']}, {res['cpu']}, pinned to one core (taskset -c 1); fit {res['fit_s']:.1f} s", ""]
    L += ["## Speed (20 candidates)", "", "| call | candidates | s | load 1/5/15 |", "|---|---|---|---|"]
    for t in res.get("speed", []):
        L.append(f"| {t['call']} | {t['n_candidates']} | {t['seconds']:.2f} | "
                 f"{t['load1']:.2f} / {t['load5']:.2f} / {t['load15']:.2f} |")
    L += ["", f"## Ranking by {TARGETS} (geometric-mean std ratio to this log)", "", "```",
          res.get("report", ""), "```", ""]
    top = res.get("top")
    if top:
        L += [f"Top candidate: **{top['name']}** ({top['describe']})", "",
              "| quantity | predicted std, top | predicted std, this log |", "|---|---|---|"]
        for k, v in top["std"].items():
            L.append(f"| {k} | {_fmt(v)} | {_fmt(top['std_this_log'][k])} |")
        L.append("")
    for c in res.get("checks", []):
        L += [f"## Check: {c['n_fitted']} of {c['n_logs']} simulated logs of '{c['experiment']}' "
              f"fitted ({c['seconds']:.0f} s, load {c['load']['load1']:.2f})", "",
              "| quantity | truth | mean fit | spread | predicted | predicted/spread | within 25 % |",
              "|---|---|---|---|---|---|---|"]
        for k, q in c["quantities"].items():
            w = c["within_25pct"].get(k, "")
            L.append(f"| {k} | {_fmt(q['truth'])} | {_fmt(q['mean'])} | {_fmt(q['spread'])} | "
                     f"{_fmt(q['predicted'])} | {_fmt(q['predicted_over_spread'])} | "
                     f"{'' if w == '' else ('yes' if w else ('no' if w is False else 'n/a'))} |")
        L += ["", f"fits above 3x the floor: {c['fits_above_floor']}; failures: {len(c['failures'])}",
              "linearisation flags: " + ("; ".join(c["linearisation"]) or "none"), ""]
    if res.get("interpretation"):
        L += ["## Interpretation", "", res["interpretation"]]
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    sys.exit(main())
