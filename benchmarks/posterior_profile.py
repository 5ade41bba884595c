"""Where the posterior's time goes on the shipped paper log: cost of one batched
log-posterior call per particle (at draws from the SMC reference, i.e. the early tempering,
and at draws near the optimum), by batch size and by chunk size, and the stages of one
``sample_posterior(method="smc")`` call.

Run (pinned to one core)::

    taskset -c 1 python benchmarks/posterior_profile.py [--log data/synthetic/csf8_paper.csv]
        [--sizes 250,1000,2000] [--chunks 0,64,256]
        [--variant old:imh=False,max_final=3 --variant new:k_min=4,n_mcmc=6]

Writes ``benchmarks/results/posterior_profile.json`` (``os.getloadavg()`` beside every
time). Times are medians of ``--repeat`` calls after one warm-up call per shape.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import argparse
import json
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"


def _load():
    return [round(x, 2) for x in os.getloadavg()]


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--log", default=str(ROOT / "data" / "synthetic" / "csf8_paper.csv"))
    ap.add_argument("--sizes", default="250,1000,2000")
    ap.add_argument("--chunks", default="0")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--variant", action="append", default=[],
                    help="NAME:key=value,… one sample_smc call with these keyword arguments "
                         "(chunk=N sets the batch chunk); repeatable")
    ap.add_argument("--name", default="posterior_profile")
    ap.add_argument("--save-draws", default=None, help="folder for each variant's draws (.npz)")
    a = ap.parse_args(argv)

    import hdid
    from hdid._posterior import density, smc

    out = {"log": a.log, "src": _common.src_fingerprint(), "load_start": _load(), "rows": []}
    t = time.perf_counter()
    fit = hdid.fit(a.log)
    out["fit_first_s"] = time.perf_counter() - t
    t = time.perf_counter()
    fit = hdid.fit(a.log)
    out["fit_warm_s"] = time.perf_counter() - t
    lp, found, ref, *_rest = smc._setup(fit, 0)
    t_modes = _rest[-1]
    out["mode_search_s"] = t_modes
    out["n_modes"] = len(found)
    rng = np.random.default_rng(0)
    Xref = ref.sample(max(int(s) for s in a.sizes.split(",")), rng)
    # near the optimum: the reference narrowed 5× (what the particles look like near β = 1)
    Xopt = ref.means[0] + 0.2 * (Xref - ref.means[0])
    for chunk in [int(c) for c in a.chunks.split(",")]:
        density.BATCH_CHUNK = chunk
        density._batch_jit = density.jax.jit(density._batch)  # fresh trace per chunk size
        for n in [int(s) for s in a.sizes.split(",")]:
            for where, X in (("reference", Xref[:n]), ("near optimum", Xopt[:n])):
                t = time.perf_counter()
                v = np.asarray(lp.batch(X))
                first = time.perf_counter() - t
                ts = []
                for _ in range(a.repeat):
                    t = time.perf_counter()
                    np.asarray(lp.batch(X))
                    ts.append(time.perf_counter() - t)
                row = {"chunk": chunk, "n": n, "where": where, "first_s": first,
                       "median_s": statistics.median(ts), "per_particle_ms":
                       1e3 * statistics.median(ts) / n, "finite": int(np.isfinite(v).sum()),
                       "load": _load()}
                out["rows"].append(row)
                print(json.dumps(row), flush=True)
    from hdid._posterior.smc import sample_smc

    out["smc"] = []
    for spec in a.variant:
        name, _, kv = spec.partition(":")
        kw = {}
        for item in filter(None, kv.split(",")):
            k, v = item.split("=")
            kw[k] = {"True": True, "False": False}.get(v, None) if v in ("True", "False") else (
                float(v) if "." in v else int(v))
        chunk = kw.pop("chunk", 0)
        density.BATCH_CHUNK = chunk
        density._batch_jit = density.jax.jit(density._batch)
        la = _load()
        t = time.perf_counter()
        post = sample_smc(fit, modes=found, **kw)
        wall = time.perf_counter() - t
        d = post.to_dict()["posterior_diagnostics"]
        s = post.summary()
        row = {"variant": name, "kwargs": kw, "chunk": chunk, "wall_s": wall,
               "load": [la, _load()], "stage_s": post.stage_s,
               "converged": post.converged, "rhat_max": d["convergence"]["rhat_max"],
               "ess_bulk_min": d["convergence"]["ess_bulk_min"],
               "ess_tail_min": d["convergence"]["ess_tail_min"],
               "worst": post.convergence.worst,
               "smc": {k: v for k, v in post.smc.items() if k != "betas"},
               "ci95": {n: s[n]["ci95"] for n in ("k1", "tau_c", "tau_s", "v_s",
                                                   "stick_band_halfwidth_rad")},
               "data_bracket": list(fit.band_bracket) if fit.band_bracket else None}
        out["smc"].append(row)
        if a.save_draws:
            np.savez(Path(a.save_draws) / f"{a.name}_{name}.npz",
                     **{k: np.asarray(v) for k, v in {**post.samples, **post.derived}.items()})
        print(json.dumps(row, default=str), flush=True)
        (RESULTS / f"{a.name}.json").write_text(json.dumps(out, indent=1, default=str) + "\n")
    out["load_end"] = _load()
    RESULTS.mkdir(exist_ok=True)
    (RESULTS / f"{a.name}.json").write_text(json.dumps(out, indent=1, default=str) + "\n")


if __name__ == "__main__":
    sys.exit(main())
