"""Posterior calibration: do ``hdid``'s credible intervals cover the truth as often as claimed?

Run (≈ 20–30 min on 2 busy cores with the defaults; stops early at ``--budget-min``)::

    python benchmarks/posterior_calibration.py [--paper-logs 16 --rich-logs 8]
        [--paper-steps 4000 --rich-steps 3000] [--budget-min 34]

For each of many synthetic logs with known truth (``data/synthetic/generate.py::make_log``,
:data:`TRUTH_CSF8`, quantized to the 4000 counts/rev encoder, no added noise — like the
shipped files), differing only in the seed (= the sub-sample release instants):

1. ``hdid.fit(log, inertia=<true inertia>)`` (inertia known: free motion fixes only torques
   relative to it);
2. ``hdid._posterior.sample_posterior(fit, n_steps=<fixed>, seed=i)`` with the default
   number of walkers (``max(32, 2·D + 2)``) and a *fixed, modest* chain length — far shorter
   than the ``50 τ`` that ``sample_posterior`` asks for (it warns), to fit the compute budget;
   the chain length in units of the estimated ``τ_max`` is reported;
3. for ``k1, k2, tau_c, tau_s, c_v, v_s, delta``, ``stick_band_halfwidth_rad`` and
   ``k1/inertia``: does the central 95 % (68 %) posterior interval contain the truth?  Also the
   rank of the truth among the draws (PIT, uniform for a calibrated posterior) and, for
   comparison, the coverage of the least-squares (Laplace) intervals ``value ± z·std`` of the
   fit itself.

Two designs, interleaved so that an early stop leaves both represented: the paper's
(``PAPER_DESIGN``: 4 runs at ±0.157 rad, 250 Hz, two set-ups) and the richer one
(``RICH_DESIGN``: 8 runs at ±0.157/0.12/0.08/0.05 rad, 1 kHz, one set-up).  Coverage is
reported per design and pooled, with binomial standard errors ``sqrt(p(1−p)/n)`` at the
nominal ``p`` and exact (Clopper–Pearson) 95 % intervals of the observed fraction.

The true stick-band half-width is :func:`hdid.reference.stick_band_halfwidth` (the
generator's), cross-checked against hdid's own ``Model.stick_band`` at the true parameters.

Writes ``benchmarks/results/posterior_calibration.md`` and ``.json`` (the JSON is re-written
after every log, so an interrupted run keeps what it did; ``--render JSON`` re-writes the
markdown from it).  ``os.getloadavg()`` is recorded for every log.
"""

from __future__ import annotations

import _common  # noqa: E402  (benchmarks/ is on sys.path when run as a script)
import argparse
import datetime as _dt
import hashlib
import importlib.util
import json
import math
import os
import platform
import statistics
import sys
import time
import traceback
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data" / "synthetic"
RESULTS = ROOT / "benchmarks" / "results"

PHYS = ("k1", "k2", "tau_c", "tau_s", "c_v", "v_s", "delta")
DERIVED = ("stick_band_halfwidth_rad", "k1/inertia")
QUANTITIES = PHYS + DERIVED
LEVELS = (0.68, 0.95)


# ----------------------------------------------------------------------------- helpers


def _load():
    la = os.getloadavg()
    return [round(la[0], 2), round(la[1], 2), round(la[2], 2)]


def _src_fingerprint() -> str:
    return _common.src_fingerprint()


def _import_generate():
    return _common.import_generate()


def _machine():
    import emcee
    import jax
    import numpy

    import hdid

    return {"nproc": os.cpu_count(), "python": platform.python_version(),
            "jax": jax.__version__, "numpy": numpy.__version__, "emcee": emcee.__version__,
            "hdid": hdid.__version__, "platform": platform.platform(),
            "src_fingerprint": _src_fingerprint()}


def _binom(k: int, n: int, p0: float) -> dict:
    """Observed fraction, SEs and an exact 95 % interval; two-sided test against p0."""
    from scipy import stats

    if n == 0:
        return {"k": 0, "n": 0}
    phat = k / n
    lo = stats.beta.ppf(0.025, k, n - k + 1) if k > 0 else 0.0
    hi = stats.beta.ppf(0.975, k + 1, n - k) if k < n else 1.0
    return {"k": k, "n": n, "coverage": phat, "nominal": p0,
            "se_nominal": math.sqrt(p0 * (1 - p0) / n),
            "se_observed": math.sqrt(phat * (1 - phat) / n),
            "cp95": [float(lo), float(hi)],
            "p_value_vs_nominal": float(stats.binomtest(k, n, p0).pvalue)}


# ----------------------------------------------------------------------------- one log


