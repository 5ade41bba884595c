"""``hdid design`` on the shipped paper log: ranking, speed of 20 candidates, and the predicted stds checked against
the spread of fits of simulated logs; ``--pairs``: diagnose's separating experiments checked by simulation.

    taskset -c 1 python benchmarks/design_check.py [--n 30] [--pairs [--n-this 5]] [--speed]
    python benchmarks/design_check.py --pair-logs DIR [--n 10]     # simulate, pickle
    taskset -c 1 python benchmarks/design_check.py --diagnose-logs DIR [--part I/K]
    python benchmarks/design_check.py --collect DIR                # into the result

``--pair-logs``/``--diagnose-logs``/``--collect``: ``hdid.diagnose`` (default candidates, ``design=False``: the
separation is computed after the verdict and does not change it) on the logs of each pair's separating experiment that
``--pairs`` fits (the same seeds), in parts that may run in parallel processes.
"""

import argparse
import json
import math
import sys
import time

from _common import DATA, RESULTS, cpu_model, header, load, parse_or_render, src_fingerprint

QUANTITIES = ("k1", "tau_c", "tau_s", "stick_band_halfwidth_rad")
TARGETS = "tau_c,tau_s,v_s,band"


#: (name, design, seed, the two forms): the issue's two confusable pairs — ripple vs kinematic error on a 2 kHz rich
#: log (seed 8805: a hidden ripple named kinematic_error order 10), backlash vs hysteresis on the paper design (seed
#: 9902: a hidden hysteresis named among hysteresis / backlash / soft_windup / kinematic_error). Backlash vs soft
#: windup on the same log: the backlash logs of the backlash–hysteresis experiment were told apart from hysteresis but
#: were ambiguous with soft_windup.
PAIRS = (("ripple vs kinematic_error, rich 2 kHz", "rich", 8805, ("ripple", "kinematic_error")),
         ("backlash vs hysteresis, paper", "paper", 9902, ("backlash", "hysteresis")),
         ("backlash vs soft_windup, paper", "paper", 9902, ("backlash", "soft_windup")))


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=30, help="simulated logs per check (per form)")
    ap.add_argument("--pairs", action="store_true", help="only the separating-experiment check")
    ap.add_argument("--speed", action="store_true", help="only re-measure the speed of 20 candidates (the rest kept)")
    ap.add_argument("--n-this", type=int, default=5, help="--pairs: simulated logs per form of the log's own design")
    ap.add_argument("--pair-logs", metavar="DIR", help="simulate --n logs per form, pickle them")
    ap.add_argument("--diagnose-logs", metavar="DIR", help="diagnose the pickled logs in DIR")
    ap.add_argument("--part", default="0/1", help="--diagnose-logs: every K-th log from the I-th")
    ap.add_argument("--collect", metavar="DIR", help="the diagnosed logs' records into the result")
    ap.add_argument("--label", default="", help="--collect: the run's name (its code, machine)")
    ap.add_argument("--certify", type=int, default=0, help="--pairs: global rival fits of the N largest upper bounds")
    ap.add_argument("--pair", type=int, action="append", help="--pairs/--pair-logs: only these PAIRS (index; repeat)")
    if (args := parse_or_render(ap, argv, "design_check", render)) is None:
        return 0
    if args.pair_logs or args.diagnose_logs or args.collect:
        return pair_diagnoses(args)
    if args.pairs:
        return pairs(args.n, args.n_this, args.pair, args.certify)
    import hdid
    from hdid._design import _check, _rank

    if args.speed:  # only the speed rows, the rest of the stored result kept
        res = json.loads((RESULTS / "design_check.json").read_text())
        fit = hdid.fit(DATA / "csf8_paper.csv")
        res["speed"], res["speed_src"] = _speed(fit, res.setdefault("loads", [])), src_fingerprint()
        _write(res)
        res["speed_separate"] = _speed(fit, res["loads"], separate=("backlash", "hysteresis"))
        _write(res)
        return 0
    res = {"benchmark": "design_check", "src": src_fingerprint(), "cpu": cpu_model(),
           "loads": [load("start")], "n": args.n}
    t = time.perf_counter()
    fit = hdid.fit(DATA / "csf8_paper.csv")
    res["fit_s"] = time.perf_counter() - t
    res["speed"] = _speed(fit, res["loads"])
    d = hdid.design(fit, targets=TARGETS)
    res["report"] = d.report()
    res["ranking"] = [{"candidate": d.predictions[i].experiment.name, "score_ratio": math.exp(s)
                       if math.isfinite(s) else None} for i, s in d.ranking]
    best, keys = d.best, ("tau_c", "tau_s", "v_s", "stick_band_halfwidth_rad")
    res["top"] = {"name": best.experiment.name, "describe": best.experiment.describe(),
                  "std": {k: _rank.std_of(best, k) for k in keys},
                  "std_this_log": {k: _rank.std_of(d.current, k) for k in keys}, "linearisation": best.honesty}
    res["checks"] = []
    for p in (best, d.current):
        names = tuple(dict.fromkeys([*p.names, "stick_band_halfwidth_rad"]))
        pred = {k: _rank.std_of(p, k) for k in names}
        res["loads"].append(load(f"before check {p.experiment.name}"))
        c = _check.run(fit, p.experiment, pred, args.n, seed=1, names=names)
        res["checks"].append(c.to_dict() | {"linearisation": p.honesty, "within_25pct": {
            k: (abs(c.ratio(k) - 1.0) <= 0.25 if math.isfinite(c.ratio(k)) else None) for k in QUANTITIES},
            "load": load(f"after check {p.experiment.name}")})
        _write(res)
    res["loads"].append(load("end"))
    _write(res)
    print((RESULTS / "design_check.md").read_text())
    return 0


