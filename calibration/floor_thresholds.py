"""How far above the measured rounding floor does a *correct* model's fit land? The
calibration of ``hdid diagnose``'s floor warning (issue 19; the decision: ``docs/decisions/floor-threshold.md``).

Clean logs simulated from a fitted base model exactly as ``diagnose_rates.py``
makes them (hdid's simulator, the same 4000-count encoder, a random sub-sample release
instant per run; the model fitted to the design's seed-9001 log), with seeds
``SEED0 + i`` (default 5000 + i: none of the calibration's 1000 + i): the base model is
fitted as ``diagnose`` first fits it (``FULL_GRID_STARTS`` grid starts) and its χ²
compared with the floor a correct model leaves on that log, ``F``
(:func:`hdid._diagnosis._floor.fit_floor`: mean ± sd over grid phases), and with the
white-noise floor ``n − k``. The independent suite's two clean logs per design (another
generator, other plants) are fitted too, for comparison only.

The threshold per design is an order statistic of its N clean logs' χ²/F
(:func:`hdid._diagnosis._excess.choose`): the ``j``-th largest, ``j`` the largest for which
the false-warning rate is ≤ 5 % at 95 % confidence. Why that: the clean logs' ratios are
exchangeable with a new clean log's, so the probability ``p`` that a new one exceeds the
``j``-th largest of N is distributed as Beta(j, N + 1 − j) over the calibration's draws
(mean j/(N + 1); Wilks 1941), whose 95 % quantile is exactly the one-sided
Clopper–Pearson bound of j − 1 exceedances in N logs
(:func:`hdid._diagnosis._rates.upper_bound`). ``j = 1`` (the largest) needs N ≥ 59; 200
logs allow ``j = 5``. ``diagnose`` reports the ratio of the base it ends with (after the
restarts from the candidates' optima, which can only lower its χ²), so a clean log's
warning rate is at most this.

    taskset -c 1 python calibration/floor_thresholds.py [N] [paper|rich ...] [--seed0 S] [--append]
    taskset -c 1 python calibration/floor_thresholds.py --hidden [paper|rich ...]
    taskset -c 1 python calibration/floor_thresholds.py --diagnose paper SEED ...
    python calibration/floor_thresholds.py --threshold   # the generated block, nothing run
    python calibration/floor_thresholds.py --render

``--hidden``: the base fits of the independent suite's 36 logs (``benchmarks/diagnose_independent.py``'s
seeds 8800/8900/9800/9900 + i, the hidden effect drawn as there), each with the threshold
of its design and the suite's verdict on it (``benchmarks/results/diagnose_independent.json``): what the
warning would say (of the base as first fitted; diagnose's later restarts only lower it).
``--diagnose DESIGN SEED …``: those logs of the suite through ``hdid.diagnose`` (all
candidates): the verdict, the ratio it reports (of its final base) and its warnings.
``--append`` keeps the designs' calibration logs of other seeds (the threshold is then
the order statistic of all of them; ``by_design`` keeps the earlier run under ``earlier``).
Writes ``calibration/results/floor_thresholds.{json,md}`` (rows of other designs are kept) and, with
``--threshold``, the ``ROWS`` block of ``src/hdid/_diagnosis/_excess.py`` from the JSON.
"""

from __future__ import annotations

import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path[:0] = [str(HERE), str(HERE.parent / "benchmarks")]  # diagnose_rates; _common, the suite
from _common import RESULTS as BENCH_RESULTS  # noqa: E402
from _common import ROOT, run_meta  # noqa: E402

from hdid.reference import logs  # noqa: E402

RESULTS = HERE / "results"
NAME = "floor_thresholds"
THRESHOLD_MODULE = ROOT / "src" / "hdid" / "_diagnosis" / "_excess.py"
#: The designs' sample rate [Hz] and runs (what ``_excess.threshold_for`` matches a log to;
#: as ``diagnose_rates.DESIGN_SHAPE``).
DESIGN_SHAPE = {"paper": (250.0, 4), "rich": (1000.0, 8)}


CLEAR_EVERY = 40
_COUNT = [0]


