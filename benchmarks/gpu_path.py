"""The JAX GPU path: the same fit, log-posterior, sampler and batch fit on CPU and on a GPU, one
result (a ``cpu`` and a ``gpu`` run; the GPU run checked against the stored CPU run's numbers).

    python benchmarks/gpu_path.py --tag cpu      # JAX_PLATFORMS=cpu forces the CPU
    python benchmarks/gpu_path.py --tag gpu      # on a machine with a GPU, after the CPU run
    python benchmarks/gpu_path.py --render       # gpu_path.md from gpu_path.json

Section 5, ``fit_many`` with logs as lanes against one start a call (the crossover by batch
size), one process per backend, the results merged into gpu_path.json:

    python benchmarks/gpu_path.py --make-logs /tmp/logs.pkl --distinct 256
    python benchmarks/gpu_path.py --crossover /tmp/logs.pkl --modes logs --out gpu.json
    JAX_PLATFORMS=cpu python benchmarks/gpu_path.py --crossover /tmp/logs.pkl --modes one logs \\
        --sizes 100 1000 --out cpu.json
    python benchmarks/gpu_path.py --merge gpu.json cpu.json
"""

import argparse
import json
import os
import sys
import time
from pathlib import Path

import _common
from _common import RESULTS, Clock, header, parse_or_render, write_result

import hdid

LOG = _common.DATA / "csf8_paper.csv"
WALKERS = (1, 18, 36, 144, 1024, 8192)
N_POSITIONS = 36
POST_STEPS = 2000
PARAMS = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v")
#: fit_many's logs (batch_speed's design, truths and seeds), and the values kept per log
DESIGN, SAVED = "paper", ("k1", "tau_c", "tau_s", "c_v")


