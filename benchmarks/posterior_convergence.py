"""Why an emcee chain does not converge on an SBC log: the chain's trajectory per check.

For each calibration log named (``--seeds paper:36027,...``, the truths and readings of
``posterior_sbc.py``), fit and basin-check it once, find its optima once, then run
``sample_posterior`` under each variant named (``--variants``) and record at every
convergence check the kept chain's length, τ of every sampled coordinate (the larger of
emcee's and the ensemble-mean τ), R-hat and ESS of every quantity, and at the end the
moves' acceptance, the walkers' acceptance spread, the log-p trace (the ensemble's
median and lowest walker in 10 segments of the kept chain) and the coverage of the truth.

Variants (``NAME[:max_steps]``): ``default`` (sample_posterior's defaults); ``long``
(the defaults, only ``max_steps`` raised: is the budget what stops the rule?);
``walkers2`` (twice the walkers); ``de`` (DE + snooker alone, no independence move); ``tune`` (8000 burn-in steps in 8 stages:
the DE step adapted twice as often, up to 1.5⁸-fold).

    taskset -c 1 python benchmarks/posterior_convergence.py --seeds paper:36027 \\
        --variants default:20000,long:60000 --name posterior_convergence
"""

from __future__ import annotations

import argparse
import json
import math
import pathlib
import sys
import time

import numpy as np

sys.path.insert(0, str(pathlib.Path(__file__).resolve().parent))
import _common  # noqa: E402
import posterior_sbc as sbc  # noqa: E402

RESULTS = pathlib.Path(__file__).resolve().parent / "results"


def _variant_kwargs(name):
    import emcee

    if name in ("default", "long"):
        return {}
    if name == "walkers2":
        return {"n_walkers": 72}
    if name == "tune":  # twice the burn-in in twice the stages: the DE step may grow 1.5^8-fold
        return {"burn_in": 8000}
    if name == "de":
        return {"moves": [(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)]}
    raise SystemExit(f"unknown variant {name!r} (default, long, walkers2, de)")