def _truths(gen, fit, info):
    """True values of every checked quantity (and the cross-check of the band)."""
    import numpy as np

    from hdid._identifiability import derived_quantities

    p = dict(info["params"])
    t = {n: float(p[n]) for n in PHYS}
    t["k1/inertia"] = p["k1"] / p["inertia"]
    t["stick_band_halfwidth_rad"] = float(info["stick_band_halfwidth"])
    model_true = fit.model.replace(**{n: float(p[n]) for n in (*PHYS, "inertia")})
    d = {k: float(np.asarray(v)) for k, v in derived_quantities(model_true).items()}
    return t, {"band_hdid_model_at_truth": d["stick_band_halfwidth_rad"],
               "k1_over_inertia_hdid_model_at_truth": d["k1/inertia"]}


def _consistency(fit, step):
    """χ² cost of a fit and how many readings its prediction leaves outside their count."""
    import numpy as np

    r = (np.asarray(fit.predict()) - np.asarray(fit.problem.theta)) / step
    m = np.asarray(fit.problem.weight) > 0
    return {"cost": float(fit.starts.costs[fit.starts.best]),
            "rms_counts": float(fit.rms_residual_rad / step),
            "max_abs_res_counts": float(np.max(np.abs(r[m]))),
            "n_outside_half_count": int(np.sum(np.abs(r[m]) > 0.5)),
            "n_samples": int(m.sum())}


def truth_check(gen, df, fit):
    """Fit the nuisance parameters with the physical ones fixed at the truth, compare.

    If the free least-squares fit (the sampler's start) leaves every reading inside its
    count just as the truth does, the data cannot tell the two apart: a miss there is the
    data's ambiguity (plus a sampler that stays in the mode it starts in), not bad intervals
    around the right mode.
    """
    import hdid

    step = gen.encoder_step()
    ft = hdid.fit(df, inertia=gen.TRUTH_CSF8["inertia"],
                  fix={n: float(gen.TRUTH_CSF8[n]) for n in PHYS})
    free, tru = _consistency(fit, step), _consistency(ft, step)
    return {"free_fit": free, "truth_fixed_fit": tru,
            "delta_cost_truth_minus_free": tru["cost"] - free["cost"],
            "free_band_rad": float(fit.stick_band_halfwidth_rad)}


def run_one(gen, design_name, design, seed, post_seed, n_steps, noise_steps, do_truth=True,
            post_kwargs=None):
    import numpy as np

    import hdid
    from hdid._posterior import sample_posterior

    d = dict(design)
    d["seed"] = seed
    step = gen.encoder_step()
    df, info = gen.make_log(gen.TRUTH_CSF8, **d, noise_std=noise_steps * step, return_truth=True)
    out = {"design": design_name, "seed": seed, "posterior_seed": post_seed,
           "n_steps": n_steps, "load_start": _load()}
    t0 = time.perf_counter()
    fit = hdid.fit(df, inertia=gen.TRUTH_CSF8["inertia"])
    out["fit_s"] = time.perf_counter() - t0
    out["fit_warnings"] = list(fit.warnings)
    out["fit_rms_counts"] = float(fit.rms_residual_rad / step)
    if do_truth:
        t2 = time.perf_counter()
        out["truth_check"] = truth_check(gen, df, fit)
        out["truth_check_s"] = time.perf_counter() - t2
    t1 = time.perf_counter()
    kw = dict(post_kwargs or {})
    if n_steps < 0:  # adaptive: grow to 50 τ, at most |n_steps| kept steps
        kw["max_steps"] = -n_steps
        post = sample_posterior(fit, seed=post_seed, **kw)
    else:
        post = sample_posterior(fit, n_steps=n_steps, seed=post_seed, **kw)
    out["steps_run"] = int(post.chain.shape[0])
    out["posterior_s"] = time.perf_counter() - t1
    out["mode_search_s"] = float(post.mode_search_s)
    diag = post.to_dict()["posterior_diagnostics"]
    out["modes"] = diag["modes"]
    out["tau_max_emcee"] = diag["tau_max_emcee"]
    out["load_end"] = _load()

    truth, check = _truths(gen, fit, info)
    out["truth"] = truth
    out["truth_model_check"] = check
    tau = np.asarray(post.tau)
    out["n_walkers"] = int(post.chain.shape[1])
    out["ndim"] = int(post.chain.shape[2])
    out["tau_max"] = float(np.nanmax(tau))
    out["tau_max_label"] = post.labels[int(np.nanargmax(tau))]
    out["tau_phys"] = {lab: float(t) for lab, t in zip(post.labels, tau) if lab in PHYS}
    out["chain_in_tau_max"] = out["steps_run"] / out["tau_max"]
    out["acceptance_mean"] = float(np.mean(post.acceptance))
    out["acceptance_min"] = float(np.min(post.acceptance))
    out["n_draws"] = int(post.draws.shape[0])
    out["burn"], out["thin"] = int(post.burn), int(post.thin)
    out["temper"] = float(post.temper)
    out["residual_rho1"] = float(post.residual_rho1)
    out["posterior_warnings"] = list(post.warnings)
    out["noise_sigma_median_counts"] = float(np.median(post.derived["noise_sigma_rad"]) / step)

    summ = post.summary()
    values = {**post.samples, **post.derived}
    q = {}
    for n in QUANTITIES:
        v = np.asarray(values[n])
        s = summ[n]
        tr = truth[n]
        lsq_v, lsq_s = (
            (fit.parameters[n].value, fit.parameters[n].std) if n in fit.parameters
            else fit.derived[n])
        q[n] = {
            "truth": tr,
            "median": s["median"],
            "ci68": s["ci68"],
            "ci95": s["ci95"],
            "cover68": bool(s["ci68"][0] <= tr <= s["ci68"][1]),
            "cover95": bool(s["ci95"][0] <= tr <= s["ci95"][1]),
            "pit": float(np.mean(v < tr)),
            "rel_err_median": (s["median"] - tr) / tr,
            "rel_width95": (s["ci95"][1] - s["ci95"][0]) / abs(tr),
            "lsq_value": float(lsq_v),
            "lsq_std": float(lsq_s) if lsq_s is not None else float("nan"),
        }
        z = (q[n]["lsq_value"] - tr) / q[n]["lsq_std"] if q[n]["lsq_std"] > 0 else float("nan")
        q[n]["lsq_z"] = z
        q[n]["lsq_cover68"] = bool(abs(z) <= 0.9945) if math.isfinite(z) else None
        q[n]["lsq_cover95"] = bool(abs(z) <= 1.96) if math.isfinite(z) else None
    out["quantities"] = q
    out["total_s"] = time.perf_counter() - t0
    return out