def _per_call(fn, reps=20, min_time=1.0):
    fn()
    walls, t0 = [], time.perf_counter()
    while len(walls) < reps or (time.perf_counter() - t0 < min_time and len(walls) < 2000):
        with Clock() as c:
            fn()
        walls.append(c.wall)
    return {"median_s": sorted(walls)[len(walls) // 2], "min_s": min(walls), "n": len(walls)}


def measure(args, ref, save) -> dict:
    """Sections 1–3 (checked against the run ``ref``, if any), calling ``save(res)`` after each (a run cut short
    by a time limit keeps what it measured). Section 4, ``fit_many`` with its default lanes (one start a call), is
    section 5's ``--modes one``: ``--crossover FILE --modes one --sizes 100 1000`` per backend."""
    import jax
    import jax.numpy as jnp
    import numpy as np

    import hdid
    from hdid._posterior import LogPosterior, sample_posterior

    res: dict = {"generated": time.strftime("%Y-%m-%dT%H:%M:%S"), "tag": args.tag, "machine": _common.machine()}
    print(res["machine"], flush=True)

    # 1. fit: first call (compile), then warm
    with Clock() as c1:
        hdid.fit(LOG)
    with Clock() as c2:
        fit = hdid.fit(LOG)
    params = {k: float(fit.values[k]) for k in PARAMS if k in fit.values}
    res["fit"] = {"first_s": c1.wall, "warm_s": c2.wall, "params": params, "cost": float(fit.starts.costs[fit.starts.best])}
    if ref:
        rp = ref["fit"]["params"]
        res["fit"]["max_rel_diff_vs_reference"] = max(abs(params[k] - rp[k]) / abs(rp[k]) for k in rp)
    print("fit", res["fit"], flush=True)
    save(res)

    # 2. log-posterior batch, at the reference's walker positions where given
    lp = LogPosterior(problem=fit.problem, centre=jnp.asarray(fit.u), temper=jnp.asarray(1.0),
                      quant_var=float(fit.problem.step) ** 2 / 12.0)
    pos = np.asarray(ref["positions"] if ref else sample_posterior(
        fit, method="emcee", n_steps=300, seed=0, progress=False).chain[-1][:N_POSITIONS])
    batch = jax.jit(lambda X: lp.batch(X))
    lp0 = np.asarray(batch(jnp.asarray(pos)))
    res |= {"positions": pos.tolist(), "logp_at_positions": lp0.tolist()}
    if ref:
        res["logp_max_abs_diff_vs_reference"] = float(np.max(np.abs(lp0 - ref["logp_at_positions"])))
    res["logp_batch"] = timings = {}
    for W in WALKERS:
        X = jnp.asarray(np.resize(pos, (W, pos.shape[1])))
        with Clock() as c:
            jax.block_until_ready(batch(X))
        t = _per_call(lambda: jax.block_until_ready(batch(X)))
        timings[str(W)] = t = t | {"compile_s": c.wall, "us_per_walker": t["median_s"] / W * 1e6}
        print(f"batch W={W}: {t['median_s'] * 1e3:.2f} ms", flush=True)
    save(res)

    # 3. sampler: the default walkers and 8× as many
    res["posterior"] = []
    for W in (None, 8 * 36):
        sample_posterior(fit, method="emcee", n_steps=20, n_walkers=W, seed=1, progress=False)  # compile
        with Clock() as c:
            post = sample_posterior(fit, method="emcee", n_steps=POST_STEPS, n_walkers=W, seed=0, progress=False)
        tau = np.asarray(post.tau)
        info = {"n_walkers": int(post.chain.shape[1]), "n_steps": int(post.chain.shape[0]), "wall_s": c.wall,
                "ms_per_step": c.wall / POST_STEPS * 1e3, "tau_max": float(np.nanmax(tau)),
                "tau_max_label": post.labels[int(np.nanargmax(tau))], "acceptance": float(np.mean(post.acceptance)),
                "walker_steps_per_s": post.chain.shape[1] * POST_STEPS / c.wall}
        res["posterior"].append(info)
        print("posterior", info, flush=True)
        save(res)

    res["load_end"] = os.getloadavg()[0]
    save(res)
    return res


# ---------------------------------------------------------------- 5. logs as lanes: the crossover

def make_logs(path: str, n: int, procs: int) -> None:
    """``n`` distinct paper-design logs (batch_speed's truths and seeds) as DataFrames,
    pickled to ``path``; made with ``procs`` processes."""
    import functools
    import multiprocessing
    import pickle

    import batch_speed

    # spawn, not fork: this process has imported JAX (threads)
    with multiprocessing.get_context("spawn").Pool(procs) as pool:
        dfs = pool.map(functools.partial(batch_speed.log_frame, DESIGN), range(n))
    Path(path).write_bytes(pickle.dumps(dfs))


def _row(rec: dict, n: int, warm, items, kw: dict, t_end: float, save, tag: str, per_log: int = 0) -> None:
    """Into ``rec``: the first ``fit_many(warm, **kw)`` (if not yet timed), then one timed ``fit_many(items(n),
    **kw)`` — wall, CPU, logs/s, errors, median k1, load, its timing and (n ≤ ``per_log``) each log's best χ² and
    :data:`SAVED` values — or fewer logs (``reduced``) or none (``skipped``) where the last row's time per log says
    ``n`` cannot finish before ``t_end``; ``save()`` after each."""
    import numpy as np

    if "first_call_s" not in rec:
        if t_end - time.perf_counter() < 30:
            return
        with Clock() as c:
            hdid.fit_many(warm, **kw)
        rec["first_call_s"] = c.wall
        print(tag, "first call", round(c.wall, 1), flush=True)
        save()
    left = t_end - time.perf_counter()
    if rec["runs"] and (rate := rec["runs"][-1]["wall_s"] / rec["runs"][-1]["n_logs"]) * n > 0.85 * left:
        m = int(0.85 * left / rate) // 100 * 100  # the last run's time per log, scaled: skip what cannot finish
        if m <= rec["runs"][-1]["n_logs"]:
            rec.setdefault("skipped", []).append({"n_logs": n, "estimate_s": rate * n, "left_s": left})
            print(tag, n, "skipped", rate * n, left, flush=True)
            return save()
        rec.setdefault("reduced", []).append({"n_logs": n, "to": m})
        n = m
    load0 = os.getloadavg()[0]
    with Clock() as c:
        table = hdid.fit_many(items(n), **kw)
    run = {"n_logs": n, "wall_s": c.wall, "cpu_s": c.cpu, "logs_per_s": n / c.wall,
           "errors": int(table["error"].notna().sum()), "k1_median": float(np.nanmedian(table["k1"])),
           "load_before": load0, "load_after": os.getloadavg()[0],
           "timing": {k: v for k, v in table.attrs["timing"].items() if isinstance(v, (int, float, str))}}
    if n <= per_log:  # each log's fit, for the comparison across modes and machines
        best = [r.starts.costs[r.starts.best] if r is not None else None for r in table["result"]]
        run["per_log"] = {"cost": [None if b is None else float(b) for b in best],
                          **{k: [None if v != v else float(v) for v in table[k]] for k in SAVED}}
    rec["runs"].append(run)
    print(tag, {k: v for k, v in run.items() if k != "per_log"}, flush=True)
    save()


def crossover(args) -> None:
    """``fit_many`` over ``args.sizes`` logs (log i = distinct log i mod D) for each mode
    (``logs``: logs as lanes, ``one``: one start a call, today's default on a CPU), within
    ``args.budget_s``; the JSON rewritten to ``args.out`` after every row."""
    import pickle

    t_end = time.perf_counter() + args.budget_s
    dfs = pickle.loads(Path(args.logs).read_bytes())
    res = {"generated": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": _common.machine(),
           "distinct_logs": len(dfs), "budget_s": args.budget_s, "width": args.width, "modes": {}}

    def save():
        (tmp := Path(args.out).with_suffix(".tmp")).write_text(json.dumps(res, indent=1))
        tmp.replace(args.out)

    save()
    kw = {"logs": {"lanes": "logs", **({"lane_width": args.width} if args.width else {})}, "one": {"lanes": 1}}
    for size in args.sizes:
        for mode in args.modes:
            _row(res["modes"].setdefault(mode, {"runs": []}), size, dfs[:2],
                 lambda n: [dfs[i % len(dfs)] for i in range(n)], kw[mode], t_end, save, mode,
                 per_log=len(dfs))
    res["load_end"] = os.getloadavg()[0]
    save()


def render(results: dict) -> str:
    cpu, gpu = results.get("cpu"), results.get("gpu")
    cols = [(t, r) for t, r in (("CPU", cpu), ("GPU", gpu)) if r]
    L = ["# The JAX GPU path: CPU vs GPU on the same code", ""]
    for t, r in cols:
        m = r["machine"]
        L.append(f"- **{t}**: generated {r['generated']} by `python benchmarks/gpu_path.py "
                 f"--tag {r['tag']}`; backend `{m['backend']}`, device {m['device_kind']}, {m['nproc']} CPU cores "
                 f"({m['cpu']}), python {m['python']}, jax {m['jax']}, x64 {m['x64']}, src {m['src_fingerprint']}, "
                 f"load {m['load_start']:.1f} → {r.get('load_end', float('nan')):.1f}.")
    row = lambda label, cell: f"| {label} | " + " | ".join(cell(r) for _, r in cols) + " |"  # noqa: E731
    L += ["", "## 1. Fit of the shipped paper log", "",
          "| | " + " | ".join(t for t, _ in cols) + " |", "|---|" + "---|" * len(cols),
          row("first call (compile)", lambda r: f"{r['fit']['first_s']:.1f} s"),
          row("warm call", lambda r: f"{r['fit']['warm_s']:.2f} s"), row("cost", lambda r: f"{r['fit']['cost']:.6f}"),
          *(row(k, lambda r: f"{r['fit']['params'][k]:.10g}") for k in PARAMS)]
    if gpu and "max_rel_diff_vs_reference" in gpu["fit"]:
        L.append(f"\nLargest relative difference of a fitted parameter, GPU vs CPU: "
                 f"{gpu['fit']['max_rel_diff_vs_reference']:.1e}.")
    L += ["", "## 2. One call of the vectorised log-posterior (`LogPosterior.batch`)", "",
          "| walkers | " + " | ".join(f"{t} median | {t} µs/walker" for t, _ in cols) + " |",
          "|---|" + "---|---|" * len(cols)]
    L += [row(W, lambda r: f"{r['logp_batch'][str(W)]['median_s'] * 1e3:.2f} ms | "
                           f"{r['logp_batch'][str(W)]['us_per_walker']:.1f}") for W in WALKERS]
    if gpu and "logp_max_abs_diff_vs_reference" in gpu:
        L.append(f"\nAt the {len(gpu['positions'])} stored walker positions the GPU's log p "
                 f"differs from the CPU's by at most {gpu['logp_max_abs_diff_vs_reference']:.1e} "
                 f"(log p ≈ {min(gpu['logp_at_positions']):.1f}…{max(gpu['logp_at_positions']):.1f}).")
    L += ["", f"## 3. `sample_posterior`, {POST_STEPS} steps after the burn-in", "",
          *header("backend", "walkers", "wall", "ms/step", "walker-steps/s", "τ_max (param)", "acceptance")]
    for t, r in cols:
        for p in r["posterior"]:
            L.append(f"| {t} | {p['n_walkers']} | {p['wall_s']:.1f} s | {p['ms_per_step']:.2f} | "
                     f"{p['walker_steps_per_s']:.0f} | {p['tau_max']:.0f} ({p['tau_max_label']}) | "
                     f"{p['acceptance']:.2f} |")
    L += ["", "## 4. `fit_many` over paper-design logs", "",
          "| backend | logs | wall | logs/s | errors | median k1 |", "|---|---|---|---|---|---|"]
    for t, r in ((t, r) for t, r in cols if "fit_many" in r):  # (now measured as section 5's --modes one)
        L.append(f"| {t} | first call, 2 logs | {r['fit_many']['first_call_s']:.1f} s | | | |")
        for q in r["fit_many"]["runs"]:
            L.append(f"| {t} | {q['n_logs']} | {q['wall_s']:.1f} s | {q['logs_per_s']:.1f} | "
                     f"{q['errors']} | {q['k1_median']:.1f} |")
    if results.get("crossover"):
        L += render_crossover(results["crossover"])
    return "\n".join([*L, "", *_common.interpretation_section(results)])


MODE_NAMES = {"logs": "logs as lanes", "one": "one start a call"}


def render_crossover(cross: dict) -> list[str]:
    """Section 5 from the ``--crossover`` runs (keyed by backend)."""
    L = ["", "## 5. `fit_many` with logs as lanes (`lanes=\"logs\"`) vs one start a call: the crossover", ""]
    for b, r in cross.items():
        m = r["machine"]
        L.append(f"- **{b.upper()}** run: generated {r['generated']}; device {m['device_kind']}, {m['nproc']} CPU cores "
                 f"({m['cpu']}), python {m['python']}, jax {m['jax']}, src {m['src_fingerprint']}; "
                 f"{r['distinct_logs']} distinct paper logs (log i of a batch is distinct log i mod "
                 f"{r['distinct_logs']}), lanes per call {r['width'] or 'by backend'}, budget {r['budget_s']:.0f} s.")
    recs = [(f"{b.upper()} {MODE_NAMES[mode]}", b, mode, rec) for b, r in cross.items() for mode, rec in r["modes"].items()]
    L += ["", "| backend | mode | logs | wall | logs/s | CPU per log | setup | grid | LM | analysis | compile in run "
          "| LM iterations | errors | median k1 | load |", "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for name, b, mode, rec in recs:
        if "first_call_s" in rec:
            L.append(f"| {b.upper()} | {MODE_NAMES[mode]} | first call, 2 logs | {rec['first_call_s']:.1f} s "
                     "| | | | | | | | | | | |")
        for q in rec["runs"]:
            t = q["timing"]
            L.append(f"| {b.upper()} | {MODE_NAMES[mode]} | {q['n_logs']} | {q['wall_s']:.1f} s | {q['logs_per_s']:.1f} "
                     f"| {q['cpu_s'] / q['n_logs'] * 1e3:.0f} ms | {t['setup_s']:.1f} s | {t['grid_s']:.1f} s | "
                     f"{t['solve_s']:.1f} s | {t['analyse_s']:.1f} s | {t['compile_s']:.1f} s | {t['lane_steps']} | "
                     f"{q['errors']} | {q['k1_median']:.1f} | {q['load_before']:.1f}→{q['load_after']:.1f} |")
        L += [f"\n{name}, {sk['n_logs']} logs: not run (estimated {sk['estimate_s']:.0f} s, {sk['left_s']:.0f} s of "
              "the budget left)." for sk in rec.get("skipped", [])]
        L += [f"\n{name}: {rd['n_logs']} logs cut to {rd['to']} to fit the budget." for rd in rec.get("reduced", [])]
    rate = {(name, q["n_logs"]): q["logs_per_s"] for name, _, _, rec in recs for q in rec["runs"]}
    L += ["", "logs/s by batch size (the crossover):", "", "| logs | " + " | ".join(x[0] for x in recs) + " |",
          "|---|" + "---|" * len(recs)]
    L += [f"| {n} | " + " | ".join(f"{rate[(x[0], n)]:.1f}" if (x[0], n) in rate else "–" for x in recs) + " |"
          for n in sorted({n for _, n in rate})]
    per = [(name, q["per_log"]) for name, _, _, rec in recs for q in rec["runs"] if "per_log" in q]
    if len(per) > 1:
        L += ["", "Same fits: each run's per-log results against the first's (the logs both fitted):", "",
              "| run | vs | logs | max rel. diff of χ² | max rel. diff of k1, tau_c, tau_s, c_v | logs > 1e-6 |",
              "|---|---|---|---|---|---|"]
        (n0, p0) = per[0]
        for name, p in per[1:]:
            k, dc, dp, bad = min(len(p0["cost"]), len(p["cost"])), 0.0, 0.0, 0
            for i in (i for i in range(k) if p0["cost"][i] is not None and p["cost"][i] is not None):
                c = abs(p["cost"][i] - p0["cost"][i]) / abs(p0["cost"][i])
                d = max(abs(p[x][i] - p0[x][i]) / abs(p0[x][i]) for x in SAVED)
                dc, dp, bad = max(dc, c), max(dp, d), bad + (max(c, d) > 1e-6)
            L.append(f"| {name} | {n0} | {k} | {dc:.1e} | {dp:.1e} | {bad} |")
    return L


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--tag", choices=("cpu", "gpu"), default="cpu",
                    help="the run it replaces in gpu_path.json (gpu: checked against the cpu run)")
    ap.add_argument("--make-logs", metavar="FILE", help="only make --distinct paper logs, pickled to FILE")
    ap.add_argument("--procs", type=int, default=2, help="with --make-logs: processes")
    ap.add_argument("--distinct", type=int, default=256, help="with --make-logs: distinct logs")
    ap.add_argument("--crossover", metavar="FILE", dest="logs",
                    help="only the batch crossover (section 5) on the pickled logs FILE; results to --out")
    ap.add_argument("--out", default="crossover.json", help="with --crossover: the JSON written")
    ap.add_argument("--modes", nargs="+", default=["logs"], choices=("logs", "one"))
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000, 10000])
    ap.add_argument("--budget-s", type=float, default=300.0, help="with --crossover: wall budget")
    ap.add_argument("--width", type=int, default=None, help="with --crossover: lanes per call (default: by backend)")
    ap.add_argument("--merge", nargs="+", metavar="FILE",
                    help="store --crossover results (JSON files) in gpu_path.json under 'crossover' and render")
    if (args := parse_or_render(ap, argv, "gpu_path", render, indent=1)) is None:
        return 0
    results = _common.stored("gpu_path")
    if args.make_logs:
        make_logs(args.make_logs, args.distinct, args.procs)
    elif args.logs:
        crossover(args)
    elif args.merge:
        runs = [json.loads(Path(f).read_text()) for f in args.merge]
        write_result("gpu_path", results | {"crossover": {r["machine"]["backend"]: r for r in runs}}, render, indent=1)
    else:
        measure(args, results.get("cpu") if args.tag == "gpu" else None,
                lambda res: write_result("gpu_path", results | {args.tag: res}, render, indent=1))
        print(f"wrote {RESULTS / 'gpu_path.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
