"""Batch speed: ``hdid.fit_many`` (vectorised, and ``workers=2``) for 1–1000 paper-design logs;
cost vs design; compile time. (``hdid.fit`` and the scipy way: fit_speed.py, scipy_way.py.)

    python benchmarks/batch_speed.py [--quick] [--n N] [--before TREE] [--only LABEL…] [--skip LABEL…]
    python benchmarks/batch_speed.py --render    # results/batch_speed.md from its JSON
"""

import argparse
import json
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import _common
from _common import ROOT, Clock, header, load

from hdid.reference import logs

NAME = "batch_speed"
#: Issue 37: 1000 paper logs in 30 s or less on 2 quiet cores.
GOAL_1000_S = 30.0
#: Seed offsets: warm-up logs never overlap the timed ones.
WARMUP = 2

DESIGNS = {
    # name: (amplitudes, fs, duration)
    "paper": ([0.157, -0.157, 0.157, -0.157], 250.0, 0.5),
    "short 0.25 s": ([0.157, -0.157, 0.157, -0.157], 250.0, 0.25),
    "long 1.0 s": ([0.157, -0.157, 0.157, -0.157], 250.0, 1.0),
    "1 kHz": ([0.157, -0.157, 0.157, -0.157], 1000.0, 0.5),
    "2 runs": ([0.157, -0.157], 250.0, 0.5),
    "8 runs": ([0.157, -0.157, 0.12, -0.12, 0.08, -0.08, 0.05, -0.05], 250.0, 0.5),
}


def truth_of(i: int) -> dict:
    """The truth of log ``i`` (seed 1000+i)."""
    import numpy as np

    rng = np.random.default_rng(1000 + i)
    truth = dict(logs.TRUTH_CSF8)
    for k in ("k1", "tau_c", "tau_s", "c_v"):
        truth[k] *= float(np.exp(rng.normal(0.0, 0.15)))
    truth["tau_s"] = max(truth["tau_s"], 1.2 * truth["tau_c"])
    return truth


def log_frame(design: str, i: int):
    """Log ``i`` of a design as a DataFrame: truth :func:`truth_of`, seed 1000+i."""
    amps, fs, duration = DESIGNS[design]
    return logs.make_log(truth_of(i), amplitudes=amps, fs=fs, duration=duration, hold=0.04,
                         offsets_by_setup={"A": 0.012, "B": -0.020}, seed=1000 + i)


def make_logs(design: str, n: int, log_dir: Path) -> list[str]:
    """``n`` logs of a design (cached CSV files): :func:`log_frame` 0 … n-1."""
    d = log_dir / design.replace(" ", "_").replace(".", "p")
    d.mkdir(parents=True, exist_ok=True)
    paths = []
    for i in range(n):
        if not (p := d / f"log{i:04d}.csv").exists():
            log_frame(design, i).to_csv(tmp := p.with_suffix(".tmp"), index=False)
            tmp.replace(p)
        paths.append(str(p))
    return paths


def _usage():
    """CPU seconds (user + sys, all threads) and peak RSS [MB] of this process."""
    ru = resource.getrusage(resource.RUSAGE_SELF)
    return ru.ru_utime + ru.ru_stime, ru.ru_maxrss / 1024


def worker(cfg: dict) -> dict:
    """One configuration, in its own process: warm up on 2 logs, then time N logs."""
    t_imp = time.perf_counter()
    import hdid

    out = {"config": cfg, "load_before": load("start")}
    warm, timed = cfg["paths"][:WARMUP], cfg["paths"][WARMUP:]
    if cfg["mode"] == "workers":
        out.update(_workers_run(cfg, warm, timed, t_imp))
    else:
        opts = dict(vectorize=True)
        out["import_s"] = time.perf_counter() - t_imp
        with Clock() as first:
            timing = hdid.fit_many(warm, **opts).attrs["timing"]
        out.update(first_call_s=first.wall, first_call_timing=timing)
        with Clock() as c:
            table = hdid.fit_many(timed, **opts)
        out.update(total_s=c.wall, cpu_s=c.cpu, timing=table.attrs["timing"], **_quality(timed, table))
    return out | {"n": len(timed), "maxrss_mb": max(out.get("maxrss_mb", 0.0), _usage()[1]), "load_after": load("end")}