# ----------------------------------------------------------------------------- aggregate


def aggregate(logs):
    import numpy as np

    ok = [r for r in logs if "quantities" in r]
    groups = {"paper": [r for r in ok if r["design"] == "paper"],
              "rich": [r for r in ok if r["design"] == "rich"], "pooled": ok}
    agg = {}
    for g, rows in groups.items():
        if not rows:
            continue
        a = {"n_logs": len(rows), "per_quantity": {}, "overall": {}}
        for n in QUANTITIES:
            e = {}
            for lev in LEVELS:
                key = f"cover{int(lev * 100)}"
                k = sum(r["quantities"][n][key] for r in rows)
                e[key] = _binom(k, len(rows), lev)
                lk = [r["quantities"][n]["lsq_" + key] for r in rows]
                lk = [x for x in lk if x is not None]
                e["lsq_" + key] = _binom(sum(lk), len(lk), lev)
            pits = np.array([r["quantities"][n]["pit"] for r in rows])
            e["pit_mean"] = float(pits.mean())
            e["pit_tail_fraction"] = float(np.mean((pits < 0.025) | (pits > 0.975)))
            e["pit_below_half"] = float(np.mean(pits < 0.5))
            e["median_rel_err"] = float(np.median([r["quantities"][n]["rel_err_median"]
                                                   for r in rows]))
            e["median_rel_width95"] = float(np.median([r["quantities"][n]["rel_width95"]
                                                      for r in rows]))
            a["per_quantity"][n] = e
        for label, names in (("physical (7)", PHYS), ("all 9", QUANTITIES)):
            for lev in LEVELS:
                key = f"cover{int(lev * 100)}"
                k = sum(r["quantities"][n][key] for r in rows for n in names)
                a["overall"][f"{label} {key}"] = _binom(k, len(rows) * len(names), lev)
        a["logs_all_phys_covered95"] = sum(
            all(r["quantities"][n]["cover95"] for n in PHYS) for r in rows)
        ch = [r["chain_in_tau_max"] for r in rows]
        a["chain_in_tau_max_median"] = float(np.median(ch))
        a["chain_in_tau_max_range"] = [float(min(ch)), float(max(ch))]
        a["tau_max_median"] = float(np.median([r["tau_max"] for r in rows]))
        a["n_steps"] = sorted({r["n_steps"] for r in rows})
        a["steps_run_median"] = float(np.median([r.get("steps_run", r["n_steps"]) for r in rows]))
        a["n_walkers"] = sorted({r["n_walkers"] for r in rows})
        a["draws_median"] = float(np.median([r["n_draws"] for r in rows]))
        a["acceptance_median"] = float(np.median([r["acceptance_mean"] for r in rows]))
        a["temper_range"] = [float(min(r["temper"] for r in rows)),
                             float(max(r["temper"] for r in rows))]
        a["logs_with_stuck_walkers"] = sum(
            any("stuck" in w for w in r["posterior_warnings"]) for r in rows)
        a["posterior_s_median"] = float(np.median([r["posterior_s"] for r in rows]))
        agg[g] = a
    return agg