def _hooks(record):
    """Record every convergence check and the kept chain's log p (patched in, benchmark only)."""
    from hdid._posterior import ensemble as ens

    orig_conv, orig_result, orig_short = ens._converge, ens._Ensemble.result, ens._short_of_tau

    def short(sampler, done, *rest):
        tau = ens._taus(sampler)[1]
        record["tau_trace"].append({"steps": int(done), "tau": [float(t) for t in tau]})
        return orig_short(sampler, done, *rest)

    def conv(sampler, lp, prob, labels):
        c = orig_conv(sampler, lp, prob, labels)
        record["checks"].append({
            "steps": int(sampler.get_chain().shape[0]), "rhat": dict(zip(c.names, map(float, c.rhat))),
            "ess_bulk": dict(zip(c.names, map(float, c.ess_bulk))),
            "ess_tail": dict(zip(c.names, map(float, c.ess_tail))),
            "tau": dict(zip(c.names, map(float, c.tau))), "chain_in_tau": c.chain_in_tau,
            "met_by": c.met_by, "load": _common.loads()})
        return c

    def result(self, *a, **k):
        L = self.sampler.get_log_prob()  # (steps, walkers)
        seg = np.array_split(np.arange(L.shape[0]), 10)
        record["logp_median"] = [float(np.median(L[s])) for s in seg]
        record["logp_low_walker"] = [float(np.min(np.median(L[s], axis=0))) for s in seg]
        record["logp_max"] = float(np.max(L))
        acc = self.sampler.acceptance_fraction
        # each walker's optimum at each step (the start mixture's likeliest component, as the
        # result's mode shares): walkers per optimum over the kept chain, and mode changes
        C = self.sampler.get_chain()
        S, W, D = C.shape
        kk = np.argmax(self.start_mix.component_logpdf(C[:: max(1, S // 200)].reshape(-1, D)), axis=1)
        kk = kk.reshape(-1, W)
        record["walkers_per_optimum"] = [np.bincount(kk[i], minlength=len(self.found)).tolist()
                                         for i in np.linspace(0, kk.shape[0] - 1, 5).astype(int)]
        record["mode_changes_per_walker"] = float(np.mean(np.sum(kk[1:] != kk[:-1], axis=0)))
        record["optima"] = [{"kind": m.kind, "weight": float(m.weight), "cost": float(m.cost),
                             "values": {n: float(v) for n, v in m.values.items()}} for m in self.found]
        record["walker_acceptance"] = {"min": float(acc.min()), "median": float(np.median(acc)),
                                       "max": float(acc.max())}
        return orig_result(self, *a, **k)

    ens._converge, ens._Ensemble.result, ens._short_of_tau = conv, result, short
    return lambda: (setattr(ens, "_converge", orig_conv), setattr(ens._Ensemble, "result", orig_result),
                    setattr(ens, "_short_of_tau", orig_short))


def run_seed(gen, design_name, seed, variants):
    import hdid
    from hdid._posterior.basin import basin_check
    from hdid._posterior.density import posterior_density
    from hdid._posterior.modes import sampled_modes

    truth, df, info, notes = sbc.draw_log(gen, design_name, seed, "none")
    prior = sbc.nominal_default_prior(design_name)
    t0, c0 = time.perf_counter(), time.process_time()
    fit = basin_check(hdid.fit(df, inertia=truth["inertia"]), df, echo=False)[0]
    fit_cpu = time.process_time() - c0
    dens = posterior_density(fit, prior=prior)
    c1 = time.process_time()
    modes = sampled_modes(fit, "auto", seed % 1000, dens.u_fit, dens.lin, dens.lp.gauss_prior)
    modes_cpu = time.process_time() - c1
    tv = {**{n: float(truth[n]) for n in sbc.REPORTED if n in truth},
          "stick_band_halfwidth_rad": float(info["stick_band_halfwidth"])}
    rows = []
    for v in variants:
        name, _, steps = v.partition(":")
        rec = {"design": design_name, "seed": seed, "variant": name, "max_steps": int(steps or 20000),
               "fit_cpu_s": fit_cpu, "modes_cpu_s": modes_cpu, "n_modes": len(modes),
               "fit_rms_over_floor": None, "checks": [], "tau_trace": [], "load_start": _common.loads()}
        undo = _hooks(rec)
        from hdid._posterior import ensemble as ens

        stages = ens.BURN_IN_STAGES
        ens.BURN_IN_STAGES = 8 if name == "tune" else stages
        c2, t2 = time.process_time(), time.perf_counter()
        try:
            post = hdid.sample_posterior(fit, seed=seed % 1000, prior=prior, modes=modes, log=df,
                                         max_steps=rec["max_steps"], **_variant_kwargs(name))
        finally:
            undo()
            ens.BURN_IN_STAGES = stages
        rec.update(cpu_s=time.process_time() - c2, wall_s=time.perf_counter() - t2, load_end=_common.loads())
        d = post.to_dict()["posterior_diagnostics"]
        rec["labels"] = list(post.labels)
        rec.update(steps=int(post.chain.shape[0]), converged=bool(post.converged),
                   met_by=d["convergence"].get("met_by"), rhat_max=d["convergence"]["rhat_max"],
                   tau_max=d["tau_max"], move_acceptance=d["move_acceptance"],
                   warnings=[w[:160] for w in post.warnings], stage_s=post.stage_s)
        values = {**post.samples, **post.derived}
        rec["coverage95"] = {}
        for n, tr in tv.items():
            x = np.asarray(values[n])
            lo, hi = np.percentile(x, [2.5, 97.5])
            rec["coverage95"][n] = {"cover": bool(lo <= tr <= hi), "rank": float(np.mean(x < tr))}
        rows.append(rec)
        last = rec["checks"][-1] if rec["checks"] else {}
        worst = sorted(last.get("tau", {}).items(), key=lambda kv: -kv[1])[:4]
        print(f"{design_name} {seed} {name}: steps {rec['steps']} converged {rec['converged']} "
              f"({rec['met_by']}) R-hat {rec['rhat_max']:.3f} tau_max {rec['tau_max']:.0f} "
              f"worst tau {[(k, round(t)) for k, t in worst]} cpu {rec['cpu_s']:.0f} s "
              f"load {rec['load_start']} -> {rec['load_end']} moves "
              f"{ {k: round(a, 3) for k, a in rec['move_acceptance'].items()} } "
              f"cover {sum(c['cover'] for c in rec['coverage95'].values())}/{len(tv)}", flush=True)
    return rows


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", required=True, help="DESIGN:SEED,...")
    ap.add_argument("--variants", default="default:20000,long:60000")
    ap.add_argument("--name", default="posterior_convergence")
    a = ap.parse_args(argv)
    from hdid.reference import logs as gen

    out = {"generated": time.strftime("%Y-%m-%dT%H:%M:%S"), "src": _common.src_fingerprint(),
           "machine": _common.machine(), "options": vars(a), "rows": []}
    path = RESULTS / f"{a.name}.json"
    for item in a.seeds.split(","):
        d, s = item.split(":")
        out["rows"] += run_seed(gen, d, int(s), a.variants.split(","))
        path.write_text(json.dumps(out, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())


def render(paths) -> str:
    """One table row per (seed, variant) from the JSONs written by :func:`main`."""
    from hdid._posterior.diagnostics import tau_outlasts_chain

    L = ["| seed | variant | walkers | steps | converged | R-hat max (quantity) | τ max (quantity) | chain / τ "
         "| g (τ ∝ steps^g) | acceptance DE / snooker / independence | walker acceptance min / median "
         "| log p median, first tenth vs last | 95 % covered | CPU s | load start → end |",
         "|" + "---|" * 15]
    for p in paths:
        for x in json.loads(pathlib.Path(p).read_text())["rows"]:
            c = x["checks"][-1] if x["checks"] else None
            tr = x["tau_trace"][-1] if x["tau_trace"] else None
            taus = dict(zip(x["labels"], tr["tau"])) if tr else {}
            if c:
                taus = c["tau"]
            h = sorted([(t["steps"], max(t["tau"])) for t in x["tau_trace"]]
                       + [(k["steps"], max(k["tau"].values())) for k in x["checks"]])
            grew = tau_outlasts_chain(h)
            if len(h) >= 2:
                n2, t2 = h[-1]
                e = [(n, t) for n, t in h[:-1] if n <= 0.5 * n2]
                g = f"{math.log(t2 / e[-1][1]) / math.log(n2 / e[-1][0]):.2f}" if e else "–"
            else:
                g = "–"
            rq = max(c["rhat"].items(), key=lambda kv: kv[1]) if c else ("–", float("nan"))
            tq = max(taus.items(), key=lambda kv: kv[1]) if taus else ("–", float("nan"))
            m = x["move_acceptance"]
            acc = " / ".join(f"{m.get(k, float('nan')):.3f}" for k in ("DEMove", "DESnookerMove",
                                                                       "independence (mixture)"))
            wa = x.get("walker_acceptance", {})
            lpm = x.get("logp_median", [])
            cov = x["coverage95"]
            W = {"walkers2": 72}.get(x["variant"], 36)
            L.append(f"| {x['seed']} | {x['variant']} | {W} | {x['steps']} | "
                     f"{'yes (' + x['met_by'] + ')' if x['converged'] else 'NO'} | "
                     f"{rq[1]:.3f} ({rq[0]}) | {tq[1]:.0f} ({tq[0]}) | {x['steps'] / tq[1]:.1f} | "
                     f"{g}{' (flagged)' if grew else ''} | {acc} | "
                     f"{wa.get('min', float('nan')):.3f} / {wa.get('median', float('nan')):.3f} | "
                     f"{lpm[0]:.1f} vs {lpm[-1]:.1f} | {sum(v['cover'] for v in cov.values())}/{len(cov)} | "
                     f"{x['cpu_s']:.0f} | {x['load_start'][0]:.1f} → {x['load_end'][0]:.1f} |")
    return "\n".join(L)
