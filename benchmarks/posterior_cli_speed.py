"""Time of ``hdid fit LOG.csv --posterior`` on 4-run paper logs: this tree's sampler side by
side with another tree's (today's sampler), in the same run, alternating per log.

Run (pinned to one core)::

    taskset -c 1 python benchmarks/posterior_cli_speed.py --old-src /tmp/wt-old/src \
        [--logs 5] [--seed0 7100] [--timeout 900]

Logs: the shipped ``data/synthetic/csf8_paper.csv`` and ``--logs − 1`` paper-design logs
from the independent simulator (``generate.make_log``, truths drawn as in
``posterior_sbc.py``, seeds ``seed0 + i``). Each is fitted and sampled by a fresh
``python -m hdid.cli fit LOG --posterior -q --json OUT`` process with ``PYTHONPATH`` set to
the tree under test (the whole process is timed: imports, fit, JIT compilation, mode
search, sampling), and the JSON's ``posterior_diagnostics`` gives the sampler's own wall
time, its compile time (this tree only) and its convergence verdict. ``os.getloadavg()``
beside every run. Writes ``benchmarks/results/posterior_cli_speed.{json,md}``.

``--mode-search`` measures instead the mode search in a fresh process, its own LM program
against the fit's (issue 17, ``post4``)::

    taskset -c 1 python benchmarks/posterior_cli_speed.py --mode-search --old-src OLD/src [--logs 3]

For each log and each tree (``--old-src``: the mode search before, ``--new-src``: this
one), alternating, one fresh process with an *empty* persistent compilation cache
(``HDID_CACHE_DIR`` a new temporary folder: a log the cache has never seen, as for a
user's new log) runs ``hdid.fit(log)`` and then ``find_modes(fit)``. Before ``post4`` the
search compiled three programs of its own (its LM at its own lane count, the
residual-and-Jacobian at an optimum, the costs along a path); now it runs the fit's LM
program in calls of the fit's lane count (``MODE_LANES``) and the Jacobian program of the
fit's analysis. Writes ``posterior_mode_search_speed.{json,md}``.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import argparse
import datetime as _dt
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
SHIPPED = ROOT / "data" / "synthetic" / "csf8_paper.csv"


def _load():
    return [round(x, 2) for x in os.getloadavg()]


def run_cli(src, log, out, timeout):
    env = dict(os.environ, PYTHONPATH=str(src))
    t0 = time.perf_counter()
    la0 = _load()
    try:
        p = subprocess.run([sys.executable, "-c", "from hdid.cli import main; main()", "fit",
                            str(log), "--posterior", "-q", "--json", str(out)],
                           env=env, capture_output=True, text=True, timeout=timeout)
        rc, err = p.returncode, p.stderr[-2000:]
    except subprocess.TimeoutExpired:
        rc, err = "timeout", ""
    wall = time.perf_counter() - t0
    r = {"process_s": wall, "rc": rc, "load_start": la0, "load_end": _load()}
    if rc == 0:
        d = json.loads(Path(out).read_text())["posterior_diagnostics"]
        conv = d.get("convergence") or {}
        r.update(posterior_s=d["wall_time_s"], compile_s=d.get("compile_s"),
                 mode_search_s=d.get("mode_search_s"), converged=d["converged"],
                 criterion=conv.get("criterion", "chain >= 50 tau (old sampler)"),
                 steps=d["n_steps"], burn_in=d["burn_in"], tau_max=d["tau_max"],
                 method=d.get("method"), engine=d.get("engine"), stage_s=d.get("stage_s"),
                 chain_in_tau=d["chain_in_tau_max"], rhat_max=conv.get("rhat_max"),
                 ess_bulk_min=conv.get("ess_bulk_min"), ess_tail_min=conv.get("ess_tail_min"),
                 met_by=conv.get("met_by"),
                 band95=json.loads(Path(out).read_text())["posterior"]["stick_band_halfwidth_rad"]["ci95"])
    else:
        r["stderr"] = err
    return r


CHILD = r"""
import json, sys, time
import hdid
hdid.configure()
from hdid._posterior import modes
t0 = time.perf_counter(); fit = hdid.fit(sys.argv[1]); t1 = time.perf_counter()
found = modes.find_modes(fit)
t2 = time.perf_counter()
print(json.dumps({"fit_s": t1 - t0, "modes_s": t2 - t1, "n_modes": len(found),
                  "costs": [m.cost for m in found]}))