# ----------------------------------------------------------------------------- markdown


def _pct(b):
    return f"{100 * b['coverage']:.0f} %" if b.get("n") else "–"


def _cov_cell(b):
    if not b.get("n"):
        return "–"
    return (f"{b['k']}/{b['n']} = {100 * b['coverage']:.0f} % "
            f"[{100 * b['cp95'][0]:.0f}, {100 * b['cp95'][1]:.0f}]")


def render(res: dict) -> str:
    agg = res["aggregate"]
    logs = [r for r in res["logs"] if "quantities" in r]
    failed = [r for r in res["logs"] if "quantities" not in r]
    o = res["options"]
    L = ["# Posterior calibration: coverage of `sample_posterior`'s intervals on synthetic logs\n"]
    L.append(f"Generated by `python benchmarks/posterior_calibration.py` on {res['generated']} "
             f"(total script time {res['total_script_s'] / 60:.1f} min; budget "
             f"{o['budget_min']} min). src fingerprint `{res['machine']['src_fingerprint']}`, "
             f"jax {res['machine']['jax']}, emcee {res['machine']['emcee']}, "
             f"{res['machine']['nproc']} cores.\n")
    fp_end = res.get("src_fingerprint_end")
    if fp_end and fp_end != res["machine"]["src_fingerprint"]:
        L.append(f"**Note:** `src/hdid` changed on disk during the run (fingerprint at the end "
                 f"`{fp_end}`); the run used the code it imported at its start.\n")
    n_p = agg.get("paper", {}).get("n_logs", 0)
    n_r = agg.get("rich", {}).get("n_logs", 0)
    L.append("## Set-up\n")
    L.append(f"- **{len(logs)} synthetic logs** with the truth `TRUTH_CSF8`: **{n_p} of the paper "
             f"design** (4 runs ±0.157 rad, 250 Hz, 0.5 s, two set-ups) and **{n_r} of the rich "
             f"design** (8 runs ±0.157/0.12/0.08/0.05 rad, 1 kHz, 0.3 s, one set-up); both in the "
             f"budget would not fit 20 rich logs with useful chains, so both designs with fewer "
             f"logs each. Logs differ only in `make_log`'s seed (sub-sample release instants); "
             f"quantized to 4000 counts/rev, added noise {o['noise_steps']} counts "
             f"(the shipped files have none).")
    L.append(f"- `hdid.fit(log, inertia=7e-7)` (true inertia, fixed), then "
             f"`sample_posterior(fit, n_steps=N, seed=i, likelihood={o.get('likelihood', 'auto')!r}, "
             f"modes={o.get('modes', 'fit')!r}, linear_prior="
             f"{tuple(res.get('linear_prior_effective', ()))!r}"
             + (f", sample_linear={tuple(res['sample_linear_effective'])!r}"
                if "sample_linear_effective" in res else "")
             + "".join(f", {k}={v!r}" for k, v in res.get("post_kwargs", {}).items()
                       if k not in ("likelihood", "modes", "linear_prior", "sample_linear"))
             + ")` "
             f"with the default walkers "
             f"(max(32, 2·D): {', '.join(map(str, agg['pooled']['n_walkers']))}); "
             f"N = {o['paper_steps']} (paper) / {o['rich_steps']} (rich) kept steps. Sampler: "
             + ("differential-evolution moves plus independence Metropolis–Hastings from a "
                "t-mixture over the optima found by `find_modes` (walkers seeded over them by "
                "Laplace mass), adapted in a 400-step burn-in that is discarded"
                if o.get("modes", "fit") == "auto" else
                "differential-evolution moves, walkers from the Laplace approximation, 400 "
                "discarded burn-in steps")
             + "; intervals: central 68 % / 95 % of the kept draws thinned by τ_max/2.")
    if res.get("stopped_early"):
        L.append(f"- **Stopped early** by the budget guard: {res['stopped_early']}")
    if failed:
        L.append(f"- {len(failed)} log(s) failed: " + "; ".join(
            f"{r['design']} seed {r['seed']}: {r['error'].splitlines()[-1]}" for r in failed))
    L.append("- Load average (1 min) during the run: " + ", ".join(
        f"{r['load_start'][0]:.1f}" for r in logs) + ".\n")

    L.append("## Chains\n")
    L.append("| design | logs | steps × walkers | median τ_max | chain / τ_max: median (range) | "
             "draws (median) | acceptance | likelihood temper | logs with stuck walkers | "
             "posterior time / log |\n|---|---|---|---|---|---|---|---|---|---|")
    for g in ("paper", "rich", "pooled"):
        if g not in agg:
            continue
        a = agg[g]
        steps = "/".join(f"≤{-n} (adaptive, median {a.get('steps_run_median', 0):.0f})" if n < 0
                         else str(n) for n in a["n_steps"])
        L.append(f"| {g} | {a['n_logs']} | {steps} × "
                 f"{'/'.join(map(str, a['n_walkers']))} | {a['tau_max_median']:.0f} | "
                 f"**{a['chain_in_tau_max_median']:.1f}** ({a['chain_in_tau_max_range'][0]:.1f}–"
                 f"{a['chain_in_tau_max_range'][1]:.1f}) | {a['draws_median']:.0f} | "
                 f"{a['acceptance_median']:.2f} | {a['temper_range'][0]:.2f}–"
                 f"{a['temper_range'][1]:.2f} | {a['logs_with_stuck_walkers']} | "
                 f"{a['posterior_s_median']:.0f} s |")
    L.append("\nτ is the larger of emcee's estimate (tol = 0; each walker about its own mean) and "
             "the pooled estimate about the ensemble mean (`tau_pooled`, which also sees walkers "
             "that stay in different modes). A chain of only a few τ biases both low. "
             "`sample_posterior` asks for ≥ 50 τ.\n")
    mrows = [r for r in logs if r.get("modes")]
    if mrows:
        L.append("### Modes found per log (`find_modes`)\n")
        L.append("| design | seed | optima: cost (Laplace weight → share of draws) | band median [mrad] |"
                 "\n|---|---|---|---|")
        for r in mrows:
            L.append(f"| {r['design']} | {r['seed']} | " + "; ".join(
                f"{m['cost']:.1f} ({m['weight']:.2f} → {m['share_of_draws']:.2f})"
                for m in r["modes"]) + f" | "
                f"{1e3 * r['quantities']['stick_band_halfwidth_rad']['median']:.1f} |")
        L.append("")

    L.append("## Coverage per quantity\n")
    L.append("Cells: covered/logs = fraction [exact 95 % Clopper–Pearson interval]. Binomial SE "
             "at the nominal level: " + ", ".join(
                 f"{g} (n = {agg[g]['n_logs']}): ±{100 * agg[g]['per_quantity']['k1']['cover95']['se_nominal']:.1f} % "
                 f"at 95 %, ±{100 * agg[g]['per_quantity']['k1']['cover68']['se_nominal']:.1f} % at 68 %"
                 for g in ("paper", "rich", "pooled") if g in agg) + ".\n")
    for g in ("pooled", "paper", "rich"):
        if g not in agg:
            continue
        a = agg[g]
        L.append(f"### {g} ({a['n_logs']} logs)\n")
        L.append("| quantity | posterior 95 % | posterior 68 % | LSQ ±1.96σ | LSQ ±1σ | "
                 "PIT mean | PIT in 2.5 % tails | median rel. error | median 95 % width |\n"
                 "|---|---|---|---|---|---|---|---|---|")
        for n in QUANTITIES:
            e = a["per_quantity"][n]
            L.append(f"| {n} | {_cov_cell(e['cover95'])} | {_cov_cell(e['cover68'])} | "
                     f"{_pct(e['lsq_cover95'])} | {_pct(e['lsq_cover68'])} | "
                     f"{e['pit_mean']:.2f} | {100 * e['pit_tail_fraction']:.0f} % | "
                     f"{100 * e['median_rel_err']:+.1f} % | {100 * e['median_rel_width95']:.1f} % |")
        L.append("")
        L.append("| overall | coverage | nominal ± SE | p (binomial test vs nominal) |\n"
                 "|---|---|---|---|")
        for k, b in a["overall"].items():
            L.append(f"| {k} | {_cov_cell(b)} | {100 * b['nominal']:.0f} ± "
                     f"{100 * b['se_nominal']:.1f} % | {b['p_value_vs_nominal']:.3g} |")
        L.append(f"\nLogs where all 7 physical 95 % intervals cover the truth: "
                 f"{a['logs_all_phys_covered95']}/{a['n_logs']}. (The pooled SEs treat the "
                 f"quantities as independent; they are not — `k1/inertia` is `k1` divided by "
                 f"the fixed true inertia, so the two always agree, and the band is a function "
                 f"of k1, k2, tau_s.)\n")

    L.append("## Stick band per log\n")
    L.append("| design | seed | truth [mrad] | median | 68 % interval | 95 % interval | "
             "covered 68 / 95 | PIT | chain / τ_max | fit rms [counts] |\n"
             "|---|---|---|---|---|---|---|---|---|---|")
    for r in logs:
        b = r["quantities"]["stick_band_halfwidth_rad"]
        L.append(f"| {r['design']} | {r['seed']} | {1e3 * b['truth']:.3f} | "
                 f"{1e3 * b['median']:.3f} | [{1e3 * b['ci68'][0]:.3f}, {1e3 * b['ci68'][1]:.3f}] | "
                 f"[{1e3 * b['ci95'][0]:.3f}, {1e3 * b['ci95'][1]:.3f}] | "
                 f"{'✓' if b['cover68'] else '✗'} / {'✓' if b['cover95'] else '✗'} | "
                 f"{b['pit']:.2f} | {r['chain_in_tau_max']:.1f} | {r['fit_rms_counts']:.2f} |")
    chk = [abs(r["truth_model_check"]["band_hdid_model_at_truth"]
               / r["quantities"]["stick_band_halfwidth_rad"]["truth"] - 1) for r in logs]
    L.append(f"\nTrue band: `hdid.reference.stick_band_halfwidth(k1, k2, tau_s)` = "
             f"{1e3 * logs[0]['quantities']['stick_band_halfwidth_rad']['truth']:.4f} mrad; "
             f"hdid's `Model.stick_band` at the true parameters agrees to "
             f"{max(chk):.1e} (relative).\n")

    L.append("## Misses at 95 % (per log)\n")
    L.append("| design | seed | quantities whose 95 % interval misses the truth (PIT) | τ_max | "
             "warnings |\n|---|---|---|---|---|")
    for r in logs:
        miss = [f"{n} ({r['quantities'][n]['pit']:.3f})" for n in QUANTITIES
                if not r["quantities"][n]["cover95"]]
        w = [x.split(";")[0][:60] for x in r["posterior_warnings"] if "shorter than" not in x]
        L.append(f"| {r['design']} | {r['seed']} | {', '.join(miss) or '—'} | "
                 f"{r['tau_max']:.0f} ({r['tau_max_label']}) | {'; '.join(w) or '—'} |")
    L.append("")
    if any("truth_check" in r for r in logs):
        L.append("## Is a miss the data's ambiguity or the sampler's? (truth-fixed fits)\n")
        L.append("For each log the nuisance parameters (release instants, start angles, offsets) "
                 "were fitted with the 7 physical parameters fixed at the truth, and compared with "
                 "the free least-squares fit that `sample_posterior` starts from: χ² cost "
                 "(residuals in units of the quantization σ = q/√12) and the number of readings "
                 "the prediction leaves outside their ±½-count interval (the interval likelihood "
                 "is ≈ perfect when that is 0 and σ_n is small). Δcost = truth − free: > 0 means "
                 "the data (least squares) prefer the free fit's mode.\n")
        from scipy import stats

        c68, c95 = stats.chi2.ppf(0.68, len(PHYS)), stats.chi2.ppf(0.95, len(PHYS))
        L.append(f"If the least-squares picture held globally, Δcost would follow χ²₇ (7 physical "
                 f"parameters): the truth lies inside the likelihood-ratio 68 % / 95 % region when "
                 f"Δcost ≤ {c68:.2f} / {c95:.2f}.\n")
        L.append("| design | seed | 95 % misses | free fit: band [mrad], rms [counts], outside ½ count | "
                 "truth fixed: rms, outside ½ count | Δcost | in LR 68 / 95 % region |\n"
                 "|---|---|---|---|---|---|---|")
        for r in logs:
            if "truth_check" not in r:
                continue
            c = r["truth_check"]
            nm = sum(not r["quantities"][n]["cover95"] for n in QUANTITIES)
            f_, t_ = c["free_fit"], c["truth_fixed_fit"]
            L.append(f"| {r['design']} | {r['seed']} | {nm} | {1e3 * c['free_band_rad']:.1f}, "
                     f"{f_['rms_counts']:.3f}, {f_['n_outside_half_count']}/{f_['n_samples']} | "
                     f"{t_['rms_counts']:.3f}, {t_['n_outside_half_count']}/{t_['n_samples']} | "
                     f"{c['delta_cost_truth_minus_free']:+.1f}"
                     f"{'' if c.get('refit_band_matches_run', True) else ' (refit ≠ run fit)'} | "
                     f"{'✓' if c['delta_cost_truth_minus_free'] <= c68 else '✗'} / "
                     f"{'✓' if c['delta_cost_truth_minus_free'] <= c95 else '✗'} |")
        dc = [r["truth_check"]["delta_cost_truth_minus_free"] for r in logs if "truth_check" in r]
        for g in ("paper", "rich"):
            d_ = [r["truth_check"]["delta_cost_truth_minus_free"] for r in logs
                  if "truth_check" in r and r["design"] == g]
            if d_:
                L.append(f"\n{g}: truth inside the LR 68 % region in {sum(x <= c68 for x in d_)}/"
                         f"{len(d_)} logs, inside the 95 % region in {sum(x <= c95 for x in d_)}/"
                         f"{len(d_)}; median Δcost {statistics.median(d_):.1f} (χ²₇ median "
                         f"{stats.chi2.ppf(0.5, len(PHYS)):.1f}).")
        L.append(f"\nAll: 68 % {sum(x <= c68 for x in dc)}/{len(dc)}, 95 % "
                 f"{sum(x <= c95 for x in dc)}/{len(dc)}.\n")
    if res.get("interpretation"):
        L.append("## Interpretation\n")
        L.append(res["interpretation"].strip() + "\n")
    return "\n".join(L) + "\n"