def base_row(log, label: str) -> dict:
    from hdid._diagnosis._diagnose import FULL_GRID_STARTS
    from hdid._diagnosis._floor import fit_floor
    from hdid._fitting import _refit
    from hdid._log import read_log
    from hdid._models._model import Model

    if not hasattr(log, "runs"):
        log = read_log(log)
    t0 = time.perf_counter()
    s = _refit.setup(log, Model.default(), {})
    cur = _refit.run("base", s, [("grid", u) for u in _refit.grid(s, FULL_GRID_STARTS)])
    t1 = time.perf_counter()
    F, sd = fit_floor(s, cur.u)
    n, k = cur.n_effective, cur.n_unknowns
    row = {"log": label, "chi2": cur.cost, "n": n, "k": k, "n_minus_k": n - k,
           "floor": F, "floor_sd": sd, "ratio": cur.cost / F, "fit_s": t1 - t0,
           "floor_s": time.perf_counter() - t1, "load1": os.getloadavg()[0]}
    # free the process's compiled programs every CLEAR_EVERY logs: every XLA:CPU
    # executable holds memory mappings, and ~120 logs' simulations and fits reached the
    # kernel's limit (LLVM "Cannot allocate memory"; tests/conftest.py). Every log: 7 s a
    # log instead of 1.5 (the programs reloaded from the store each time).
    _COUNT[0] += 1
    if _COUNT[0] % CLEAR_EVERY == 0:
        import gc

        import jax

        jax.clear_caches()
        gc.collect()
    print(f"{label:18s} χ² {cur.cost:7.2f} n {n:6.1f} k {k:3d} n−k {n - k:6.1f} "
          f"F {F:6.2f} ± {sd:5.2f}  χ²/F {cur.cost / F:5.2f}  (fit {row['fit_s']:.1f} s, "
          f"floor {row['floor_s']:.2f} s, load {row['load1']:.1f})", flush=True)
    return row


def threshold_table(rows: list, meta: dict) -> list[dict]:
    """Per design: the threshold (:func:`~hdid._diagnosis._excess.choose`) of its clean
    calibration logs' χ²/F (rounded *up* at the 4th decimal: never below the order
    statistic, so no more of the logs exceed it), the logs, how many exceed it, where it
    was measured."""
    from hdid._diagnosis._excess import choose

    out = []
    for design, (rate, runs) in DESIGN_SHAPE.items():
        r = [x["ratio"] for x in rows if x["design"] == design and x["kind"] == "calibration"]
        if not r or choose(r) is None:
            continue
        thr, above = choose(r)
        seeds = sorted(x["seed"] for x in rows if x["design"] == design
                       and x["kind"] == "calibration")
        where = meta.get("by_design", {}).get(design, {})
        out.append({"design": design, "rate_hz": rate, "runs": runs, "logs": len(r),
                    "above": above, "threshold": math.ceil(thr * 1e4) / 1e4,
                    "measured": _measured(where, seeds)})
    return out


def _measured(where: dict, seeds: list) -> str:
    """Where and when the calibration logs were fitted (an ``--append`` run and the runs
    before it)."""
    runs, w = [], where
    while w:
        runs.append(f"{(w.get('date') or '?')[:10]} (src {w.get('src') or '?'})")
        w = w.get("earlier")
    return f"measured {' and '.join(reversed(runs))}, seeds {_ranges(seeds)}"


def _ranges(seeds: list) -> str:
    """``[5000, 5001, …, 5199, 7000, …]`` → ``"5000–5199, 7000–7199"``."""
    parts, start = [], seeds[0]
    for a, b in zip(seeds, seeds[1:] + [None]):
        if b != a + 1:
            parts.append(f"{start}–{a}" if a != start else f"{a}")
            start = b
    return ", ".join(parts)


def write_threshold(rows: list, meta: dict) -> str:
    """The generated block of ``_excess.py`` (between its markers): never typed by hand."""
    line = lambda t: "    {" + ", ".join(f"{k!r}: {v!r}" for k, v in t.items()) + "},"  # noqa: E731
    block = "ROWS = (\n" + "\n".join(line(t) for t in threshold_table(rows, meta)) + "\n)\n"
    text = THRESHOLD_MODULE.read_text()
    a, b = "# BEGIN GENERATED\n", "# END GENERATED\n"
    i, j = text.index(a) + len(a), text.index(b)
    THRESHOLD_MODULE.write_text(text[:i] + block + text[j:])
    return block


