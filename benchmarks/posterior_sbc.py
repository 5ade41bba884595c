"""Simulation-based calibration of the posterior under its default priors (coverage, ranks,
convergence, time; emcee and SMC on the same fits); ``--cli``: ``hdid fit LOG --posterior`` timed
as a process, the result's CLI-speed section (each mode keeps the other's section).

    taskset -c 1 python benchmarks/posterior_sbc.py [--paper-logs 20 --rich-logs 20] [--seed0 34000]
        [--max-steps 20000] [--end-by S] [--method emcee,smc]
    taskset -c 1 python benchmarks/posterior_sbc.py --cli [--logs 1] [--repeats 3]
    python benchmarks/posterior_sbc.py [--cli] --render [--interpretation FILE]
"""

import argparse
import functools
import json
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
import traceback
from pathlib import Path

import _common
import numpy as np
from _common import DATA, ROOT
from scipy.stats import binomtest

CHECKED = ("k1", "k2", "tau_c", "tau_s", "c_v", "stick_band_halfwidth_rad")
REPORTED = CHECKED + ("v_s", "delta")
BINS = 10
#: A drawn truth is redrawn until its stick band is narrower than this fraction of the design's smallest release
#: amplitude (a release inside the band never moves: the log would have a run without motion, which hdid rejects).
BAND_MARGIN = 0.9
DEFAULT_PRIOR_NAMES = ("k1", "k2", "tau_c", "tau_s", "c_v", "v_s", "delta")


@functools.cache
def nominal_default_prior(design_name):
    """``{name: (centre value, sd in the transformed space)}``: the default priors of the
    design's nominal log (see ``DEFAULT_PRIOR_NAMES``)."""
    from hdid._fitting._fit import _setup
    from hdid._models._transforms import from_unconstrained
    from hdid._posterior.priors import default_priors
    from hdid.reference import logs as gen

    cat = dict(gen.TRUTH_CSF8)
    design = getattr(gen, design_name.upper() + "_DESIGN")  # PAPER_DESIGN / RICH_DESIGN
    prob = _setup(gen.make_log(cat, **dict(design, seed=0)), inertia=cat["inertia"]).problem
    specs, pri = prob.base.parameter_specs(), default_priors(prob)
    return {n: (float(from_unconstrained(specs[n], pri[n].mean, np)), float(pri[n].sd)) for n in DEFAULT_PRIOR_NAMES}


def draw_default(gen, rng, design_name, design):
    """A truth from :func:`nominal_default_prior` (log-normal; delta logit-normal on its
    interval); returns ``(truth, band rejections, order rejections)``."""
    from hdid.effects.stribeck import DELTA_INTERVAL
    from hdid.reference import stick_band_halfwidth

    pri = nominal_default_prior(design_name)
    lo, hi = DELTA_INTERVAL
    amp = min(abs(a) for a in design["amplitudes"])
    band_rejects = order_rejects = 0
    for _ in range(100000):
        t = dict(gen.TRUTH_CSF8)
        for n, (c, sd) in pri.items():  # delta: logit-normal on its interval; the others log-normal
            z = (math.log((c - lo) / (hi - c)) if n == "delta" else 0.0) + sd * rng.standard_normal()
            t[n] = lo + (hi - lo) / (1 + math.exp(-z)) if n == "delta" else c * math.exp(z)
        if t["tau_s"] < t["tau_c"]:
            order_rejects += 1
            continue
        band = stick_band_halfwidth(t["k1"], t["k2"], t["tau_s"], t.get("ratio", 100.0))
        if band < BAND_MARGIN * amp:
            return t, band_rejects, order_rejects
        band_rejects += 1
    raise RuntimeError("no truth with a band inside the design's smallest amplitude")


def inside_cut(values, ratio, design):
    """Draws (``values``: k1, k2, tau_s arrays) whose stick band is below ``BAND_MARGIN`` ×
    the design's smallest release, the cut :func:`draw_default` makes: the band ``θ_b``
    solves ``k1·(θ_b/N) + k2·(θ_b/N)³ = N·tau_s`` (``reference.stick_band_halfwidth``),
    monotone for ``k2 ≥ 0``, so ``θ_b < B`` is ``k1·x + k2·x³ > N·tau_s`` at ``x = B/N``."""
    x = BAND_MARGIN * min(abs(a) for a in design["amplitudes"]) / ratio
    k1, k2, ts = (np.asarray(values[n], dtype=float) for n in ("k1", "k2", "tau_s"))
    return k1 * x + k2 * x**3 > ratio * ts