def _speed(fit, loads, separate=()):
    """Seconds of ``hdid.design`` with 20 candidates: the process's first call, then warm;
    ``separate``: two effects, each added to the fit's model and fitted, the pair given
    as ``separate=`` (the separations as diagnose computes them)."""
    import hdid
    from hdid._design import _candidates
    from hdid.effects._registry import registry

    vals = fit.model.float_values()
    pair = [hdid.fit(DATA / "csf8_paper.csv", start_from_model=True,
                     model=fit.model.with_effect(registry()[k].start_from(vals))) for k in separate] or None

    base = _candidates.baseline(fit)
    extra = [dict(name="rate x8", rate=8 * base.rate),
             dict(name="amplitude x1.25", amplitudes=[1.25 * a for a in base.amplitudes]),
             dict(name="repeats x3", repeats=3)]
    cands = _candidates.default_candidates(base, fit.model)[1:] + _candidates.load_candidates(extra, base)
    timings = []
    for label in ("first with separate" if pair else "cold", "warm", "warm"):
        loads.append(load(f"before {label}"))
        t, cpu = time.perf_counter(), time.process_time()
        d20 = hdid.design(fit, cands, targets=None if pair else TARGETS, separate=pair)
        timings.append({"call": label, "n_candidates": len(d20.predictions), "seconds": time.perf_counter() - t,
                        "cpu_s": time.process_time() - cpu, **load(label)})
        if pair:
            timings[-1].update(separate=list(separate), top=(top := d20.best).experiment.name,
                               top_2lnlr=list(top.separation), top_kind=top.separation_kind)
    return timings


def _case_log(design: str, seed: int):
    """The independent suite's log ``seed`` (its hidden effect from the stored record)."""
    import diagnose_independent as di

    stored = json.loads((RESULTS / "diagnose_independent.json").read_text())["records"]
    name = next(r["hidden"] for r in stored if (r["design"], r["seed"]) == (design, seed))
    truth, des, hp = di.suite_log(design, seed, name)
    return name, di.make_log(truth, des, hp, seed, name)


def _pair_fits(design, seed, keys):
    """The hidden effect's name, the two forms' diagnose candidates on the suite's log ``seed``, diagnose's seconds."""
    import hdid

    hidden, df = _case_log(design, seed)
    t = time.perf_counter()
    by = {c.key: c for c in hdid.diagnose(df, candidates=list(keys), design=False).candidates if c.error is None}
    return hidden, [by[k] for k in keys], time.perf_counter() - t


def _chi2(r, step):
    return r.n_effective * (r.rms_residual_rad / (step / math.sqrt(12.0))) ** 2