def _quality(timed: list, table) -> dict:
    """Failures, medians, and per log the best χ² (the before/after table compares them)."""
    out = {"n_failed": int(table["error"].notna().sum()),
           "errors": [e for e in table["error"] if isinstance(e, str)][:3],
           "summary": {c: float(table[c].median()) for c in ("k1", "tau_c", "rms_residual_counts") if c in table}}
    out["per_log"] = [None if (res := r.result) is None else
                      {"log": int(Path(path).stem[3:]), "chi2": float(res.starts.costs[res.starts.best])}
                      for path, r in zip(timed, table.itertuples())]
    return out


def _workers_run(cfg: dict, warm: list, timed: list, t_imp: float) -> dict:
    """``fit_many`` on a warm LocalCluster of ``cfg['workers']`` single-threaded processes.

    First call: start the cluster and fit the 2 warm-up logs on *every* worker (each traces
    and compiles, or reads the persistent cache). Timed: ``fit_many(client=…)`` with the
    chunks ``fit_many(workers=W)`` makes. CPU is the sum over the workers and this process.
    """
    import hdid
    from distributed import Client, LocalCluster

    W = int(cfg["workers"])
    out = {"import_s": time.perf_counter() - t_imp}
    t = time.perf_counter()
    cluster = LocalCluster(n_workers=W, threads_per_worker=1, processes=True, dashboard_address=None)
    client = Client(cluster)
    try:
        client.run(lambda: hdid.fit_many(warm) is not None)
        out.update(first_call_s=time.perf_counter() - t, first_call_timing={"compile_s": float("nan")})
        before, c0, t = client.run(_usage), _usage()[0], time.perf_counter()
        from hdid._fitting._batch import CHUNKS_PER_WORKER

        chunk = max(1, -(-len(timed) // (CHUNKS_PER_WORKER * W)))  # as fit_many(workers=W)
        table = hdid.fit_many(timed, client=client, chunk_size=chunk)
        out["total_s"] = time.perf_counter() - t
        after = client.run(_usage)
        out.update(cpu_s=(_usage()[0] - c0) + sum(after[k][0] - before[k][0] for k in after),
                   maxrss_mb=max(v[1] for v in after.values()), timing=table.attrs["timing"],
                   **_quality(timed, table))
    finally:
        client.close()
        cluster.close()
    return out


def run_worker(cfg: dict, cache_dir: Path, timeout: float = 3600) -> dict:
    env = _common.user_env(HDID_CACHE_DIR=str(cache_dir))
    if cfg.get("tree"):  # another checkout's hdid (its src first on the path)
        env["PYTHONPATH"] = str(Path(cfg["tree"]) / "src")
    wall, _, out = _common.run_timed([sys.executable, __file__, "--worker", json.dumps(cfg)], env, timeout,
                                     cwd=ROOT / "benchmarks")
    return _common.last_json(out) | {"process_s": wall}


def measure(args) -> dict:
    log_dir, cache = Path(args.log_dir), Path(tempfile.mkdtemp(prefix="hdid_batch_cache_"))
    res = {"load_start": load("script start"), "machine": _common.machine(), "quick": args.quick, "runs": []}
    ns = [1, 10, 100] if args.quick else [1, 10, 100, args.n]
    print("making logs ...", flush=True)
    t_script = time.perf_counter()
    paper = make_logs("paper", WARMUP + max(ns), log_dir)
    res["log_generation_s"] = time.perf_counter() - t_script

    def go(label, mode, n, design="paper", paths=None, **extra):
        if any(map(label.startswith, args.skip or ())) or (args.only and not any(map(label.startswith, args.only))):
            return None
        paths = paths or make_logs(design, WARMUP + n, log_dir)
        cfg = {"label": label, "mode": mode, "design": design, "paths": paths[: WARMUP + n], **extra}
        if extra.get("tree"):  # the older checkout's commit
            res["before"] = {"tree": extra["tree"], "commit": subprocess.run(
                ["git", "-C", extra["tree"], "log", "-1", "--format=%h %s"],
                capture_output=True, text=True).stdout.strip()[:100]}
        print(f"{label} ...", flush=True)
        r = run_worker(cfg, cache)
        r["config"].pop("paths")
        res["runs"].append(r)
        print(f"  {r['n'] / r['total_s']:.2f} logs/s ({r['total_s']:.1f} s), "
              f"rss {r['maxrss_mb']:.0f} MB, load {r['load_after']['load1']:.1f}", flush=True)
        return r

    # compile: empty cache, then populated (the first vectorised worker populates it)
    go("vectorized, cold cache, 1 log", "vectorized", 1, paths=paper)
    go("vectorized, warm cache, 1 log", "vectorized", 1, paths=paper)
    for n in ns:
        go(f"vectorized {n}", "vectorized", n, paths=paper)
    if args.before:  # the same logs through the older tree, right after
        go(f"before: vectorized {max(ns)}", "vectorized", max(ns), paths=paper, tree=str(Path(args.before).resolve()))
    # several cores: worker processes (threads in one process do not add cores)
    for n in ns[-2:]:
        go(f"workers 2, {n}", "workers", n, paths=paper, workers=2)
    for design in (*list(DESIGNS)[1:], "paper"):
        go(f"design {design}, 20 logs", "vectorized", 20, design=design, paths=paper if design == "paper" else None)
    res |= {"script_s": time.perf_counter() - t_script, "load_end": load("script end")}
    shutil.rmtree(cache, ignore_errors=True)
    return res


def _find(res, label):
    return next((r for r in res["runs"] if r["config"]["label"] == label), None)


def _rate(r):
    return r["n"] / r["total_s"]


def _cpu_ms(r):
    """CPU ms per log (NaN where not measured)."""
    return r["cpu_s"] / r["n"] * 1e3 if r.get("cpu_s") is not None else float("nan")


def _ld(r):
    return f"{r['load_before']['load1']:.1f}→{r['load_after']['load1']:.1f}"


def _dchi2(a: dict, b: dict) -> list[float]:
    """|Δ best χ²| of two runs on the logs both fitted."""
    x = {p["log"]: p["chi2"] for p in a.get("per_log") or [] if p}
    return [abs(x[p["log"]] - p["chi2"]) for p in b.get("per_log") or [] if p and p["log"] in x]


def render(res: dict) -> str:
    m = res["machine"]
    L = ["# Batch speed: `fit_many`, vectorised and with worker processes\n",
         f"Generated by `python benchmarks/batch_speed.py{' --quick' if res['quick'] else ''}` on {m['date']} "
         f"(script {res['script_s']:.0f} s; src {m['src_fingerprint']}). Machine: {m['nproc']} cores ({m['cpu']}), "
         f"python {m['python']}, jax {m['jax']} ({m.get('backend', m.get('jax_backend'))}). Load average at start "
         f"{res['load_start']['load1']:.1f}, at end {res['load_end']['load1']:.1f}: the 2 cores are shared with "
         "other engineers' jobs, so every row gives the 1-min load before→after it; a load above 2 means hdid got "
         "less than the 2 cores.\n"]
    L += [f"Re-measured with `--only {' '.join(repr(o) for o in rr['only'])}` on {rr['machine']['date']} (src "
          f"{rr['machine']['src_fingerprint']}, load {rr['load_start']['load1']:.1f} → {rr['load_end']['load1']:.1f}): "
          "those rows replace the first run's.\n" for rr in res.get("reruns", [])]
    L.append("Logs: paper design (4 runs ±0.157 rad, 250 Hz, 0.5 s per run, 125 samples), truths k1, tau_c, tau_s, "
             "c_v drawn log-normal (sd 15 %) around the CSF-8 values, made with `hdid.reference.logs.make_log`. "
             "Every configuration runs in a fresh subprocess: it first fits 2 other logs (compile or "
             "persistent-cache read; reported as *first call*), then the N timed logs; peak RSS is that process's.\n")

    vec = sorted((r for r in res["runs"] if r["config"]["label"].startswith("vectorized ")
                  and r["config"]["label"].split()[1].isdigit()
                  and "," not in r["config"]["label"]), key=lambda r: r["n"])

    v1000 = _find(res, "vectorized 1000")
    big = v1000 or max(vec, key=lambda r: r["n"])
    wk = [r for r in res["runs"] if r["config"]["mode"] == "workers"]
    wbig = max(wk, key=lambda r: r["n"]) if wk else None
    L += ["## Goals\n", *header("goal", "measured", "met?")]
    if wbig:
        tw = wbig["total_s"] * 1000 / wbig["n"]
        how = "measured" if wbig["n"] == 1000 else f"extrapolated from {wbig['n']} logs"
        L.append(f"| 1000 logs ≤ {GOAL_1000_S:.0f} s on 2 cores | **{tw:.0f} s** with `workers=2` (2 processes on a "
                 f"warm LocalCluster; {how}; load {_ld(wbig)}) | {'✓' if tw <= GOAL_1000_S else '✗'} |")
    t1000 = big["total_s"] * 1000 / big["n"]
    how = "measured" if v1000 else f"extrapolated from {big['n']} logs"
    L.append(f"| … in one process (one core: JAX runs one CPU program at a time per process) | "
             f"{t1000:.0f} s ({how}; load {_ld(big)}) | — |")
    if big.get("cpu_s"):
        t2 = big["cpu_s"] * 1000 / big["n"] / 2
        L.append(f"| 1000 logs ≤ {GOAL_1000_S:.0f} s on 2 quiet cores, from the CPU time per log "
                 f"('{big['config']['label']}': {big['cpu_s'] / big['n'] * 1e3:.0f} ms) × 1000 / 2 processes (a "
                 f"lower bound: perfect split, no worker start) | {t2:.0f} s | {'✓' if t2 <= GOAL_1000_S else '✗'} |")
    L.append("")
    if wk:
        L += ["Several cores (`fit_many(workers=2)` / `hdid fit --workers 2`): logs are split into about 8 chunks per "
              "worker process (as `workers=2` does); the timed call runs on a cluster whose workers have each fitted 2 "
              "logs already (*first call*: cluster start plus every worker's trace/compile or cache read).\n",
              *header("N logs", "wall", "logs/s", "CPU per log (all processes)", "speed-up vs one process",
                      "first call", "peak RSS (a worker)", "load")]
        for r in sorted(wk, key=lambda r: r["n"]):
            one = _find(res, f"vectorized {r['n']}")
            up = f"{_rate(r) / _rate(one):.2f}×" if one else "—"
            L.append(f"| {r['n']} | {r['total_s']:.1f} s | {_rate(r):.2f} | {_cpu_ms(r):.0f} ms | {up} | "
                     f"{r['first_call_s']:.1f} s | {r['maxrss_mb']:.0f} MB | {_ld(r)} |")
        L.append("")

    L += ["## logs/s (4-run paper-design logs)\n", "(`hdid.fit` log by log and the scipy way: `fit_speed.md`.)\n",
          *header("N logs", "vectorised `fit_many`", "CPU per log", "peak RSS", "first call (compile)", "load")]
    for r in vec:
        L.append(f"| {r['n']} | {_rate(r):.2f} ({r['total_s']:.1f} s) | {_cpu_ms(r):.0f} ms | "
                 f"{r['maxrss_mb']:.0f} MB | {r['first_call_s']:.1f} s | {_ld(r)} |")
    L.append("")
    L += _common.interpretation_section(res)
    L += _before_after(res, big)
    L += ["", "## Where the vectorised time goes\n",
          "Wall seconds, and CPU seconds (process time, both threads) in brackets.\n",
          *header("N", "total", "compile", "setup (read, prepare)", "grid", "LM (phases 1+2)", "analysis",
                  "LM lane-steps", "CPU µs per lane-step")]
    for r in vec:
        t = r["timing"]
        both = lambda k, t=t: f"{t[f'{k}_s']:.2f} s" + (  # noqa: E731
            f" ({c:.2f})" if (c := t.get(f"{k}_cpu_s")) is not None else "")
        L.append(f"| {r['n']} | {t['total_s']:.2f} s | {t['compile_s']:.2f} s | {both('setup')} | {both('grid')} | "
                 f"{both('solve')} | {both('analyse')} | {t['lane_steps']} | "
                 f"{1e6 * t.get('solve_cpu_s', t['solve_s']) / max(t['lane_steps'], 1):.0f} |")
    L += ["", "## Compile time (first call in a fresh process, 2 logs)\n",
          *header("persistent cache", "first call", "of which compile (trace + lower + XLA / cache read)")]
    for label, what in (("vectorized, cold cache, 1 log", "empty"), ("vectorized, warm cache, 1 log", "populated")):
        if r := _find(res, label):
            L.append(f"| {what} | {r['first_call_s']:.1f} s | {r['first_call_timing']['compile_s']:.1f} s |")
    L.append("\nIn a warm process (the timed calls above) `compile_s` is 0: one compiled "
             "program per bucket shape is reused for every log.\n")
    L += ["## Cost vs design (20 logs each, vectorised)\n",
          *header("design", "samples per run", "runs", "logs/s", "ms per log (wall)", "CPU ms per log", "first call",
                  "peak RSS", "load")]
    for design in DESIGNS:
        if not (r := _find(res, f"design {design}, 20 logs")):
            continue
        amps, fs, dur = DESIGNS[design]
        L.append(f"| {design} | {round(fs * dur)} | {len(amps)} | {_rate(r):.2f} | {1e3 / _rate(r):.0f} | "
                 f"{_cpu_ms(r):.0f} | {r['first_call_s']:.1f} s | {r['maxrss_mb']:.0f} MB | {_ld(r)} |")
    L += ["", "Where the time goes and why the batch is built this way (one lane per program, "
          "processes not threads, what was tried): `docs/decisions/batch-lanes.md`.\n"]
    fails = [(r["config"]["label"], r.get("n_failed", 0), r.get("errors")) for r in res["runs"] if r.get("n_failed")]
    if fails:
        L.append("Failed logs: " + "; ".join(f"{a}: {b} ({c})" for a, b, c in fails) + "\n")
    return "\n".join(L) + "\n"


def _before_after(res: dict, after: dict) -> list[str]:
    """The before/after table: the same N logs through ``--before``'s tree and this one."""
    before = _find(res, f"before: vectorized {after['n']}")
    if not before:
        return []
    b = res.get("before", {})
    L = ["", f"## Before/after: the same {after['n']} logs, `fit_many` in one process\n",
         f"Before: `{b.get('commit', '?')}` (a detached worktree, its own `src`); after: this tree. Each in a fresh "
         "process after its 2-log warm-up, one after the other; CPU is the process's (load below: the 1-min load "
         "before→after each).\n", *header("tree", "wall", "ms per log (wall)", "CPU ms per log", "LM iterations",
                                           "grid CPU", "LM CPU", "analysis CPU", "load")]
    for name, r in (("before", before), ("after", after)):
        t = r["timing"]
        L.append(f"| {name} | {r['total_s']:.1f} s | {1e3 * r['total_s'] / r['n']:.0f} | "
                 f"{_cpu_ms(r):.0f} | {t['lane_steps']} | {t['grid_cpu_s']:.2f} s | "
                 f"{t['solve_cpu_s']:.2f} s | {t['analyse_cpu_s']:.2f} s | {_ld(r)} |")
    if d := _dchi2(after, before):
        L.append(f"\nBest χ² after vs before, same {len(d)} logs: max |Δχ²| = {max(d):.2g}, logs with |Δχ²| > 0.1: "
                 f"{sum(v > 0.1 for v in d)} (χ² in units of the quantization variance). (Before, the batch's 'LM' "
                 "time included its grid.)")
    return L


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true", help="fewer and smaller runs (≈ 6 min)")
    ap.add_argument("--log-dir", default=str(Path(tempfile.gettempdir()) / "hdid_batch_logs"),
                    help="where the generated logs are cached")
    ap.add_argument("--n", type=int, default=1000, help="the largest batch (default 1000; "
                    "the 1000-log figures are then extrapolated)")
    ap.add_argument("--before", metavar="TREE", help="also the largest batch with TREE's src "
                    "(a worktree of an older commit): a before/after table in the same run")
    ap.add_argument("--worker", help=argparse.SUPPRESS)  # one configuration, in a subprocess
    ap.add_argument("--only", nargs="+", metavar="LABEL",
                    help="measure only the configurations whose label starts with one of "
                         "these (e.g. 'workers 2'), replacing those rows of the stored JSON")
    ap.add_argument("--skip", nargs="+", metavar="LABEL",
                    help="leave out the configurations whose label starts with one of these "
                         "(to be measured later with --only, e.g. on free cores)")
    if (args := _common.parse_or_render(ap, argv, NAME, render)) is None:
        return
    if args.worker:
        print(json.dumps(worker(json.loads(args.worker))))
        return
    res = measure(args)
    if args.only:  # merge into the previous full run, replacing rows by label
        prev, new = _common.stored(NAME), {r["config"]["label"]: r for r in res["runs"]}
        prev["runs"] = [new.pop(r["config"]["label"], r) for r in prev["runs"]] + list(new.values())
        prev.setdefault("reruns", []).append({"only": args.only, **{k: res[k] for k in (
            "load_start", "load_end", "machine", "script_s")}})
        if "before" in res:  # the before/after rows were re-measured: their commit too
            prev["before"] = res["before"]
        res = prev
    _common.write_result(NAME, res, render)
    print(render(res))


if __name__ == "__main__":
    main()
