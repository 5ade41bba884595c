"""Same numbers, less time (issue 17, ``post8``): the mode search, the limit fits and two
seeded posteriors on the shipped paper log, dumped for comparison between trees.

Run once per tree (pinned to one core), then compare::

    PYTHONPATH=TREE/src taskset -c 0 python benchmarks/posterior_same_post8.py dump OUT.npz
    python benchmarks/posterior_same_post8.py compare REF.npz NEW.npz

``dump`` prints the wall time of ``limit_fits`` (k2, tau_c, c_v), ``find_modes`` (seed 1),
a default emcee ``sample_posterior`` (200 burn-in + 200 steps, seed 1, its stage times)
and ``method="smc"`` (seed 1), and saves the limit fits' end points, paths and costs,
the optima and weights, the emcee chain and the SMC's tau_c draws. ``compare`` prints,
per array, ``True`` when bit-identical, else the largest relative difference.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent


def dump(out: str) -> None:
    import jax.numpy as jnp

    import hdid
    from hdid._posterior.limits import limit_fits
    from hdid._posterior.modes import MODE_LANES, find_modes

    print("load", os.getloadavg())
    fit = hdid.fit(ROOT / "data" / "synthetic" / "csf8_paper.csv")
    best = float(fit.problem.cost(jnp.asarray(fit.u)))
    t = time.perf_counter()
    L = limit_fits(fit, ["k2", "tau_c", "c_v"], best, MODE_LANES)
    tl = time.perf_counter() - t
    t = time.perf_counter()
    M = find_modes(fit, seed=1)
    tm = time.perf_counter() - t
    t = time.perf_counter()
    post = hdid.sample_posterior(fit, n_steps=200, burn_in=200, seed=1, progress=False)
    tp = time.perf_counter() - t
    t = time.perf_counter()
    smc = hdid.sample_posterior(fit, method="smc", seed=1, progress=False)
    ts = time.perf_counter() - t
    d = {f"lim_{x.name}_u": x.u for x in L}
    d.update({f"lim_{x.name}_path": np.array([u for u, _ in x.path]) for x in L})
    d.update({f"lim_{x.name}_c": np.array([c for _, c in x.path] + [x.dchi2_lsq]) for x in L})
    d["modes_u"] = np.array([m.u for m in M])
    d["modes_w"] = np.array([m.weight for m in M])
    d["chain"] = post.chain
    d["smc_tc"] = np.asarray(smc.samples["tau_c"])
    np.savez(out, **d)
    print(f"limit_fits {tl:.2f} s, find_modes {tm:.2f} s, sample_posterior (200 + 200) "
          f"{tp:.2f} s (mode search {post.stage_s['mode_search']:.2f} s), smc {ts:.2f} s")
    print("load", os.getloadavg())


def compare(ref: str, new: str) -> None:
    a, b = np.load(ref), np.load(new)
    for k in a.files:
        x, y = a[k], b[k]
        same = x.shape == y.shape and np.array_equal(x, y)
        rel = (float(np.max(np.abs(x - y) / np.maximum(np.abs(x), 1e-300)))
               if x.shape == y.shape else "shape differs")
        print(k, True if same else rel)


if __name__ == "__main__":
    if sys.argv[1] == "dump":
        dump(sys.argv[2])
    else:
        compare(sys.argv[2], sys.argv[3])