"""


def run_modes(log, src):
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, PYTHONPATH=str(src), HDID_CACHE_DIR=cache)
        la = _load()
        p = subprocess.run([sys.executable, "-c", CHILD, str(log)], env=env,
                           capture_output=True, text=True, timeout=900)
        if p.returncode != 0:
            return {"rc": p.returncode, "stderr": p.stderr[-2000:], "load_start": la}
        r = json.loads(p.stdout.strip().splitlines()[-1])
        r.update(rc=0, load_start=la, load_end=_load())
        return r


def render_modes(res):
    L = ["# Mode search in a fresh process: before (programs of its own) and after (the fit's)\n",
         f"Generated by `python benchmarks/posterior_cli_speed.py --mode-search` on {res['generated']} "
         f"(before: `{res.get('old_src')}`, after: `{res.get('new_src')}`); "
         "one core of a 2-core machine shared with other engineers; each run a fresh process "
         "with an empty compilation cache.\n",
         "| log | variant | fit s | mode search s | optima (costs) | load start → end |",
         "|---|---|---|---|---|---|"]
    for r in res["rows"]:
        if r["rc"] != 0:
            L.append(f"| {r['log']} | {r['variant']} | failed | | | {r['load_start'][0]} |")
            continue
        L.append(f"| {r['log']} | {r['variant']} | {r['fit_s']:.1f} | {r['modes_s']:.1f} | "
                 f"{r['n_modes']} ({', '.join(f'{c:.1f}' for c in r['costs'])}) | "
                 f"{r['load_start'][0]} → {r['load_end'][0]} |")
    return "\n".join(L) + "\n"


def _f(v, spec):
    return "" if v is None else format(v, spec)


def _rule(r, arviz):
    """The rule that passed (``met_by``) or, failing/older trees, the criterion's family."""
    if r.get("met_by"):
        return r["met_by"]
    if not arviz:
        return "50 τ, old sampler"
    return "R-hat or 50 τ" if "tau" in str(r.get("criterion", "")) else "arviz"