def render(res: dict) -> str:
    from hdid._diagnosis._rates import upper_bound

    rows, meta = res["rows"], res["meta"]
    lines = [f"# {NAME}: base χ² against the rounding floor a correct model leaves", "",
             f"`{meta.get('cmd')}`; per design: " + "; ".join(
                 f"{d} {m.get('date')} load {m.get('load')} → {m.get('load_end')}, src "
                 f"{m.get('src')}" for d, m in meta.get("by_design", {}).items()), "",
             "| design | clean logs | seeds | χ²/F mean ± sd | median | largest | threshold "
             "(logs above) | false-warning rate, mean j/(N+1) | one-sided 95 % bound "
             "| χ²/(n−k) mean |",
             "|---|---|---|---|---|---|---|---|---|---|"]
    for t in threshold_table(rows, meta):
        r = np.array([x["ratio"] for x in rows if x["design"] == t["design"]
                      and x["kind"] == "calibration"])
        a = [x["chi2"] / x["n_minus_k"] for x in rows if x["design"] == t["design"]
             and x["kind"] == "calibration"]
        n = len(r)
        lines.append(f"| {t['design']} | {n} | {t['measured'].split('seeds ')[-1]} | "
                     f"{r.mean():.3f} ± {r.std(ddof=1):.3f} | {np.median(r):.3f} | "
                     f"{r.max():.3f} | {t['threshold']:.4f} ({t['above']}) | "
                     f"{100 * (t['above'] + 1) / (n + 1):.2f} % | "
                     f"{100 * upper_bound(t['above'], n):.2f} % | {np.mean(a):.3f} |")
    thr = {t["design"]: t["threshold"] for t in threshold_table(rows, meta)}
    hidden = [x for x in rows if x["kind"] == "hidden"]
    if hidden:
        h = meta.get("hidden", {})
        lines += ["", "## The independent suite's logs (base as first fitted; "
                  f"`{h.get('cmd')}`, {h.get('date')}, load {h.get('load')} → "
                  f"{h.get('load_end')})", "",
                  "| design | seed | hidden | main's verdict | χ² | n − k | F ± sd | χ²/F | "
                  "above threshold | warned (verdict names no effect) |",
                  "|---|---|---|---|---|---|---|---|---|---|"]
        for x in hidden:
            up = x["ratio"] > thr.get(x["design"], math.inf)
            warn = up and x["main_verdict"] in ("adequate", "unexplained")
            lines.append(f"| {x['design']} | {x['seed']} | {x['hidden']} | "
                         f"{x['main_verdict']} | {x['chi2']:.2f} | {x['n_minus_k']:.1f} | "
                         f"{x['floor']:.2f} ± {x['floor_sd']:.2f} | {x['ratio']:.3f} | "
                         f"{'yes' if up else ''} | {'**warned**' if warn else ''} |")
    if res.get("diagnosed"):
        h = meta.get("diagnosed", {})
        lines += ["", f"## Through `hdid.diagnose` (`{h.get('cmd')}`, {h.get('date')}, src "
                  f"{h.get('src')}, load {h.get('load')} → {h.get('load_end')})", "",
                  "| design | seed | hidden | verdict | χ² | F ± sd | χ²/F | floor warning | "
                  "wall s |", "|---|---|---|---|---|---|---|---|---|"]
        for x in res["diagnosed"]:
            warned = any("names no effect" in w for w in x["warnings"])
            lines.append(f"| {x['design']} | {x['seed']} | {x['hidden']} | {x['summary']} | "
                         f"{x['chi2']:.2f} | {x['floor']:.2f} ± {x['floor_sd']:.2f} | "
                         f"{x['ratio']:.3f} | {'**yes**' if warned else 'no'} | "
                         f"{x['wall_s']:.0f} |")
    lines += ["", "| design | kind | log | χ² | n − k | F ± sd | χ²/F | fit s | load |",
              "|---|---|---|---|---|---|---|---|---|"]
    for x in rows:
        if x["kind"] == "hidden":
            continue
        lines.append(f"| {x['design']} | {x['kind']} | {x['log']} | {x['chi2']:.2f} | "
                     f"{x['n_minus_k']:.1f} | {x['floor']:.2f} ± {x['floor_sd']:.2f} | "
                     f"{x['ratio']:.3f} | {x['fit_s']:.1f} | {x['load1']:.1f} |")
    return "\n".join(lines) + "\n"