def _realised(fits, e, n, seed):
    """Realised 2 ln LR on ``n`` logs of ``e`` simulated from each fitted form, both fitted by hdid.fit as the
    separation fits them: the truth at its own order, the rival at its best (scanned on the first log, then ±1)."""
    import numpy as np

    from hdid._design._best_rival import best_rival_fit
    from hdid._design._check import simulate_logs

    out = {}
    for i, truth in enumerate(fits):
        other, vals, wins = fits[1 - i], [], 0
        for k, log in enumerate(simulate_logs(truth, e, n, seed=seed + i)):
            rt = best_rival_fit(log, truth, e, window=0)
            ro = best_rival_fit(log, other, e, window=1 + 2 * (k == 0), truth=truth)
            other = ro if k == 0 and ro is not None else other
            if rt is None or ro is None:  # a failed fit is a result too
                print("  fit failed", flush=True)
                continue
            x = _chi2(ro, e.resolution) - _chi2(rt, e.resolution)
            vals.append(x)
            wins += x > 0
        v = np.asarray(vals)
        out["ab"[i] + "_true"] = {"n": int(v.size), "mean": float(v.mean()) if v.size else None,
                                  "median": float(np.median(v)) if v.size else None,
                                  "sd": float(v.std(ddof=1)) if v.size > 1 else None,
                                  "min": float(v.min()) if v.size else None, "true_form_lower_chi2": int(wins)}
    return out


def pairs(n: int, n_this: int, only=None, certify: int = 0) -> int:
    """``--pairs``: diagnose's separating experiments, checked by simulation (``only``:
    those of PAIRS, the other rows kept)."""
    from hdid._config import float64
    from hdid._diagnosis._separating import experiments_for, separating

    chosen_pairs = [p for i, p in enumerate(PAIRS) if not only or i in only]
    for title, design, seed, keys in chosen_pairs:
        hidden, (a, b), dt = _pair_fits(design, seed, keys)
        row = {"title": title, "design": design, "seed": seed, "hidden": hidden,
               "forms": [a.label, b.label], "delta_bic": [a.delta_bic, b.delta_bic],
               "src": src_fingerprint(), "n": n, "n_this": n_this,
               "diagnose_s": dt, "load_before": load("before separation")}
        t = time.perf_counter()
        rec = separating(a, b, certify=certify)
        row.update(certify=certify, separation_s=time.perf_counter() - t,
                   load_after_separation=load("after separation"),
                   separating={k: v for k, v in rec.items() if k != "text"}, text=rec["text"])
        print(title, "->", rec["text"], f"({row['separation_s']:.0f} s)", flush=True)
        _write_row(row)
        fa, fb = a.fit.result(), b.fit.result()
        exps = experiments_for(fa, fb)
        chosen = next(e for e in exps if e.name == rec.get("experiment"))
        for e, m in ((chosen, n), (exps[0], n_this)):
            if m <= 0:
                continue
            t = time.perf_counter()
            with float64():
                real = _realised((fa, fb), e, m, seed=seed)
            row.setdefault("realised", {})[e.name] = {**real, "seconds": time.perf_counter() - t,
                                                      **load(f"after {e.name}")}
            print("  ", e.name, real, flush=True)
            _write_row(row)
    return 0


def _write_row(row):
    """``row`` into the stored ``pairs`` rows (re-read first: pairs may run in parallel processes), in PAIRS' order."""
    res = json.loads((RESULTS / "design_check.json").read_text())
    pr = res.setdefault("pairs", {"cpu": cpu_model(), "rows": []})
    pr["rows"] = [r for r in pr["rows"] if r["title"] != row["title"]] + [row]
    titles = [p[0] for p in PAIRS]
    pr["rows"].sort(key=lambda r: titles.index(r["title"]) if r["title"] in titles else 99)
    _write(res)