def render(res):
    L = ["# `hdid fit LOG --posterior`: new sampler vs today's, 4-run paper logs\n",
         f"Generated by `python benchmarks/posterior_cli_speed.py` on {res['generated']}; "
         f"trees: new = `{res['new_src']}`, old = `{res['old_src']}`. One core of a 2-core "
         "machine shared with other engineers (loads per run below).\n",
         "| log | sampler | process s | posterior s | compile s | mode search s | converged "
         "(criterion) | steps (+burn-in) | R-hat max | ESS bulk/tail min | chain / τ_max | "
         "band 95 % [mrad] | load start → end |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for row in res["rows"]:
        for k in ("new", "old"):
            r = row.get(k)
            if r is None:
                continue
            if r.get("rc") != 0:
                L.append(f"| {row['log']} | {k} | {r['process_s']:.0f} | failed ({r['rc']}) "
                         "| | | | | | | | | |")
                continue
            b = r["band95"]
            arviz = r["rhat_max"] is not None
            L.append(
                f"| {row['log']} | {k} | {r['process_s']:.0f} | {r['posterior_s']:.0f} | "
                f"{_f(r['compile_s'], '.1f')} | {_f(r['mode_search_s'], '.1f')} | "
                f"{'yes' if r['converged'] else 'NO'} ({_rule(r, arviz)}) | "
                f"{r['steps']} (+{r['burn_in']}) | {_f(r['rhat_max'], '.3f')} | "
                f"{_f(r['ess_bulk_min'], '.0f')}/{_f(r['ess_tail_min'], '.0f')} | "
                f"{r['chain_in_tau']:.1f} | {1e3 * b[0]:.1f}–{1e3 * b[1]:.1f} | "
                f"{r['load_start'][0]} → {r['load_end'][0]} |")
    for k in ("new", "old"):
        ok = [row[k] for row in res["rows"] if row.get(k, {}).get("rc") == 0]
        if ok:
            L.append(f"\n{k}: median process {statistics.median(r['process_s'] for r in ok):.0f} s, "
                     f"median posterior {statistics.median(r['posterior_s'] for r in ok):.0f} s, "
                     f"converged {sum(r['converged'] for r in ok)}/{len(ok)}.")
    return "\n".join(L) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--old-src", type=Path)
    ap.add_argument("--new-src", type=Path, default=ROOT / "src")
    ap.add_argument("--logs", type=int, default=5)
    ap.add_argument("--seed0", type=int, default=7100)
    ap.add_argument("--timeout", type=float, default=900)
    ap.add_argument("--only", default="new,old")
    ap.add_argument("--out-dir", type=Path, default=RESULTS)
    ap.add_argument("--name", default=None)
    ap.add_argument("--mode-search", action="store_true",
                    help="time the mode search (own LM program vs the fit's) instead")
    args = ap.parse_args(argv)
    import posterior_sbc as sbc

    gen = _common.import_generate()
    tmp = Path(tempfile.mkdtemp())
    logs = [("csf8_paper.csv", SHIPPED)]
    for i in range(args.logs - 1):
        import numpy as np

        seed = args.seed0 + i
        truth = sbc.draw_truth(gen, np.random.default_rng(seed), 0.157)
        d = dict(gen.PAPER_DESIGN, seed=seed)
        p = tmp / f"paper_{seed}.csv"
        gen.make_log(truth, **d).to_csv(p, index=False)
        logs.append((p.name, p))
    if args.mode_search:
        name = args.name or "posterior_mode_search_speed"
        res = {"generated": _dt.datetime.now().isoformat(timespec="seconds"), "rows": [],
               "old_src": str(args.old_src), "new_src": str(args.new_src)}
        for log_name, path in logs:
            if args.old_src is None:
                ap.error("--mode-search needs --old-src (the tree before)")
            for variant, src in (("before", args.old_src), ("after", args.new_src)):
                r = run_modes(path, src)
                r.update(log=log_name, variant=variant)
                res["rows"].append(r)
                print(log_name, variant, {k: r.get(k) for k in ("fit_s", "modes_s", "n_modes", "rc")},
                      _load(), flush=True)
                (args.out_dir / f"{name}.json").write_text(json.dumps(res, indent=1))
                (args.out_dir / f"{name}.md").write_text(render_modes(res))
        return
    args.name = args.name or "posterior_cli_speed"
    if args.old_src is None:
        ap.error("--old-src is required (without --mode-search)")
    res = {"generated": _dt.datetime.now().isoformat(timespec="seconds"),
           "new_src": str(args.new_src), "old_src": str(args.old_src), "rows": []}
    out = args.out_dir / f"{args.name}.json"
    for name, path in logs:
        row = {"log": name}
        for k in args.only.split(","):
            src = args.new_src if k == "new" else args.old_src
            row[k] = run_cli(src, path, tmp / f"{k}.json", args.timeout)
            print(name, k, {x: row[k].get(x) for x in ("process_s", "posterior_s", "converged", "rc")},
                  _load(), flush=True)
        res["rows"].append(row)
        out.write_text(json.dumps(res, indent=1))
        (args.out_dir / f"{args.name}.md").write_text(render(res))


if __name__ == "__main__":
    sys.exit(main())