def draw_noise(gen, seed, noise="prior"):
    """The log's noise σ_n [rad] before rounding: ``"prior"``, from the sampler's prior
    (log-uniform on ``density.SIGMA_BOUNDS`` steps, its own stream); ``"none"``, 0 (rounding alone);
    ``"analog"``, ``step/√12`` on readings left unrounded (:func:`draw_log`). (``"moving"``, noise after each
    release only, ran at ec586c5: the check section of ``results/posterior_sbc.md``.)"""
    from hdid._posterior.density import SIGMA_BOUNDS

    if noise == "none":
        return 0.0
    if noise == "analog":
        return 2 * math.pi / gen.COUNTS_PER_REV / math.sqrt(12)
    lo, hi = (math.log(b * 2 * math.pi / gen.COUNTS_PER_REV) for b in SIGMA_BOUNDS)
    return math.exp(np.random.default_rng([seed, 1]).uniform(lo, hi))


def draw_log(gen, design_name, seed, noise="prior"):
    """The calibration's log ``seed`` of a design (``"paper"`` / ``"rich"``): ``(truth, log, generator info, notes)``,
    the truth drawn by :func:`draw_default` from ``rng(seed)``, the noise by :func:`draw_noise`. ``noise="analog"``:
    the readings are not rounded (every reading at full weight, Gaussian noise: the sampler's likelihood is then the
    generator's exactly, a check that rounding is not what miscalibrates)."""
    design = getattr(gen, design_name.upper() + "_DESIGN")
    truth, band_rejects, order_rejects = draw_default(gen, np.random.default_rng(seed), design_name, design)
    sigma = draw_noise(gen, seed, noise)
    df, info = gen.make_log(truth, **dict(design, seed=seed), noise_std=sigma, return_truth=True,
                            quantize=noise != "analog")
    return truth, df, info, {"band_rejects": band_rejects, "order_rejects": order_rejects, "noise_sigma_rad": sigma}


