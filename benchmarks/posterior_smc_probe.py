"""Why the paper-design posterior misses the truth: probes run for issue 17 (SMC).

``--mode truthcost SEEDS``: for paper-design logs drawn as in ``posterior_sbc.py``, the
least-squares cost at the fit and with the seven physical parameters fixed at the truth
(nuisance refitted): Δχ² in the fit's q/√12 units.

``--mode reference SEED SCALES``: ``sample_smc`` on one such log with the reference
mixture widened to each of ``SCALES`` × the Laplace widths (does a wider start reach
an optimum that ``find_modes`` missed?). Prints the 95 % intervals beside the truth.

Run: ``taskset -c 1 python benchmarks/posterior_smc_probe.py --mode truthcost 7000,7002``.
"""

from __future__ import annotations

import _common  # noqa: F401
import argparse
import json
import os
import time

import numpy as np
import posterior_sbc as ps

import hdid

NAMES = ["k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v"]


def _log(gen, seed):
    rng = np.random.default_rng(seed)
    truth = ps.draw_truth(gen, rng, min(abs(a) for a in gen.PAPER_DESIGN["amplitudes"]))
    d = dict(gen.PAPER_DESIGN)
    d["seed"] = seed
    df, info = gen.make_log(truth, **d, return_truth=True)
    return truth, df, info


def truthcost(gen, seeds):
    for seed in seeds:
        truth, df, _ = _log(gen, seed)
        fit = hdid.fit(df, inertia=truth["inertia"])
        ft = hdid.fit(df, inertia=truth["inertia"], fix={n: truth[n] for n in NAMES})
        c0, c1 = float(fit.problem.cost(fit.u)), float(ft.problem.cost(ft.u))
        print(json.dumps({"seed": seed, "cost_fit": c0, "cost_truth": c1, "dchi2": c1 - c0,
                          "load": os.getloadavg()}), flush=True)


def reference(gen, seed, scales):
    from hdid._posterior import find_modes, smc

    truth, df, info = _log(gen, seed)
    fit = hdid.fit(df, inertia=truth["inertia"])
    modes = find_modes(fit, seed=seed % 1000)
    print("modes", [(round(m.cost, 2), round(m.weight, 2)) for m in modes], flush=True)
    tv = dict(truth, stick_band_halfwidth_rad=info["stick_band_halfwidth"])
    for sc in scales:
        smc.REF_SCALE = sc
        la, t = os.getloadavg(), time.perf_counter()
        p = smc.sample_smc(fit, modes=modes, seed=seed % 1000)
        s = p.summary()
        print(json.dumps({"scale": sc, "s": time.perf_counter() - t, "converged": p.converged,
                          "log_z": p.smc["log_evidence"], "load": la,
                          "ci95_truth": {n: s[n]["ci95"] + [tv[n]] for n in
                                         NAMES[:6] + ["stick_band_halfwidth_rad"]}}), flush=True)


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--mode", choices=("truthcost", "reference"), required=True)
    ap.add_argument("seeds")
    ap.add_argument("scales", nargs="?", default="1.5,3")
    a = ap.parse_args(argv)
    gen = _common.import_generate()
    seeds = [int(s) for s in a.seeds.split(",")]
    if a.mode == "truthcost":
        truthcost(gen, seeds)
    else:
        reference(gen, seeds[0], [float(x) for x in a.scales.split(",")])


if __name__ == "__main__":
    main()