def _suite_log(design: str, seed: int):
    """The independent suite's log ``seed`` of ``design`` and its hidden effect's name, as
    ``diagnose_independent.run_design`` draws them."""
    from diagnose_independent import HIDDEN, draw, hidden_params

    name = HIDDEN[seed % 100]
    truth, des = draw(design, seed)
    rng = np.random.default_rng(seed + 10_000)
    hp = hidden_params(name, truth, des, rng) if name != "none" else {}
    kw = logs.reference_kwargs(name, truth, **hp) if name != "none" else None
    return logs.make_log(truth, **{k: v for k, v in des.items() if k != "gear_factor"},
                         seed=seed, hidden=kw), name


def diagnosed_rows(design: str, seeds: list) -> list:
    import hdid

    out = []
    for seed in seeds:
        df, name = _suite_log(design, seed)
        t0 = time.perf_counter()
        d = hdid.diagnose(df)
        rf = d.rounding_floor or {}
        out.append({"design": design, "seed": seed, "hidden": name, "verdict": d.verdict,
                    "summary": d.summary, "chi2": rf.get("chi2"), "floor": rf.get("floor"),
                    "floor_sd": rf.get("floor_sd"), "ratio": rf.get("chi2_over_floor"),
                    "n_minus_k": rf.get("n_minus_k"), "exceeded": rf.get("exceeded"),
                    "warnings": d.warnings, "wall_s": time.perf_counter() - t0,
                    "load1": os.getloadavg()[0]})
        print(f"{design} {seed} {name}: {d.verdict} ({d.summary[:60]}); χ²/F "
              f"{rf.get('chi2_over_floor', math.nan):.2f}; floor warning "
              f"{any('names no effect' in w for w in d.warnings)} "
              f"({out[-1]['wall_s']:.0f} s, load {out[-1]['load1']:.1f})", flush=True)
    return out


def hidden_rows(designs: list) -> list:
    """Base χ²/F of the independent suite's logs (:func:`_suite_log`), with main's verdict
    from its committed results."""
    from diagnose_independent import HIDDEN

    verdicts = {(r["design"], r["seed"]): r.get("named") for r in json.loads(
        (BENCH_RESULTS / "diagnose_independent.json").read_text())["records"]}
    out = []
    for design in designs:
        for seed0 in {"rich": (8800, 8900), "paper": (9800, 9900)}[design]:
            for i in range(len(HIDDEN)):
                df, name = _suite_log(design, seed0 + i)
                out.append({"design": design, "kind": "hidden", "hidden": name,
                            "seed": seed0 + i, "main_verdict": verdicts.get((design, seed0 + i)),
                            **base_row(df, f"{design} {seed0 + i} {name}")})
    return out