def pair_diagnoses(args) -> int:
    """``--pair-logs`` / ``--diagnose-logs`` / ``--collect`` (module docstring)."""
    import pickle
    from pathlib import Path

    import hdid

    if args.pair_logs:
        from hdid._design._check import simulate_logs
        from hdid._diagnosis._separating import experiments_for

        out = Path(args.pair_logs)
        out.mkdir(parents=True, exist_ok=True)
        stored = json.loads((RESULTS / "design_check.json").read_text())["pairs"]["rows"]
        for p, (title, design, seed, keys) in enumerate(PAIRS):
            if args.pair and p not in args.pair:
                continue
            fits = [c.fit.result() for c in _pair_fits(design, seed, keys)[1]]
            name = next(r for r in stored if r["title"] == title)["separating"]["experiment"]
            e = next(x for x in experiments_for(*fits) if x.name == name)
            for i, f in enumerate(fits):  # the seeds of --pairs' realised 2 ln LR
                for k, log in enumerate(simulate_logs(f, e, args.n, seed=seed + i)):
                    rec = {"pair": title, "truth": keys[i], "log_index": k, "experiment": name}
                    (out / f"p{p}_{keys[i]}_{k:02d}.pkl").write_bytes(pickle.dumps({**rec, "log": log}))
            print(title, name, "logs written", flush=True)
        return 0
    if args.diagnose_logs:
        import platform

        import jax
        from diagnose_independent import _named

        i, k = map(int, args.part.split("/"))
        # log 0 of every form first, then log 1, ...: the first logs done cover every form
        files = sorted(Path(args.diagnose_logs).glob("p*.pkl"), key=lambda f: (f.stem[-2:], f.stem))
        for f in files[i::k]:
            if f.with_suffix(".json").exists():
                continue
            rec = pickle.loads(f.read_bytes())
            log = rec.pop("log")
            rec["load_before"] = load("before")
            t, c = time.perf_counter(), time.process_time()
            d = hdid.diagnose(log, design=False)
            cands = [x for x in d.candidates if x.error is None]
            named = _named(d)
            rec.update(verdict=d.verdict, named=named, summary=d.summary,
                       table=[(x.key, x.label, x.delta_bic, x.rms_after_rad / d.floor_rad) for x in cands[:6]],
                       rms_before_floor=d.base.rms_residual_rad / d.floor_rad,
                       wall_s=time.perf_counter() - t, cpu_s=time.process_time() - c,
                       load_after=load("after"), src=src_fingerprint(), cpu=cpu_model(),
                       host=platform.node(), jax=jax.__version__)
            rec["grade"] = ("right" if named == rec["truth"] else "honest" if
                            rec["truth"] in named.split("|") else "wrong")
            f.with_suffix(".json").write_text(json.dumps(rec, indent=1, default=str))
            print(f.stem, d.verdict, named, rec["grade"], f"{rec['wall_s']:.0f} s", flush=True)
        return 0
    rows = [json.loads(f.read_text()) for f in sorted(Path(args.collect).glob("p*.json"))]
    res = json.loads((RESULTS / "design_check.json").read_text())
    runs = [r for r in res.get("pair_diagnoses", []) if r["label"] != args.label]
    res["pair_diagnoses"] = runs + [{"label": args.label, "rows": rows}]
    _write(res)
    return 0


def _write(res):
    (RESULTS / "design_check.json").write_text(json.dumps(res, indent=2, allow_nan=False,
                                                          default=lambda x: None) + "\n")
    (RESULTS / "design_check.md").write_text(render(res))


def _fmt(x):
    return "n/a" if x is None or (isinstance(x, float) and not math.isfinite(x)) else f"{x:.3g}"


