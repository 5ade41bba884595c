"""The shipped paper log's Coulomb ridge (issue 17, ``post8``): independence components at
every point of the limit continuation against post7's (the end and the first point),
side by side in one process on one fit, seeds alternating which goes first.

The ``path`` and ``ridge`` variants were retired by these measurements (benchmarks/
README.md, ``post8``): the library knobs they set are last in commit c355578 — run the
script on that tree (``git archive c355578``) for them; ``main`` and ``--k2-report`` run
on any tree since.

Run (pinned to one core)::

    PYTHONPATH=src taskset -c 0 python benchmarks/posterior_ridge_post8.py \
        --seeds 1 2 --max-steps 10000 [--variants main path]

``main``: ``limits.LIMIT_PATH_POINTS = 1`` (the default: post7's limit optima); ``path``:
``len(LIMIT_PATH) − 1`` (a frozen t-component at every continuation point within reach,
each ``LIMIT_PROPOSAL_WEIGHT`` of the independence proposal); ``ridge``: main plus
``RidgeMove`` along the continuations (``driver.RIDGE_MOVE_WEIGHT = 0.2``);
``path+ridge``: both. Records per run: R-hat /
ESS / τ, tau_c's and the band's 95 % intervals, the share of the kept chain below
tau_c 1 mN m and with k2 < 0.1 × the fit's (the k2 → 0 optimum), move acceptances, wall
per stage and the load; appends to ``results/posterior_ridge_post8.json`` and rewrites the
``.md``. ``--k2-report`` adds the k2 → 0 optimum's χ², σ_n and Laplace mass against the
best optimum's (report only).
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import argparse
import datetime as _dt
import json
import math
import os
import time
from pathlib import Path

import numpy as np

import hdid

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
SHIPPED = ROOT / "data" / "synthetic" / "csf8_paper.csv"
NAME = "posterior_ridge_post8"
BAND = "stick_band_halfwidth_rad"
#: share of the steps the ``ridge`` variants give ``RidgeMove``
RIDGE_WEIGHT = 0.2


def _load():
    return [round(x, 2) for x in os.getloadavg()]


def run(fit, variant: str, seed: int, max_steps: int) -> dict:
    from hdid._posterior import driver, limits

    if variant != "main" and not hasattr(driver, "RIDGE_MOVE_WEIGHT"):
        raise SystemExit("the path/ridge variants were retired from the library (post8): "
                         "run this script on the tree of commit c355578")
    limits.LIMIT_PATH_POINTS = len(limits.LIMIT_PATH) - 1 if "path" in variant else 1
    driver.RIDGE_MOVE_WEIGHT = RIDGE_WEIGHT if "ridge" in variant else 0.0
    la0 = _load()
    post = hdid.sample_posterior(fit, seed=seed, max_steps=max_steps, progress=False)
    la1 = _load()
    limits.LIMIT_PATH_POINTS, driver.RIDGE_MOVE_WEIGHT = 1, 0.0
    d = post.to_dict()
    diag = d["posterior_diagnostics"]
    conv = diag["convergence"] or {}
    tc = np.exp(post.chain[..., post.labels.index("tau_c")])
    k2 = np.exp(post.chain[..., post.labels.index("k2")])
    tau = dict(diag["tau"])
    return {
        "variant": variant, "seed": seed, "max_steps": max_steps,
        "date_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "load_start": la0, "load_end": la1,
        "tau_c_ci95": d["posterior"]["tau_c"]["ci95"], "band_ci95": d["posterior"][BAND]["ci95"],
        "k2_ci95": d["posterior"]["k2"]["ci95"],
        "share_tau_c_below_1mNm": float(np.mean(tc < 1e-3)),
        "share_k2_below_0.1_fit": float(np.mean(k2 < 0.1 * fit.values["k2"])),
        "converged": diag["converged"], "rhat_max": conv.get("rhat_max"),
        "ess_bulk_min": conv.get("ess_bulk_min"), "ess_tail_min": conv.get("ess_tail_min"),
        "rhat": {k: v["rhat"] for k, v in (conv.get("per_quantity") or {}).items()},
        "tau_max": diag["tau_max"], "tau_max_of": max(tau, key=lambda k: tau[k]),
        "steps": diag["n_steps"], "n_components": len(diag["modes"]),
        "move_acceptance": diag["move_acceptance"], "wall_s": diag["wall_time_s"],
        "stage_s": diag["stage_s"], "warnings": diag["warnings"],
        "modes": [{"kind": m["kind"], "weight": m["weight"], "cost": m["cost"],
                   "share": m.get("share_of_draws")} for m in diag["modes"]],
    }


def k2_report(fit) -> dict:
    """The k2 → 0 limit optimum against the best optimum: χ² (fit units), best log σ_n of
    each, −2 log p at each one's best σ_n and at the floor, Laplace log-evidence."""
    import jax.numpy as jnp

    from hdid._posterior.density import posterior_density
    from hdid._posterior.limits import limit_fits
    from hdid._posterior.modes import MODE_LANES, _laplace

    prob = fit.problem
    dens = posterior_density(fit)
    lp = dens.lp
    best = float(prob.cost(jnp.asarray(fit.u)))
    lim = {x.name: x for x in limit_fits(fit, ["k2"], best, MODE_LANES)}["k2"]
    q = float(prob.step)
    lo = math.log(dens.bounds[0] * q)
    grid = np.linspace(lo, lo + 3.0, 301)
    out = {"q_rad": q, "sigma_floor_rad": dens.bounds[0] * q,
           "rms_residual_rad": fit.rms_residual_rad}
    from hdid._diagnosis._floor import projected_floor
    from hdid._posterior.modes import _rj

    lin = np.asarray(dens.lin, dtype=float)
    P = prob.n_physical
    w = np.asarray(prob.weight, dtype=float).ravel()
    rows = np.flatnonzero(w > 0)
    sig = float(prob.sigma)
    for tag, u in (("fit", np.asarray(fit.u)), ("k2_limit", lim.u)):
        cost, cov, logz = _laplace(prob, u)
        r, J = _rj(prob, u)
        yhat = np.asarray(prob.theta, dtype=float).ravel()[rows] + r[: w.size][rows] * sig / w[rows]
        F, F_sd = projected_floor(yhat, w[rows], J, sig, sig * math.sqrt(12.0), rows)
        out.setdefault("floor", {})[tag] = {"F": F, "F_sd_over_phases": F_sd,
                                            "n_minus_k": float(np.sum(w**2)) - len(u)}
        X = np.column_stack([np.tile(u, (grid.size, 1)), grid])
        lps = np.asarray(lp.batch(lp.to_sampled_np(X)), dtype=float)
        j = int(np.argmax(lps))
        out[tag] = {"cost": cost, "laplace_log_evidence": logz,
                    "laplace_log_evidence_value_flat": logz + float(lin @ (u[:P] - np.asarray(fit.u)[:P])),
                    "values": {k: float(v) for k, v in prob.values_np(u).items()},
                    "k2": float(prob.values_np(u)["k2"]),
                    "best_sigma_rad": float(math.exp(grid[j])),
                    "log_p_at_best_sigma": float(lps[j]), "log_p_at_floor": float(lps[0]),
                    "sd_log_k2": float(math.sqrt(cov[list(prob.free).index("k2"),
                                                      list(prob.free).index("k2")]))}
    return out