def main(argv):
    from diagnose_rates import RICH, _second_setup
    from diagnose_independent import draw

    import hdid
    from hdid._simulation._synthetic import synthesize

    out = RESULTS / f"{NAME}.json"
    if "--threshold" in argv or "--render" in argv:
        res = json.loads(out.read_text())
        (RESULTS / f"{NAME}.md").write_text(render(res))
        if "--threshold" in argv:
            print(write_threshold(res["rows"], res["meta"]))
        return
    if "--diagnose" in argv:
        design = next(a for a in argv if a in ("paper", "rich"))
        seeds = [int(a) for a in argv if a.isdigit()]
        res = json.loads(out.read_text())
        keep = [r for r in res.get("diagnosed", []) if (r["design"], r["seed"]) not in
                {(design, s) for s in seeds}]
        res["diagnosed"] = keep + diagnosed_rows(design, seeds)
        res["meta"]["diagnosed"] = {**run_meta(cmd="taskset -c 1 python calibration/"
                                               "floor_thresholds.py " + " ".join(argv)),
                                    "load_end": " ".join(f"{x:.1f}" for x in os.getloadavg())}
        out.write_text(json.dumps(res, indent=2, default=float) + "\n")
        (RESULTS / f"{NAME}.md").write_text(render(res))
        return
    if "--hidden" in argv:
        designs = [a for a in argv if a in ("paper", "rich")] or ["paper", "rich"]
        res = json.loads(out.read_text())
        res["rows"] = [r for r in res["rows"] if not (r["kind"] == "hidden"
                                                      and r["design"] in designs)]
        res["rows"] += hidden_rows(designs)
        res["meta"]["hidden"] = {**run_meta(cmd="taskset -c 1 python calibration/floor_thresholds.py "
                                            + " ".join(argv)),
                                 "load_end": " ".join(f"{x:.1f}" for x in os.getloadavg())}
        out.write_text(json.dumps(res, indent=2, default=float) + "\n")
        (RESULTS / f"{NAME}.md").write_text(render(res))
        print(render(res))
        return
    n = int(argv[0]) if argv and argv[0].isdigit() else 6
    seed0 = int(argv[argv.index("--seed0") + 1]) if "--seed0" in argv else 5000
    designs = [a for a in argv if a in ("paper", "rich")] or ["paper", "rich"]
    gen = logs
    meta = run_meta(cmd="taskset -c 1 python calibration/floor_thresholds.py " + " ".join(argv))
    res = json.loads(out.read_text()) if out.exists() else {"meta": meta, "rows": []}
    append = "--append" in argv  # keep the designs' calibration logs of other seeds
    rows = [r for r in res["rows"] if r["design"] not in designs
            or (append and r["kind"] == "hidden")
            or (append and r["kind"] == "calibration" and not seed0 <= r["seed"] < seed0 + n)]
    kept = ({"diagnosed": res["diagnosed"]} if append and "diagnosed" in res else {})
    kept_meta = ({k: res["meta"][k] for k in ("hidden", "diagnosed") if k in res["meta"]}
                 if append else {})
    by_design = {k: v for k, v in res["meta"].get("by_design", {}).items()
                 if k not in designs or append}
    for name in designs:
        m = run_meta()
        design = dict(RICH if name == "rich" else gen.PAPER_DESIGN)
        truth = {k: v for k, v in gen.TRUTH_CSF8.items() if k != "ratio"}
        fitted = hdid.fit(gen.make_log(truth, **{**design, "seed": 9001}))
        with tempfile.TemporaryDirectory() as tmp:
            for i in range(n):
                path = Path(tmp) / f"{name}_{i}.csv"
                synthesize(path, amplitudes=list(design["amplitudes"]), rate=design["fs"],
                           duration=design["duration"], hold=design["hold"], offset=0.005,
                           model=fitted.model, seed=seed0 + i)
                if len(design["offsets_by_setup"]) > 1:
                    _second_setup(path)
                rows.append({"design": name, "kind": "calibration", "seed": seed0 + i,
                             **base_row(str(path), f"{name} cal {seed0 + i}")})
        for seed in ({"rich": (8800, 8900), "paper": (9800, 9900)}[name]):
            tr, des = draw(name, seed)
            mk = {k: v for k, v in des.items() if k != "gear_factor"}
            df = gen.make_log(tr, **mk, seed=seed, hidden=None)
            rows.append({"design": name, "kind": "independent", "seed": seed,
                         **base_row(df, f"{name} ind {seed}")})
        earlier = by_design.get(name) if append else None
        by_design[name] = {"date": m["date"], "src": m["src"], "load": m["load"],
                           "load_end": " ".join(f"{x:.1f}" for x in os.getloadavg()),
                           "seeds": [seed0, seed0 + n - 1],
                           **({"earlier": earlier} if earlier else {})}
        res = {"meta": {**meta, **kept_meta, "by_design": by_design}, "rows": rows, **kept}
        RESULTS.mkdir(exist_ok=True)
        out.write_text(json.dumps(res, indent=2, default=float) + "\n")
        (RESULTS / f"{NAME}.md").write_text(render(res))
    print(render(res))


if __name__ == "__main__":
    main(sys.argv[1:])