# ----------------------------------------------------------------------------- main


def _schedule(n_paper, n_rich):
    """Interleave the designs so that an early stop leaves both represented."""
    order, ip, ir = [], 0, 0
    while ip < n_paper or ir < n_rich:
        # keep the fractions done of each design equal
        if ir >= n_rich or (ip < n_paper and ip / max(n_paper, 1) <= ir / max(n_rich, 1)):
            order.append(("paper", ip))
            ip += 1
        else:
            order.append(("rich", ir))
            ir += 1
    return order


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--paper-logs", type=int, default=16)
    ap.add_argument("--rich-logs", type=int, default=8)
    ap.add_argument("--paper-steps", type=int, default=4000,
                    help="kept steps (paper); negative: adaptive to 50 τ with at most |N| steps")
    ap.add_argument("--rich-steps", type=int, default=3000, help="as --paper-steps (rich)")
    ap.add_argument("--noise-steps", type=float, default=0.0,
                    help="Gaussian noise before quantization, in encoder counts (default 0)")
    ap.add_argument("--seed0", type=int, default=1000,
                    help="make_log seeds: seed0 + i (paper), seed0 + 1000 + i (rich)")
    ap.add_argument("--budget-min", type=float, default=34.0,
                    help="start no new log when the projected total would exceed this")
    ap.add_argument("--out-dir", type=Path, default=RESULTS)
    ap.add_argument("--render", type=Path, help="re-write the markdown from this JSON")
    ap.add_argument("--no-truth-fit", action="store_true",
                    help="skip the per-log fit with the physical parameters fixed at the truth")
    ap.add_argument("--augment", type=Path,
                    help="add the truth-fixed fits to the logs of this JSON (no sampling), "
                         "re-aggregate and re-render")
    ap.add_argument("--likelihood", default="auto", help="sample_posterior(likelihood=)")
    ap.add_argument("--modes", default="auto", help="sample_posterior(modes=): auto or fit")
    ap.add_argument("--linear-prior", default="",
                    help="comma-separated parameters with a prior flat in the value "
                         "(default: sample_posterior's LINEAR_PRIOR; 'none' for none)")
    ap.add_argument("--sample-linear", default="",
                    help="comma-separated parameters sampled in their value (default: "
                         "sample_posterior's SAMPLE_LINEAR; 'none' for the fit's coordinates)")
    ap.add_argument("--post", action="append", default=[], metavar="KEY=VALUE",
                    help="extra sample_posterior keyword (int/float/str), e.g. mixture_split=4")
    ap.add_argument("--interpretation", type=Path,
                    help="markdown file whose text is added as the Interpretation section")
    args = ap.parse_args(argv)

    if args.augment:
        t_aug = time.perf_counter()
        res = json.loads(args.augment.read_text())
        gen = _import_generate()
        import hdid

        designs = {"paper": gen.PAPER_DESIGN, "rich": gen.RICH_DESIGN}
        noise = float(res["options"].get("noise_steps", 0.0))
        for r in res["logs"]:
            if "quantities" not in r:
                continue
            if "truth_check" in r and "band_hdid_model_at_truth" in r["truth_check"]:
                r["truth_model_check"] = r.pop("truth_check")   # older key
            if "truth_check" in r:
                continue
            d = dict(designs[r["design"]])
            d["seed"] = r["seed"]
            df = gen.make_log(gen.TRUTH_CSF8, **d, noise_std=noise * gen.encoder_step())
            t2 = time.perf_counter()
            fit = hdid.fit(df, inertia=gen.TRUTH_CSF8["inertia"])
            r["truth_check"] = truth_check(gen, df, fit)
            r["truth_check_s"] = time.perf_counter() - t2
            r["truth_check"]["refit_band_matches_run"] = bool(math.isclose(
                r["truth_check"]["free_band_rad"],
                r["quantities"]["stick_band_halfwidth_rad"]["lsq_value"], rel_tol=1e-6))
            print(f"{r['design']} {r['seed']}: Δcost {r['truth_check']['delta_cost_truth_minus_free']:+.1f}",
                  flush=True)
        res["aggregate"] = aggregate(res["logs"])
        res["augment_s"] = time.perf_counter() - t_aug
        args.augment.write_text(json.dumps(res, indent=2) + "\n")
        args.render = args.augment
    if args.render:
        res = json.loads(args.render.read_text())
        if args.interpretation:
            res["interpretation"] = args.interpretation.read_text()
            args.render.write_text(json.dumps(res, indent=2) + "\n")
        (args.render.parent / "posterior_calibration.md").write_text(render(res))
        print(render(res))
        return 0

    t_script = time.perf_counter()
    gen = _import_generate()
    res = {"generated": _dt.datetime.now().isoformat(timespec="seconds"),
           "machine": _machine(),
           "options": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
           "designs": {"paper": {k: v for k, v in gen.PAPER_DESIGN.items() if k != "seed"},
                       "rich": {k: v for k, v in gen.RICH_DESIGN.items() if k != "seed"}},
           "truth": dict(gen.TRUTH_CSF8), "logs": [], "load_start": _load()}
    designs = {"paper": (gen.PAPER_DESIGN, args.paper_steps, args.seed0),
               "rich": (gen.RICH_DESIGN, args.rich_steps, args.seed0 + 1000)}
    args.out_dir.mkdir(parents=True, exist_ok=True)
    out_json = args.out_dir / "posterior_calibration.json"
    per_design_time: dict[str, list[float]] = {"paper": [], "rich": []}
    budget = 60.0 * args.budget_min
    from hdid._posterior import LINEAR_PRIOR, SAMPLE_LINEAR

    post_kwargs = {"likelihood": args.likelihood, "modes": args.modes}
    for item in args.post:
        k, _, v = item.partition("=")
        for conv in (int, float, str):
            try:
                post_kwargs[k] = conv(v)
                break
            except ValueError:
                continue
    if args.linear_prior:  # otherwise sample_posterior's default (LINEAR_PRIOR)
        post_kwargs["linear_prior"] = tuple(
            n for n in args.linear_prior.split(",") if n and n != "none")
    if args.sample_linear:  # otherwise sample_posterior's default (SAMPLE_LINEAR)
        post_kwargs["sample_linear"] = tuple(
            n for n in args.sample_linear.split(",") if n and n != "none")
    res["linear_prior_effective"] = list(post_kwargs.get("linear_prior", LINEAR_PRIOR))
    res["sample_linear_effective"] = list(post_kwargs.get("sample_linear", SAMPLE_LINEAR))
    res["post_kwargs"] = {k: (list(v) if isinstance(v, tuple) else v) for k, v in post_kwargs.items()}
    for k, (g, i) in enumerate(_schedule(args.paper_logs, args.rich_logs)):
        design, n_steps, s0 = designs[g]
        elapsed = time.perf_counter() - t_script
        # projected cost of this log: the last one of its design (the first includes compiles)
        est = per_design_time[g][-1] if per_design_time[g] else (
            120.0 if g == "rich" else 60.0)
        if elapsed + est > budget:
            res["stopped_early"] = (f"after {elapsed / 60:.1f} min, before {g} log {i} "
                                    f"(projected {est:.0f} s more)")
            print("budget:", res["stopped_early"], flush=True)
            break
        t0 = time.perf_counter()
        try:
            r = run_one(gen, g, design, s0 + i, i, n_steps, args.noise_steps,
                        do_truth=not args.no_truth_fit, post_kwargs=post_kwargs)
        except Exception:  # keep going: a failed log is reported, not fatal
            r = {"design": g, "seed": s0 + i, "error": traceback.format_exc()}
        dt = time.perf_counter() - t0
        per_design_time[g].append(dt)
        res["logs"].append(r)
        if "quantities" in r:
            cov = sum(r["quantities"][n]["cover95"] for n in QUANTITIES)
            print(f"[{k + 1}] {g} seed {s0 + i}: {dt:.0f} s, tau_max {r['tau_max']:.0f} "
                  f"({r['chain_in_tau_max']:.1f} tau), 95% covers {cov}/{len(QUANTITIES)}, "
                  f"load {r['load_start'][0]:.2f}", flush=True)
        else:
            print(f"[{k + 1}] {g} seed {s0 + i}: FAILED\n{r['error']}", flush=True)
        res["aggregate"] = aggregate(res["logs"])
        res["total_script_s"] = time.perf_counter() - t_script
        out_json.write_text(json.dumps(res, indent=2) + "\n")

    res["load_end"] = _load()
    res["src_fingerprint_end"] = _src_fingerprint()
    res["aggregate"] = aggregate(res["logs"])
    res["total_script_s"] = time.perf_counter() - t_script
    if args.interpretation:
        res["interpretation"] = args.interpretation.read_text()
    out_json.write_text(json.dumps(res, indent=2) + "\n")
    md = render(res)
    (args.out_dir / "posterior_calibration.md").write_text(md)
    print(md)
    return 0


if __name__ == "__main__":
    sys.exit(main())
