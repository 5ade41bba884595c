"""Friction in data coordinates against the plain coordinates, side by side (issue 17,
branch ``post6``).

Run (pinned to one core)::

    taskset -c 1 python benchmarks/posterior_coordinates.py [--logs shipped,9100,9101]
        [--max-steps 10000] [--seed 1] [--name posterior_coordinates_post6]

For each log: ``hdid.fit`` (the shipped paper log; or a paper-design log of the
independent simulator, its truth drawn as ``posterior_sbc.py --prior physical`` draws it,
with the catalog Gaussians given as ``prior=``), the optima sought once, then
``hdid.sample_posterior(fit, modes=optima, seed, prior, max_steps, coordinates=...)`` for
``plain`` (today's default) and ``friction`` in the same process, alternating which goes
first per log. Each stops when converged (arviz R-hat ≤ 1.01, bulk/tail ESS ≥ 400 on every
parameter and the band, judged in the same coordinates for both) or at ``--max-steps``.
Writes ``benchmarks/results/<name>.json`` after every run, with ``os.getloadavg()``.
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

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
SHIPPED = ROOT / "data" / "synthetic" / "csf8_paper.csv"
sys.path.insert(0, str(ROOT / "benchmarks"))
QUANTITIES = ("k1", "k2", "tau_c", "tau_s", "c_v", "v_s", "delta", "stick_band_halfwidth_rad")


def _load():
    return [round(x, 2) for x in os.getloadavg()]


def load_fit(name):
    import hdid

    if name == "shipped":
        return hdid.fit(str(SHIPPED)), None, None
    import posterior_sbc as sbc

    gen = _common.import_generate()
    seed = int(name)
    rng = np.random.default_rng(seed)
    truth, df, info, notes = sbc.draw_physical(gen, rng, gen.PAPER_DESIGN, seed)
    cat = sbc.catalog_prior(gen)
    prior = {n: cat[n] for n in sbc.PHYSICAL_GIVEN}
    fit = hdid.fit(df, inertia=truth["inertia"])
    truth = {**{k: float(v) for k, v in truth.items() if isinstance(v, (int, float))},
             "stick_band_halfwidth_rad": float(info["stick_band_halfwidth"])
             if "stick_band_halfwidth" in info else None}
    return fit, prior, truth


def row_of(post, truth):
    c = post.convergence
    s = post.summary()
    d = post.to_dict()["posterior_diagnostics"]
    out = {
        "converged": post.converged,
        "n_steps": int(post.chain.shape[0]),
        "rhat_max": float(np.nanmax(c.rhat)),
        "ess_bulk_min": float(np.nanmin(c.ess_bulk)),
        "ess_tail_min": float(np.nanmin(c.ess_tail)),
        "worst": list(c.worst),
        "tau_max": float(np.nanmax(post.tau)),
        "tau": d["tau"],
        "chain_in_tau_max": d["chain_in_tau_max"],
        "wall_s": post.wall_time_s,
        "stage_s": dict(post.stage_s),
        "move_acceptance": dict(post.move_acceptance),
        "ci95": {q: s[q]["ci95"] for q in QUANTITIES if q in s},
        "median": {q: s[q]["median"] for q in QUANTITIES if q in s},
        "warnings": [w[:160] for w in post.warnings],
    }
    if truth:
        out["covered95"] = {q: bool(s[q]["ci95"][0] <= truth[q] <= s[q]["ci95"][1])
                            for q in QUANTITIES if q in s and truth.get(q) is not None}
    return out


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", default="shipped,9100,9101")
    ap.add_argument("--max-steps", type=int, default=10000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--coords", default="plain,friction")
    ap.add_argument("--name", default="posterior_coordinates_post6")
    a = ap.parse_args()
    import hdid
    from hdid._posterior.density import posterior_density
    from hdid._posterior.modes import sampled_modes

    out = RESULTS / f"{a.name}.json"
    rows = []
    coords = a.coords.split(",")
    for k, name in enumerate(a.logs.split(",")):
        t0 = time.perf_counter()
        fit, prior, truth = load_fit(name)
        fit_s = time.perf_counter() - t0
        dens = posterior_density(fit, prior=prior)
        t = time.perf_counter()
        found = sampled_modes(fit, "auto", a.seed, dens.u_fit, dens.lin, dens.lp.gauss_prior)
        modes_s = time.perf_counter() - t
        print(name, f"fit {fit_s:.1f} s, modes {modes_s:.1f} s ({len(found)})", _load(), flush=True)
        order = coords if k % 2 == 0 else coords[::-1]
        for cs in order:
            load0 = _load()
            post = hdid.sample_posterior(fit, modes=found, seed=a.seed, prior=prior,
                                         max_steps=a.max_steps, coordinates=cs)
            r = {"log": name, "coordinates": cs, "fit_s": fit_s, "modes_s": modes_s,
                 "n_modes": len(found), "load_before": load0, "load_after": _load(),
                 "truth": truth, **row_of(post, truth)}
            rows.append(r)
            print(f"  {cs:8s} conv {r['converged']} steps {r['n_steps']} R-hat {r['rhat_max']:.3f} "
                  f"ESS {r['ess_bulk_min']:.0f}/{r['ess_tail_min']:.0f} tau {r['tau_max']:.0f} "
                  f"wall {r['wall_s']:.1f} s acc {r['move_acceptance']} worst {r['worst']} "
                  f"load {r['load_after']}", flush=True)
            out.write_text(json.dumps({
                "when": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
                "src": _common.src_fingerprint(), "cpu": _common.cpu_model(),
                "args": vars(a), "rows": rows}, indent=1))


if __name__ == "__main__":
    main()