def render(res) -> str:
    L = ["# hdid design on the shipped paper log (data/synthetic/csf8_paper.csv)", "",
         f"src {res['src']}, {res['cpu']}, pinned to one core (taskset -c 1); fit {res['fit_s']:.1f} s", ""]
    L += ["## Speed (20 candidates" + (f", src {res['speed_src']}" if res.get("speed_src") else "")
          + ")", "", "| call | candidates | s | load 1/5/15 |", "|---|---|---|---|"]
    for t in res.get("speed", []):
        L.append(f"| {t['call']} | {t['n_candidates']} | {t['seconds']:.2f} | "
                 f"{t['load1']:.2f} / {t['load5']:.2f} / {t['load15']:.2f} |")
    sep = res.get("speed_separate")
    if sep:
        L += ["", f"--separate {','.join(sep[0]['separate'])} (fits of this log with each added; the separations as "
                  "diagnose computes them: local refits, then the largest fitted globally until it is a value):", "",
              *header("call", "candidates", "s", "CPU s", "top", "its 2 ln LR (A, B true)", "kind", "load 1/5/15")]
        for t in sep:
            L.append(f"| {t['call']} | {t['n_candidates']} | {t['seconds']:.2f} | {_fmt(t.get('cpu_s'))} | {t['top']} | "
                     f"{', '.join(_fmt(x) for x in t['top_2lnlr'])} | {t['top_kind']} | "
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
              *header("quantity", "truth", "mean fit", "spread", "predicted", "predicted/spread", "within 25 %")]
        for k, q in c["quantities"].items():
            w = {"": "", True: "yes", False: "no"}.get(c["within_25pct"].get(k, ""), "n/a")
            cells = (_fmt(q[x]) for x in ("truth", "mean", "spread", "predicted", "predicted_over_spread"))
            L.append(f"| {k} | {' | '.join(cells)} | {w} |")
        L += ["", f"fits above 3x the floor: {c['fits_above_floor']}; failures: {len(c['failures'])}",
              "linearisation flags: " + ("; ".join(c["linearisation"]) or "none"), ""]
    pr = res.get("pairs")
    if pr:
        srcs = ", ".join(dict.fromkeys(r.get("src", pr.get("src", "?")) for r in pr["rows"]))
        L += [f"## Separating experiments confirmed by simulation (--pairs, src {srcs}, "
              f"{pr['cpu']}; logs per form: the n after the slash in 'realised')", "",
              "Predicted: λ, the rival's χ² fitted globally (hdid.fit's multi-start driver) to the other form's "
              "noise-free readings, and a noisy log's 2·ln LR, λ + (k_true − k_rival) ± √(4λ + 2 tr((P_A − P_B)²)) "
              "(locally refitted upper bound in brackets). Realised: χ²(other form) − χ²(true form) of hdid.fit on "
              "logs simulated from each fitted form (median; mean ± sd; how many logs the true form fits better); "
              "ratio = predicted mean / realised median.", "",
              *header("pair (log)", "experiment", "form true", "predicted", "realised", "ratio", "s", "load")]
        for r in pr["rows"]:
            s_ = r["separating"]
            for name, real in r.get("realised", {}).items():
                own = name == s_.get("experiment")
                for key, form in zip(("a_true", "b_true"), r["forms"]):
                    q = real.get(key) or {}
                    if own:
                        nl = s_.get("noisy_log", {}).get(key, {})
                        mean = nl.get("mean")
                        draws = s_.get("release_draws", {}).get(key) or []
                        pred = (f"λ {_fmt(s_.get(key))}"
                                + (f" (mean of {', '.join(map(_fmt, draws))})" if len(draws) > 1 else "")
                                + f": {_fmt(mean)} ± {_fmt(nl.get('sd'))} "
                                f"({_fmt(s_.get('locally_refitted', {}).get(key))})")
                    else:
                        tl = s_.get("this_log", {})
                        mean = tl.get(key, {}).get("mean")
                        pred = (f"λ {_fmt(tl.get('lambda', {}).get(key))}: {_fmt(mean)} ± "
                                f"{_fmt(tl.get(key, {}).get('sd'))}" if tl else f"{_fmt(s_.get('this_log_2lnlr'))}")
                    med = q.get("median")
                    ratio = (mean / med if isinstance(mean, (int, float)) and med and math.isfinite(mean) else None)
                    cell = ("n/a" if q.get("mean") is None else
                            f"{_fmt(med)}; {_fmt(q['mean'])} ± {_fmt(q.get('sd'))}; "
                            f"{q['true_form_lower_chi2']}/{q['n']}")
                    L.append(f"| {r['title']} (seed {r['seed']}, hidden {r['hidden']}) | {name} | {form} | {pred} | "
                             f"{cell} | {_fmt(ratio)} | {real['seconds']:.0f} | {real['load1']:.1f} |")
        L += [""] + [f"- {r['text']} (computed in {r['separation_s']:.0f} s"
                     + (f", the {r['certify']} largest upper bounds also fitted globally"
                        if r.get("certify") else "") + ")" for r in pr["rows"]] + [""]
    for run in res.get("pair_diagnoses", []):
        L += ["## hdid.diagnose on the separating experiments' logs (default candidates, "
              f"design=False; --diagnose-logs): {run['label']}", "",
              "| pair | true form | logs | right | honest (ambiguous, truth in the set) | wrong | "
              "named when not right | wall s (median) | load |", "|---|---|---|---|---|---|---|---|---|"]
        groups: dict = {}
        for r in run["rows"]:
            groups.setdefault((r["pair"], r["truth"]), []).append(r)
        for (pair, truth), g in groups.items():
            n = {k: sum(r["grade"] == k for r in g) for k in ("right", "honest", "wrong")}
            other = ", ".join(sorted({r["named"] for r in g if r["grade"] != "right"})) or "-"
            wall = sorted(r["wall_s"] for r in g)[len(g) // 2]
            loads = [r["load_after"]["load1"] for r in g]
            L.append(f"| {pair} | {truth} | {len(g)} | {n['right']} | {n['honest']} | {n['wrong']} "
                     f"| {other} | {wall:.0f} | {min(loads):.1f}-{max(loads):.1f} |")
        L.append("")
    if res.get("interpretation"):
        L += ["## Interpretation", "", res["interpretation"]]
    return "\n".join(L) + "\n"


if __name__ == "__main__":
    sys.exit(main())
