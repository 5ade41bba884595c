"""Side by side, in one process: the samplers of ``sample_posterior`` on the same logs and the
same optima — tempered SMC alone (``method="smc"``) and emcee (``method="emcee"``, the
default) — time, convergence (arviz) and intervals.

Run (pinned to one core)::

    taskset -c 1 python benchmarks/posterior_engine.py [--logs 3] [--seed0 7300]
        [--prior catalog|none] [--max-steps 4000] [--name posterior_engine]

Logs: the shipped ``data/synthetic/csf8_paper.csv`` (default prior) and ``--logs``
paper-design logs from the independent simulator drawn as in ``posterior_sbc.py`` (with
``--prior catalog`` the truths come from the sampler's prior and the sampler is given it).
Each log is fitted once and its optima found once (``find_modes``, time reported); every
sampler gets them. ``os.getloadavg()`` beside every time. Writes
``benchmarks/results/<name>.{json,md}``.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import argparse
import datetime as _dt
import json
import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
SHIPPED = ROOT / "data" / "synthetic" / "csf8_paper.csv"
QUANT = ("k1", "k2", "tau_c", "tau_s", "c_v", "v_s", "delta", "stick_band_halfwidth_rad")

#: The committed rows named "emcee+smc-pilot" (emcee started from a tempered-SMC pilot, its
#: independence proposal fitted to the SMC particles; retired by these measurements) and
#: "emcee+modes" (= today's "emcee") were run at commit ca353da, where
#: ``sample_posterior`` had a ``pilot`` option.
SAMPLERS = {
    "smc": dict(method="smc"),
    "emcee": dict(method="emcee"),
}


def _load():
    return [round(x, 2) for x in os.getloadavg()]


def one(fit, modes, name, kw, seed, prior, max_steps, truth):
    import numpy as np

    import hdid

    la = _load()
    t = time.perf_counter()
    extra = {} if kw["method"] == "smc" else {"max_steps": max_steps}
    p = hdid.sample_posterior(fit, modes=modes, seed=seed, prior=prior, **kw, **extra)
    w = time.perf_counter() - t
    c = p.convergence
    s = p.summary()
    vals = {**p.samples, **p.derived}
    r = {"sampler": name, "wall_s": w, "load_start": la, "load_end": _load(),
         "converged": p.converged, "rhat_max": float(np.max(c.rhat)),
         "ess_bulk_min": float(np.min(c.ess_bulk)), "ess_tail_min": float(np.min(c.ess_tail)),
         "worst": c.worst[0], "stage_s": p.stage_s, "shape": list(p.chain.shape),
         "move_acceptance": p.move_acceptance,
         "ci95": {n: s[n]["ci95"] for n in QUANT},
         "median": {n: s[n]["median"] for n in QUANT}}
    if truth:
        r["cover95"] = {n: bool(s[n]["ci95"][0] <= truth[n] <= s[n]["ci95"][1]) for n in QUANT}
        r["rank"] = {n: float(np.mean(np.asarray(vals[n]) < truth[n])) for n in QUANT}
    return r


def render(res):
    L = ["# Posterior samplers side by side (same logs, same optima, one process)\n",
         f"`python benchmarks/posterior_engine.py` on {res['generated']}, options "
         f"`{json.dumps(res['options'])}`; one core (`taskset -c 1`) of the shared 2-core "
         "machine, load averages (1/5/15 min) per run.\n",
         "| log | sampler | wall s (pilot, burn-in, kept, diag) | converged | R-hat max | "
         "ESS bulk/tail min | worst | draws | band 95 % [mrad] | tau_c 95 % [mNm] | v_s 95 % "
         "[rad/s] | misses (95 %) | load |",
         "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for lg in res["logs"]:
        for r in lg["runs"]:
            st = r["stage_s"]
            parts = ", ".join(f"{st.get(k, 0):.1f}" for k in ("pilot_smc", "burn_in", "kept_chain", "diagnostics")) \
                if r["sampler"] != "smc" else f"smc {st.get('smc', 0):.1f}, diag {st.get('diagnostics', 0):.1f}"
            b, tc, vs = (r["ci95"][n] for n in ("stick_band_halfwidth_rad", "tau_c", "v_s"))
            miss = ", ".join(n for n, ok in r.get("cover95", {}).items() if not ok) or "–"
            L.append(f"| {lg['log']} | {r['sampler']} | {r['wall_s']:.1f} ({parts}) | "
                     f"{'yes' if r['converged'] else 'NO'} | {r['rhat_max']:.3f} | "
                     f"{r['ess_bulk_min']:.0f}/{r['ess_tail_min']:.0f} | {r['worst']} | "
                     f"{'×'.join(map(str, r['shape'][:2]))} | [{1e3 * b[0]:.1f}, {1e3 * b[1]:.1f}] | "
                     f"[{1e3 * tc[0]:.3f}, {1e3 * tc[1]:.3f}] | [{vs[0]:.2f}, {vs[1]:.2f}] | {miss} | "
                     f"{r['load_start'][0]} → {r['load_end'][0]} |")
        L.append(f"| {lg['log']} | (fit {lg['fit_s']:.1f} s, mode search {lg['modes_s']:.1f} s, "
                 f"{lg['n_modes']} optima) | | | | | | | | | | | |")
    return "\n".join(L) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", type=int, default=3)
    ap.add_argument("--seed0", type=int, default=7300)
    ap.add_argument("--prior", default="catalog", choices=("catalog", "none"))
    ap.add_argument("--max-steps", type=int, default=4000)
    ap.add_argument("--no-shipped", action="store_true")
    ap.add_argument("--samplers", default=",".join(SAMPLERS))
    ap.add_argument("--name", default="posterior_engine")
    ap.add_argument("--render", type=Path)
    args = ap.parse_args(argv)
    out_json, out_md = RESULTS / f"{args.name}.json", RESULTS / f"{args.name}.md"
    if args.render:
        out_md.write_text(render(json.loads(args.render.read_text())))
        return
    import numpy as np

    import hdid
    from hdid._posterior import find_modes
    from posterior_sbc import catalog_prior, draw_from_prior, draw_truth

    gen = _common.import_generate()
    res = {"generated": _dt.datetime.now().isoformat(timespec="seconds"),
           "options": {k: v for k, v in vars(args).items() if k != "render"}, "logs": []}
    jobs = [] if args.no_shipped else [("shipped csf8_paper.csv", None)]
    jobs += [(f"paper seed {args.seed0 + i}", args.seed0 + i) for i in range(args.logs)]
    for label, seed in jobs:
        prior, truth = None, None
        if seed is None:
            df = str(SHIPPED)
            inertia = None
            tr = json.loads((ROOT / "data" / "synthetic" / "truth.json").read_text())
            truth = None
        else:
            rng = np.random.default_rng(seed)
            design = gen.PAPER_DESIGN
            amp = min(abs(a) for a in design["amplitudes"])
            if args.prior == "catalog":
                t, _ = draw_from_prior(gen, rng, amp)
                prior = catalog_prior(gen)
            else:
                t = draw_truth(gen, rng, amp)
            df, info = gen.make_log(t, **{**design, "seed": seed}, return_truth=True)
            inertia = t["inertia"]
            truth = {n: float(t[n]) for n in QUANT if n in t}
            truth["stick_band_halfwidth_rad"] = float(info["stick_band_halfwidth"])
        t0 = time.perf_counter()
        fit = hdid.fit(df, inertia=inertia) if inertia else hdid.fit(df)
        fit_s = time.perf_counter() - t0
        t0 = time.perf_counter()
        from hdid._posterior.density import posterior_density
        from hdid._posterior.modes import sampled_modes

        dens = posterior_density(fit, prior=prior)
        modes = sampled_modes(fit, "auto", 0, dens.u_fit, dens.lin, dens.lp.gauss_prior)
        modes_s = time.perf_counter() - t0
        lg = {"log": label, "seed": seed, "fit_s": fit_s, "modes_s": modes_s,
              "n_modes": len(modes), "truth": truth, "runs": []}
        for name in args.samplers.split(","):
            lg["runs"].append(one(fit, modes, name, SAMPLERS[name], (seed or 0) % 1000, prior,
                                  args.max_steps, truth))
            print(label, {k: lg["runs"][-1][k] for k in ("sampler", "wall_s", "converged", "rhat_max", "ess_bulk_min", "worst")}, _load(), flush=True)
        res["logs"].append(lg)
        out_json.write_text(json.dumps(res, indent=1))
        out_md.write_text(render(res))


if __name__ == "__main__":
    sys.exit(main())