def run_one(gen, design_name, seed, max_steps, method="emcee,smc", noise="prior"):
    """One log: fit once and basin-check it (the fit the samplers sample), its optima once, then each sampler."""
    import hdid
    from hdid._posterior.basin import basin_check
    from hdid._posterior.density import posterior_density
    from hdid._posterior.modes import sampled_modes

    truth, df, info, notes = draw_log(gen, design_name, seed, noise)
    design, prior = getattr(gen, design_name.upper() + "_DESIGN"), nominal_default_prior(design_name)
    base = {"design": design_name, "seed": seed, "truth_params": truth, "load_start": _common.loads(),
            "prior": "default", "band_rejects": notes["band_rejects"], "truth_notes": notes}
    t0, c0 = time.perf_counter(), time.process_time()  # CPU s beside wall s: a starved core shows
    fit = basin_check(hdid.fit(df, inertia=truth["inertia"]), df, echo=False)[0]
    base["fit_s"], t1 = time.perf_counter() - t0, time.perf_counter()
    dens = posterior_density(fit, prior=prior)
    modes = sampled_modes(fit, "auto", seed % 1000, dens.u_fit, dens.lin, dens.lp.gauss_prior)
    modes_s = time.perf_counter() - t1
    tv = {**{n: float(truth[n]) for n in REPORTED if n in truth}, "noise_sigma_rad": notes["noise_sigma_rad"],
          "stick_band_halfwidth_rad": float(info["stick_band_halfwidth"])}
    outs = []
    for m in method.split(","):
        out, t1 = dict(base, load_start=_common.loads()), time.perf_counter()
        kw = {} if m == "smc" else {"max_steps": max_steps}
        post = hdid.sample_posterior(fit, seed=seed % 1000, method=m, prior=prior, modes=modes, log=df, **kw)
        out.update(posterior_s=time.perf_counter() - t1 + modes_s, load_end=_common.loads())
        diag = post.to_dict()["posterior_diagnostics"]
        c = diag["convergence"]
        out.update(steps=int(post.chain.shape[0]), converged=bool(post.converged), rhat_max=c["rhat_max"],
                   met_by=c.get("met_by"), ess_bulk_min=c["ess_bulk_min"], ess_tail_min=c["ess_tail_min"],
                   tau_max=diag["tau_max"], compile_s=post.compile_s, stage_s=post.stage_s, mode_search_s=modes_s,
                   n_modes=len(post.modes), move_acceptance=diag["move_acceptance"], warnings=list(post.warnings),
                   widths=post.to_dict()["posterior_width"], method=post.method,
                   smc={k: v for k, v in post.smc.items() if k != "betas"})
        values, q = {**post.samples, **post.derived}, {}
        # the truths' prior is the sampler's cut to bands below BAND_MARGIN × the smallest
        # release: the draws are conditioned on the same cut (else SBC is biased by construction)
        keep = inside_cut(values, truth.get("ratio", 100.0), design)
        out["cut_share"] = float(1.0 - keep.mean())
        if keep.sum() < 2:  # every draw outside the cut: ranked uncut (the row says so)
            keep = np.ones_like(keep)
        for n in REPORTED + ("noise_sigma_rad",):
            v, tr = np.asarray(values[n])[keep], tv[n]
            lo95, lo68, med, hi68, hi95 = np.percentile(v, [2.5, 16, 50, 84, 97.5])
            q[n] = {"truth": tr, "median": med, "ci95": [lo95, hi95], "ci68": [lo68, hi68],
                    "cover95": bool(lo95 <= tr <= hi95), "cover68": bool(lo68 <= tr <= hi68),
                    "rank": float(np.mean(v < tr)), "n_draws": int(v.size)}
        outs.append(out | {"quantities": q, "total_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0})
    return outs


def samples_per_period(r):
    """Readings a period of the true swing ``√(k1/(J·N²))/2π``, hardened at the largest release (``swing_hz``)."""
    from hdid._simulation._aliasing import swing_hz
    from hdid.reference import logs as gen
    t, d = r["truth_params"], getattr(gen, r["design"].upper() + "_DESIGN")
    n, amp = t.get("ratio", 100.0), max(abs(a) for a in d["amplitudes"])
    return d["fs"] / swing_hz(math.sqrt(t["k1"] / (t["inertia"] * n**2)) / (2 * math.pi), t, amp / n)


def _pooled(rs, what):
    """``what (n logs): k/m = x % [Wilson 95 %].``: pooled 95 % coverage of logs ``rs`` over ``CHECKED``."""
    k, m = sum(r["quantities"][n]["cover95"] for r in rs for n in CHECKED), len(rs) * len(CHECKED)
    return [f"{what} ({len(rs)}): {k}/{m} = {k / m:.1%} [{'{:.1%}, {:.1%}'.format(*_wilson(k, m))}]."] if m else []


def _wilson(k, n):
    """Wilson score 95 % interval of a binomial proportion ``k/n`` (``n`` > 0)."""
    return binomtest(int(k), n).proportion_ci(method="wilson")


def _steps(r):
    """emcee: kept steps; SMC: runs × particles, SMC steps (temperatures), log-Z sd."""
    m = r.get("smc") or {}
    return (f"SMC {m['n_runs']}×{m['n_particles']}, {m['steps']} ({m['temperatures']}), sd log Z "
            f"{m['log_evidence_sd']:.2f}" if r.get("method") == "smc" else str(r["steps"]))


def render(res):
    cli = "\n" + render_cli(res["cli"]) if "cli" in res else ""
    for key, sub in res.get("checks", {}).items():  # diagnostic runs kept beside the result
        cli = f"\n# Check: {key}\n\n{sub.get('about', '')}\n\n{_render(sub, sub['logs'], sub['options']['method'])}{cli}"
    if "logs" not in res:
        return cli.lstrip("\n")
    methods = list(dict.fromkeys(r.get("method") or res["options"].get("method", "emcee") for r in res["logs"]))
    if len(methods) <= 1:
        return _render(res, res["logs"]) + cli
    head = (f"# Posterior calibration, samplers side by side: {', '.join(methods)}\n\nEach log is fitted once and its "
            "optima found once; every sampler gets the same fit and optima (time of that search is counted in each "
            "sampler's time).\n\n" + "\n".join(_common.interpretation_section(res)))
    return head + "\n".join(_render(res, [r for r in res["logs"] if (r.get("method") or "emcee") == m], m)
                            for m in methods) + cli


def _where(res):
    """Where the logs ran, from the run's own machine record (each shard's, when merged)."""
    shards = res.get("shards") or []
    machines = sorted({q.get("machine") or "?" for q in shards} or {res.get("machine") or "a shared 2-core machine"})
    return (f"one core per log on {' / '.join(machines)}"
            + (f", {len(shards)} shards side by side (merged with --merge)" if len(shards) > 1 else ""))


def _render(res, all_logs, method=None):
    logs = [r for r in all_logs if "quantities" in r]
    L = [f"#{'#' if method else ''} Posterior SBC under the default priors{': sampler ' + method if method else ''}\n",
         f"Generated by `python benchmarks/posterior_sbc.py` on {res['generated']} (options "
         f"{json.dumps(res['options'])}); truths drawn from the sampler's prior (the default priors of each design's "
         f"nominal log); {_where(res)}; load averages (is it shared?) and CPU s per log in the JSON, loads below.\n",
         f"Logs done: {len(logs)} ({sum(r['design'] == 'paper' for r in logs)} paper design, "
         f"{sum(r['design'] == 'rich' for r in logs)} four-amplitude 1 kHz); failed: {len(all_logs) - len(logs)}.\n"]
    if not logs:
        return "\n".join(L)
    conv = [r for r in logs if r["converged"]]
    by_rule = {k: sum(r.get("met_by") == k for r in conv) for k in ("R-hat", "50 tau")}
    L += [f"**Converged (bulk/tail ESS ≥ 400 and R-hat ≤ 1.01 or a chain ≥ 50 τ, on every sampled quantity and "
          f"the band): {len(conv)} of {len(logs)}** (by R-hat {by_rule['R-hat']}, by 50 τ {by_rule['50 tau']}).\n",
          "## Coverage of the central intervals (truth inside)\n",
          "| quantity | 95 % paper | 95 % rich | 95 % pooled [Wilson 95 %] | 68 % pooled |", "|---|---|---|---|---|"]
    tot_k = tot_n = 0
    for n in REPORTED:
        rs = {des: [r["quantities"][n]["cover95"] for r in logs if r["design"] == des] for des in ("paper", "rich")}
        cells = [f"{sum(c)}/{len(c)}" if c else "–" for c in rs.values()]
        k, k68 = (sum(r["quantities"][n][c] for r in logs) for c in ("cover95", "cover68"))
        lo, hi = _wilson(k, len(logs))
        if n in CHECKED:
            tot_k, tot_n = tot_k + k, tot_n + len(logs)
        L.append(f"| {n}{'' if n in CHECKED else ' (not in the pooled figure)'} | {cells[0]} | {cells[1]} | "
                 f"{k}/{len(logs)} = {k / len(logs):.0%} [{lo:.0%}, {hi:.0%}] | {k68 / len(logs):.0%} |")
    lo, hi = _wilson(tot_k, tot_n)
    L.append(f"\nPooled 95 % coverage over k1, k2, tau_c, tau_s, c_v and the band: {tot_k}/{tot_n} = "
             f"{tot_k / tot_n:.1%} [{lo:.1%}, {hi:.1%}].\n")
    for des in ("paper", "rich", None):
        L += _pooled([r for r in conv if des in (None, r["design"])], f"Converged logs only, {des or 'both designs'}")
    spp = {id(r): samples_per_period(r) for r in logs}  # aliased: < 2.5 readings a period of the true swing
    for what, rs in (("\nAliased (< 2.5 readings a period of the true swing)", [r for r in logs if spp[id(r)] < 2.5]),
                     ("Resolved", [r for r in logs if spp[id(r)] >= 2.5])):
        L += _pooled(rs, f"{what} logs") + _pooled([r for r in rs if r["converged"]], f"{what.strip()} logs, converged only")
    basin = sum(any(w.startswith("WRONG BASIN") for w in r.get("warnings", [])) for r in logs)
    L.append(f"\nLogs with the WRONG BASIN statement: {basin} of {len(logs)}.\n")
    L += [f"## Rank of the truth among the draws ({BINS} bins, counts; uniform if calibrated)\n",
          "| quantity | " + " | ".join(f"{i / BINS:.1f}" for i in range(BINS)) + " |", "|---|" + "---|" * BINS]
    for n in REPORTED:
        h = [sum(min(BINS - 1, int(r["quantities"][n]["rank"] * BINS)) == b for r in logs) for b in range(BINS)]
        L.append(f"| {n} | " + " | ".join(str(c) for c in h) + " |")
    wr = {}
    for n, w in ((n, w) for r in logs for n, w in (r.get("widths") or {}).items()):
        wr.setdefault(n, []).append(w["posterior_over_prior_width"])
    if wr:
        L += ["\n## What the data narrowed: posterior sd / prior sd (transformed space)\n",
              "Median over the logs [min, max]; ≤ 0.71 'measured' (the data carry at least half the precision), "
              "> 0.89 'assumed' (the prior sets the interval).\n",
              "| parameter | median | min | max |", "|---|---|---|---|"]
        for n, v in wr.items():
            L.append(f"| {n} | {statistics.median(v):.2f} | {min(v):.2f} | {max(v):.2f} |")
    L += ["\n## Convergence and time per log\n", *_common.header(
        "design", "seed", "readings a period", "converged", "steps", "R-hat max", "ESS bulk min", "ESS tail min", "fit s",
        "posterior s (compile, mode search)", "load start → end", "misses (95 %)")]
    for r in logs:
        miss = [n for n in REPORTED if not r["quantities"][n]["cover95"]]
        spp = samples_per_period(r)
        conv_ = f"yes ({r['met_by']})" if r["converged"] else "NO"
        L.append(f"| {r['design']} | {r['seed']} | {spp:.2f} | {conv_} | {_steps(r)} | {r['rhat_max']:.3f} | "
                 f"{r['ess_bulk_min']:.0f} | {r['ess_tail_min']:.0f} | {r['fit_s']:.0f} | {r['posterior_s']:.0f} "
                 f"({r['compile_s']:.1f}, {r['mode_search_s']:.0f}) | {r['load_start'][0]} → {r['load_end'][0]} | "
                 f"{', '.join(miss) or '–'} |")
    for des, ts in ((d, [r["posterior_s"] for r in logs if r["design"] == d]) for d in ("paper", "rich")):
        if ts:
            L.append(f"\nMedian `sample_posterior` time, {des}: {statistics.median(ts):.0f} s ({_where(res)}, "
                     "see loads).")
    return "\n".join(L) + "\n"


SAMPLERS = ("emcee", "smc")


def run_cli(sampler, log, out, timeout):
    """One ``hdid fit LOG --posterior --sampler SAMPLER`` process: its wall time, the posterior's own
    (``sample_posterior``) and its convergence, from the JSON it writes."""
    env, t0, r = dict(os.environ, PYTHONPATH=str(ROOT / "src")), time.perf_counter(), {"load_start": _common.loads()}
    try:
        p = subprocess.run([sys.executable, "-c", "from hdid.cli import main; main()", "fit", str(log), "--posterior",
                            "--sampler", sampler, "-q", "--json", str(out)], env=env, capture_output=True, text=True,
                           timeout=timeout)
        rc, err = p.returncode, p.stderr[-2000:]
    except subprocess.TimeoutExpired:
        rc, err = "timeout", ""
    r.update(process_s=time.perf_counter() - t0, rc=rc, load_end=_common.loads())
    if rc != 0:
        return r | {"stderr": err}
    d = (full := json.loads(Path(out).read_text()))["posterior_diagnostics"]
    c = d.get("convergence") or {}
    return r | {"posterior_s": d["wall_time_s"], "converged": d["converged"],
                **{k: d.get(k) for k in ("compile_s", "mode_search_s", "burn_in")}, "steps": d.get("n_steps"),
                "chain_in_tau": d.get("chain_in_tau_max"),
                **{k: c.get(k) for k in ("met_by", "rhat_max", "ess_bulk_min", "ess_tail_min")},
                "band95": full["posterior"]["stick_band_halfwidth_rad"]["ci95"]}


def render_cli(res):
    f = lambda v, spec: "" if v is None else format(v, spec)  # noqa: E731
    L = ["## CLI speed: `hdid fit LOG --posterior`, emcee and SMC side by side, 4-run paper logs\n",
         f"Generated by `python benchmarks/posterior_sbc.py --cli` on {res['generated']} (src {res.get('src')}). One "
         "core of a 2-core machine shared with other work (loads per run below: the times are as noisy as those "
         "loads).\n", *([f"### Interpretation\n\n{res['interpretation']}\n"] if res.get("interpretation") else []),
         "| log | sampler | process s | posterior s | compile s | mode search s | converged (rule) | steps "
         "(+burn-in) | R-hat max | ESS bulk/tail min | chain / τ_max | band 95 % [mrad] | load start → end |", "|---" * 13 + "|"]
    for row in res["rows"]:
        for k, r in ((k, row[k]) for k in SAMPLERS if k in row):
            if r.get("rc") != 0:
                L.append(f"| {row['log']} | {k} | {r['process_s']:.0f} | failed ({r['rc']}) |" + " |" * 9)
                continue
            emcee = k == "emcee"
            steps = f"{r['steps']} (+{r['burn_in']})" if emcee else "–"
            L.append(
                f"| {row['log']} | {k} | {r['process_s']:.0f} | {r['posterior_s']:.0f} | {f(r['compile_s'], '.1f')} | "
                f"{f(r['mode_search_s'], '.1f')} | {'yes' if r['converged'] else 'NO'} ({r.get('met_by') or '–'}) | "
                f"{steps} | {f(r['rhat_max'], '.3f')} | {f(r['ess_bulk_min'], '.0f')}/{f(r['ess_tail_min'], '.0f')} | "
                f"{f(r['chain_in_tau'], '.1f') if emcee else '–'} | "
                f"{1e3 * r['band95'][0]:.1f}–{1e3 * r['band95'][1]:.1f} | {r['load_start'][0]} → {r['load_end'][0]} |")
    for k, ok in ((k, [row[k] for row in res["rows"] if row.get(k, {}).get("rc") == 0]) for k in SAMPLERS):
        if ok:
            L.append(f"\n{k}: median process {statistics.median(r['process_s'] for r in ok):.0f} s, "
                     f"median posterior {statistics.median(r['posterior_s'] for r in ok):.0f} s, "
                     f"converged {sum(r['converged'] for r in ok)}/{len(ok)}.")
    return "\n".join(L) + "\n"


def main_cli(args, gen):
    """``--cli``: the shipped paper log and ``--logs``−1 drawn ones, ``--repeats`` processes each per sampler."""
    tmp, logs = Path(tempfile.mkdtemp()), [("csf8_paper.csv", DATA / "csf8_paper.csv")]
    for seed in range(args.seed0, args.seed0 + args.logs - 1):
        logs.append((f"paper_{seed}.csv", tmp / f"paper_{seed}.csv"))
        draw_log(gen, "paper", seed)[1].to_csv(logs[-1][1], index=False)
    full = _common.stored(args.name)
    full["cli"] = res = {"generated": time.strftime("%Y-%m-%dT%H:%M:%S"), "src": _common.src_fingerprint(), "rows": []}
    for name, path in logs:
        for row in ({"log": name} for _ in range(args.repeats)):
            for k in SAMPLERS:
                row[k] = run_cli(k, path, tmp / f"{k}.json", args.timeout)
                print(name, k, {x: row[k].get(x) for x in ("process_s", "posterior_s", "converged", "rc")},
                      _common.loads(), flush=True)
            res["rows"].append(row)
            _common.write_result(args.name, full, render, indent=1)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--paper-logs", type=int, default=20)
    ap.add_argument("--rich-logs", type=int, default=20)
    ap.add_argument("--seed0", type=int, default=34000)
    ap.add_argument("--max-steps", type=int, default=20000, help="emcee's chain length cap")
    ap.add_argument("--end-by", type=float, metavar="S", help="start no log that would end after S seconds from the "
                    "start, judged by the latest log of its design in this process (before any: --expect-s)")
    ap.add_argument("--expect-s", default="", metavar="DESIGN:S,...",
                    help="--end-by: a log's expected seconds before this process has timed one of its design")
    ap.add_argument("--paper-first", action="store_true",
                    help="every paper log before any rich one (a cut budget drops rich logs first)")
    ap.add_argument("--name", default="posterior_sbc", help="results/NAME.{json,md}")
    ap.add_argument("--method", default="emcee,smc", help="samplers, comma-separated (one fit and optima a log)")
    ap.add_argument("--noise", choices=("prior", "none", "analog"), default="prior", help="noise before rounding: "
                    "the sampler's σ_n prior or none; analog: step/√12 on unrounded readings (the likelihood exact)")
    ap.add_argument("--seeds", default="", metavar="DESIGN:SEED,...", help="run exactly these logs, in this order")
    ap.add_argument("--shard", default="0/1", help="K/N: run every N-th log from the K-th")
    ap.add_argument("--merge", nargs="+", metavar="JSON", help="join shards' results into NAME")
    ap.add_argument("--check", metavar="KEY", help="--merge: keep the joined run beside NAME's logs, as check KEY")
    ap.add_argument("--about", default="", help="--check: what the check is, above its tables")
    ap.add_argument("--cli", action="store_true", help="time the CLI process instead: --logs, --repeats, --timeout")
    ap.add_argument("--logs", type=int, default=1, help="--cli: the shipped log and N-1 drawn ones")
    ap.add_argument("--repeats", type=int, default=3, help="--cli: runs per log and sampler")
    ap.add_argument("--timeout", type=float, default=900, help="--cli: per process [s]")
    if (args := _common.parse_or_render(ap, argv, lambda a: a.name, render, indent=1)) is None:
        return
    from hdid.reference import logs as gen

    if args.cli:
        return main_cli(args, gen)
    if args.merge:
        parts = []
        for f in args.merge:  # a shard killed while writing leaves a torn file: said, not merged
            try:
                parts.append(json.loads(Path(f).read_text()))
            except ValueError as e:
                print(f"{f}: not merged ({e})", file=sys.stderr)
        res = dict(parts[0], logs=[r for q in parts for r in q["logs"]],
                   shards=[{k: q.get(k) for k in ("generated", "options", "load_start", "machine", "skipped")}
                           for q in parts])
        res.pop("cli", None)
        if args.check:  # a run beside the stored one (other conditions): kept whole, its own tables
            (full := _common.stored(args.name)).setdefault("checks", {})[args.check] = dict(res, about=args.about)
            return _common.write_result(args.name, full, render, indent=1)
        res.update({k: v for k, v in _common.stored(args.name).items() if k in ("cli", "checks", "skew_checks")})
        return _common.write_result(args.name, res, render, indent=1)

    res = {"generated": time.strftime("%Y-%m-%dT%H:%M:%S"), "load_start": _common.loads(),
           "machine": f"{os.cpu_count()} cores, {_common.cpu_model()}", "src": _common.src_fingerprint(),
           "options": {k: v for k, v in vars(args).items() if k != "render"}, "logs": []}
    res.update({k: v for k, v in _common.stored(args.name).items() if k in ("cli", "checks", "skew_checks")})
    sched = [(d, args.seed0 + off + i) for i in range(max(args.paper_logs, args.rich_logs))
             for d, off, n in (("paper", 0, args.paper_logs), ("rich", 1000, args.rich_logs)) if i < n]
    sched = [(d, int(x)) for d, x in (item.split(":") for item in args.seeds.split(","))] if args.seeds else sched
    if args.paper_first:
        sched.sort(key=lambda s: s[0] != "paper")  # stable: seeds stay in order within a design
    (k, n), t_start = (int(x) for x in args.shard.split("/")), time.perf_counter()
    expect = {d: float(v) for d, v in (x.split(":") for x in args.expect_s.split(",") if x)}
    for name, seed in sched[k::n]:
        now = time.perf_counter() - t_start
        if args.end_by is not None and now + expect.get(name, 0.0) > args.end_by:
            res["skipped"] = res.get("skipped", []) + [{"design": name, "seed": seed, "at_s": now}]
            _common.write_result(args.name, res, render, indent=1)
            continue  # a log of the other design may still fit
        t_log = time.perf_counter()
        try:
            rs = run_one(gen, name, seed, args.max_steps, args.method, args.noise)
        except Exception:  # record and go on
            rs = [{"design": name, "seed": seed, "method": m, "error": traceback.format_exc()}
                  for m in args.method.split(",")]
        expect[name] = time.perf_counter() - t_log  # the latest: the first of a design also compiled
        res["logs"].extend(rs)
        _common.write_result(args.name, res, render, indent=1)
        for r in rs:
            print(name, seed, {k: r.get(k) for k in ("method", "converged", "steps", "posterior_s", "rhat_max",
                                                    "ess_bulk_min")}, _common.loads(), flush=True)


if __name__ == "__main__":
    sys.exit(main())