def render(records: list[dict]) -> str:
    head = _common.md_head(
        ["variant", "seed", "steps", "R-hat max", "ESS bulk/tail min", "τ_max (of)",
         "tau_c 95 % [mN m]", "share tau_c < 1 mN m", "share k2 → 0", "band 95 % [mrad]",
         "acc. indep. / ridge", "wall s", "load start→end"])
    rows = []
    for r in records:
        c = _common.chain_cells(r, share_digits=3)
        acc = r["move_acceptance"].get("independence (mixture)", float("nan"))
        rac = r["move_acceptance"].get("ridge", float("nan"))
        rows.append(
            f"| {r['variant']} | {r['seed']} | {r['steps']} | {c['rhat']} | {c['ess']} | {c['tau']} "
            f"| {c['tau_c']} | {c['share']} | {r['share_k2_below_0.1_fit']:.3f} | {c['band']} "
            f"| {acc:.3f} / {rac:.3f} | {c['wall']} | {c['load']} |")
    return ("# The shipped log's Coulomb ridge: components along the limit path (issue 17, "
            "post8)\n\nWritten by `benchmarks/posterior_ridge_post8.py`; one core "
            "(`taskset -c 0`), one fit per process, variants alternating. Shares: kept "
            "chain, every step and walker.\n\n" + head + "\n".join(rows) + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--max-steps", type=int, default=10000)
    ap.add_argument("--variants", nargs="+", default=["main", "path"])
    ap.add_argument("--k2-report", action="store_true")
    a = ap.parse_args(argv)
    path = RESULTS / f"{NAME}.json"
    records = json.loads(path.read_text()) if path.exists() else []
    fit = hdid.fit(SHIPPED)
    if a.k2_report:
        rep = k2_report(fit)
        print(json.dumps(rep, indent=1))
        (RESULTS / f"{NAME}_k2.json").write_text(json.dumps(rep, indent=1) + "\n")
    for i, seed in enumerate(a.seeds):
        order = a.variants if i % 2 == 0 else a.variants[::-1]
        for v in order:
            rec = run(fit, v, seed, a.max_steps)
            records.append(rec)
            path.write_text(json.dumps(records, indent=1) + "\n")
            (RESULTS / f"{NAME}.md").write_text(render(records))
            print({k: rec[k] for k in ("variant", "seed", "rhat_max", "tau_max", "tau_max_of",
                                       "share_tau_c_below_1mNm", "share_k2_below_0.1_fit",
                                       "wall_s", "load_start", "load_end")}, flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
