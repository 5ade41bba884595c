"""Nested / neural importance sampling (nautilus) for the paper-design posterior (issue 17,
branch ``post9``), side by side with today's default emcee in one process on one fit.

Run (pinned to one core)::

    PYTHONPATH=src taskset -c 0 python benchmarks/posterior_nautilus.py \
        --logs shipped 9100 9101 --emcee-seeds 1 2 --runs 4 [--n-live 500] [--precond]

Per log: the fit, its optima and limit fits (``sampled_modes``, seed 1, shared by every
sampler), then

- ``--runs`` independent nautilus runs (seeds 1..runs) of ``LogPosterior.batch`` over a
  *reference box* (posterior repartitioning): a product of uniforms in the sampled
  coordinates spanning every optimum and limit fit ± ``--box-sd`` Laplace sd, clipped to
  the true prior's hard bounds (the ±7 box, the start angle's ±5 steps, σ_n's bounds).
  The likelihood handed to nautilus is the whole log-posterior (prior included); the
  reference box is uniform, so the target is the posterior truncated to the box. That is
  the posterior only where the box covers it: ``edge_share`` is the posterior weight in
  the outer 2 % of every box side that is *not* a true prior bound (it should be ≪ 1 %).
  log Z is that of the unnormalised density in the sampled coordinates (comparable
  between runs on one log, not between logs).
- convergence across runs: each run's weighted draws resampled to its Kish ESS
  (multinomial, random order) are one "chain"; arviz rank R-hat and bulk/tail ESS on
  every sampled quantity and the band (the library's criterion); also the spread of
  log Z, of the k2 → 0 share and of tau_c's lower tail across runs.
- today's default ``hdid.sample_posterior(fit, seed=s, max_steps=N)`` on the same fit and
  optima (``--emcee-seeds``).
- ``--precond``: emcee, walkers started from the pooled nautilus draws, its independence
  move a t-mixture (``MixtureProposal``) fitted to them by sklearn's GaussianMixture
  (``--precond-components``), DE moves as in the default; same cap. ``--precond-limits``
  adds the limit fits' t-components of the default's proposal (5 % each) to that mixture;
  ``--no-default`` skips the default runs.

Every time with the 1-min load before/after and the process CPU time; results appended to
``results/posterior_nautilus.json`` and the ``.md`` rewritten from it.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
from _common import run_head  # noqa: E402
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
NAME = "posterior_nautilus"
BAND = "stick_band_halfwidth_rad"
CHUNK = 128  # rows per LogPosterior.batch call (one compiled shape)


def _load():
    return round(os.getloadavg()[0], 2)


def log_and_optima(which: str):
    """``make_log(which)`` fitted, its posterior density and its optima + limit fits
    (``sampled_modes``, seed 1), with the fit's and the mode search's wall times."""
    from hdid._posterior.density import posterior_density
    from hdid._posterior.modes import sampled_modes

    t0 = time.perf_counter()
    fit, prior, truth = make_log(which)
    fit_s = time.perf_counter() - t0
    dens = posterior_density(fit, prior=prior)
    t1 = time.perf_counter()
    found = sampled_modes(fit, "auto", 1, dens.u_fit, dens.lin, dens.lp.gauss_prior)
    return fit, prior, truth, dens, found, fit_s, time.perf_counter() - t1


def make_log(which: str):
    """``(fit, prior)``: the shipped log (default priors) or an independent-simulator paper
    log drawn as ``posterior_sbc.py --prior physical`` draws seeds 9100/9101."""
    if which == "shipped":
        return hdid.fit(str(SHIPPED)), None, None
    import posterior_sbc as sbc

    gen = _common.import_generate()
    seed = int(which)
    rng = np.random.default_rng(seed)
    truth, df, info, _ = sbc.draw_physical(gen, rng, gen.PAPER_DESIGN, seed)
    cat = sbc.catalog_prior(gen)
    prior = {n: cat[n] for n in sbc.PHYSICAL_GIVEN}
    truth = dict(truth)
    truth[BAND] = float(info["stick_band_halfwidth"])
    return hdid.fit(df, inertia=truth["inertia"]), prior, truth


class Density:
    """``LogPosterior.batch`` in fixed chunks of ``CHUNK`` rows, counted and timed."""

    def __init__(self, lp):
        self.lp, self.n, self.t = lp, 0, 0.0

    def __call__(self, X):
        t0 = time.perf_counter()
        X = np.atleast_2d(np.asarray(X, dtype=float))
        n = len(X)
        out = np.empty(n)
        for i in range(0, n, CHUNK):
            b = X[i : i + CHUNK]
            k = len(b)
            if k < CHUNK:
                b = np.concatenate([b, np.repeat(b[:1], CHUNK - k, 0)])
            out[i : i + k] = np.asarray(self.lp.batch(b))[:k]
        self.n += n
        self.t += time.perf_counter() - t0
        return out


def reference_box(lp, fit, found, k_sd: float):
    """``(lo, hi, hard_lo, hard_hi)`` in the sampled coordinates: every optimum and limit
    fit ± ``k_sd`` Laplace sd, clipped to the prior's hard bounds (``hard_*``: the side is
    a bound of the true prior, so weight there is not a truncation)."""
    from hdid._posterior.density import PRIOR_HALF_WIDTH, START_ANGLE_HALF_WIDTH

    prob = fit.problem
    P, R = prob.n_physical, prob.n_runs
    D = lp.ndim
    X = np.array([lp.to_sampled_np(np.concatenate([m.u, [0.0]])) for m in found])
    S = np.array([np.sqrt(np.concatenate([np.clip(np.diag(lp.sampled_cov_np(m.u, m.cov)), 0, None), [0.0]]))
                  for m in found])
    lo, hi = np.min(X - k_sd * S, 0), np.max(X + k_sd * S, 0)
    blo, bhi = np.full(D, -np.inf), np.full(D, np.inf)
    c = np.asarray(lp.centre)
    G = None if lp.gauss_prior is None else np.asarray(lp.gauss_prior)
    samp = np.zeros(P) if lp.sample_linear is None else np.asarray(lp.sample_linear)
    for j in range(P):
        if G is not None and G[2, j] > 0:
            continue  # a Gaussian prior: no hard bound
        if samp[j] > 0:
            blo[j], bhi[j] = math.exp(-PRIOR_HALF_WIDTH), math.exp(PRIOR_HALF_WIDTH)
        else:
            blo[j], bhi[j] = c[j] - PRIOR_HALF_WIDTH, c[j] + PRIOR_HALF_WIDTH
    i = P + (R if prob.release_free else 0)
    blo[i : i + R] = c[i : i + R] - START_ANGLE_HALF_WIDTH
    bhi[i : i + R] = c[i : i + R] + START_ANGLE_HALF_WIDTH
    q = float(prob.step)
    blo[-1], bhi[-1] = math.log(lp.sigma_bounds[0] * q), math.log(lp.sigma_bounds[1] * q)
    lo[-1], hi[-1] = blo[-1], bhi[-1]
    hard_lo, hard_hi = lo <= blo, hi >= bhi
    return np.maximum(lo, blo), np.minimum(hi, bhi), hard_lo, hard_hi


def wquantile(x, w, qs):
    i = np.argsort(x)
    cw = np.cumsum(w[i])
    cw /= cw[-1]
    return [float(x[i][min(np.searchsorted(cw, q), len(x) - 1)]) for q in qs]


def summarise(lp, fit, X, w, rng, n_band=4000):
    """Mode share, tau_c's lower tail, the band's interval from weighted draws ``X``."""
    from hdid._posterior.density import derived_np, to_physical

    prob = fit.problem
    w = w / w.sum()
    U = lp.from_sampled_np(X)
    phys = to_physical(prob, U)
    k2f, tcf = fit.values["k2"], fit.values["tau_c"]
    idx = rng.choice(len(w), size=n_band, p=w)
    band = derived_np(prob, U[idx])[BAND]
    return {
        "share_k2_below_0.1_fit": float(np.sum(w * (phys["k2"] < 0.1 * k2f))),
        "share_tau_c_below_1mNm": float(np.sum(w * (phys["tau_c"] < 1e-3))),
        "tau_c_q025": wquantile(phys["tau_c"], w, [0.025])[0],
        "tau_c_ci95": wquantile(phys["tau_c"], w, [0.025, 0.975]),
        "v_s_ci95": wquantile(phys["v_s"], w, [0.025, 0.975]),
        "band_ci95": [float(v) for v in np.quantile(band, [0.025, 0.975])],
        "tau_c_fit": float(tcf),
    }


def run_nautilus(lp, fit, box, seed, n_live, n_eff, n_networks, n_batch, rng):
    import nautilus

    lo, hi, hard_lo, hard_hi = box
    dens = Density(lp)
    D = lp.ndim

    def prior(c):
        return lo + (hi - lo) * c

    la0, t0, c0 = _load(), time.perf_counter(), time.process_time()
    s = nautilus.Sampler(prior, dens, n_dim=D, n_live=n_live, vectorized=True,
                         pass_dict=False, seed=seed, n_batch=n_batch, n_networks=n_networks)
    s.run(verbose=False, n_eff=n_eff, discard_exploration=True)
    wall, cpu, la1 = time.perf_counter() - t0, time.process_time() - c0, _load()
    X, lw, _ = s.posterior()
    w = np.exp(lw - lw.max())
    w /= w.sum()
    span = hi - lo
    edge = np.zeros(D)
    for j in range(D):
        near = np.zeros(len(w), dtype=bool)
        if not hard_lo[j]:
            near |= X[:, j] < lo[j] + 0.02 * span[j]
        if not hard_hi[j]:
            near |= X[:, j] > hi[j] - 0.02 * span[j]
        edge[j] = np.sum(w[near])
    out = {"seed": seed, "wall_s": wall, "cpu_s": cpu, "load_start": la0, "load_end": la1,
           "n_like": dens.n, "like_s": dens.t, "n_bounds": len(s.bounds),
           "log_z": float(s.log_z),
           # the box's uniform density 1/V: log ∫ p̃ = log Z + log V (comparable across boxes)
           "log_z_unnorm": float(s.log_z + np.sum(np.log(hi - lo))), "n_eff": float(s.n_eff), "kish": float(1 / np.sum(w**2)),
           "edge_share_max": float(edge.max()), "edge_worst": int(np.argmax(edge)),
           "n_live": n_live, "n_networks": n_networks, "n_batch": n_batch}
    out.update(summarise(lp, fit, X, w, rng))
    return out, X, w


def across_runs(lp, fit, labels, runs, rng):
    """arviz R-hat/ESS with each run's draws (resampled to its Kish ESS) as a chain."""
    from hdid._posterior.density import derived_np
    from hdid._posterior.diagnostics import convergence

    n = int(min(r[0]["kish"] for r in runs))
    chains = []
    for _, X, w in runs:
        idx = rng.choice(len(w), size=n, p=w / w.sum())
        Xi = X[idx]
        band = derived_np(fit.problem, lp.from_sampled_np(Xi))[BAND]
        chains.append(np.column_stack([Xi, band]))
    C = np.stack(chains, axis=1)  # (draws, chains, K)
    conv = convergence(C, labels + [BAND])
    d = conv.to_dict()
    d["converged"] = bool(conv.converged)
    d["worst"] = list(conv.worst)
    d["draws_per_chain"] = n
    d["kish_total"] = float(sum(r[0]["kish"] for r in runs))
    return d


def emcee_record(post, fit, seed, wall, cpu, la0, la1):
    d = post.to_dict()
    diag = d["posterior_diagnostics"]
    conv = diag["convergence"] or {}
    ch = post.chain
    tc = np.exp(ch[..., post.labels.index("tau_c")])
    k2 = np.exp(ch[..., post.labels.index("k2")])
    return {"seed": seed, "wall_s": wall, "cpu_s": cpu, "load_start": la0, "load_end": la1,
            "steps": int(ch.shape[0]), "walkers": int(ch.shape[1]),
            "n_like": int((ch.shape[0] + post.burn_in) * ch.shape[1]),
            "converged": bool(post.converged), "rhat_max": conv.get("rhat_max"),
            "ess_bulk_min": conv.get("ess_bulk_min"), "ess_tail_min": conv.get("ess_tail_min"),
            "worst": conv.get("worst"), "tau_max": diag["tau_max"],
            "stage_s": post.stage_s, "move_acceptance": diag["move_acceptance"],
            "share_k2_below_0.1_fit": float(np.mean(k2 < 0.1 * fit.values["k2"])),
            "share_tau_c_below_1mNm": float(np.mean(tc < 1e-3)),
            "tau_c_q025": float(np.quantile(tc, 0.025)),
            "tau_c_ci95": d["posterior"]["tau_c"]["ci95"], "v_s_ci95": d["posterior"]["v_s"]["ci95"],
            "band_ci95": d["posterior"][BAND]["ci95"]}


def precond_moves(X, w, n_comp, rng, inflate=1.2, extra=None):
    """DE moves as the default's plus independence MH from a t-mixture fitted to the
    nautilus draws (sampled coordinates); ``extra`` = ``(means, covs, weight each)``:
    components added as they are (the limit fits', ``--precond-limits``)."""
    import emcee
    from sklearn.mixture import GaussianMixture

    from hdid._posterior.moves import MixtureProposal

    idx = rng.choice(len(w), size=min(20000, 4 * len(w)), p=w / w.sum())
    Y = X[idx]
    sc = Y.std(0)
    gm = GaussianMixture(n_comp, covariance_type="full", reg_covar=1e-6, random_state=0,
                         n_init=1, max_iter=300).fit(Y / sc)
    means = gm.means_ * sc
    covs = gm.covariances_ * np.outer(sc, sc)[None] * inflate**2
    weights = gm.weights_
    if extra is not None and len(extra[0]):
        em, ec, ew = extra
        weights = np.concatenate([weights * (1 - ew * len(em)), np.full(len(em), ew)])
        means, covs = np.concatenate([means, em]), np.concatenate([covs, ec])
    mix = MixtureProposal(means, covs, weights, nu=8.0)
    return [(emcee.moves.DEMove(), 0.4), (emcee.moves.DEMove(gamma0=1.0), 0.05),
            (emcee.moves.DESnookerMove(), 0.2), (emcee.moves.MHMove(mix), 0.35)], mix


def walker_modes(lp, found, X, w, W, rng):
    from dataclasses import replace

    idx = rng.choice(len(w), size=W, replace=False, p=w / w.sum())
    U = lp.from_sampled_np(X[idx])
    D1 = found[0].u.size
    return [replace(found[0], u=U[i, :-1].copy(), cov=1e-10 * np.eye(D1), weight=1.0 / W,
                    kind="optimum", limit=None, cost=found[0].cost,
                    log_evidence=found[0].log_evidence) for i in range(W)]


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", nargs="+", default=["shipped"])
    ap.add_argument("--emcee-seeds", nargs="*", type=int, default=[1])
    ap.add_argument("--runs", type=int, default=4)
    ap.add_argument("--n-live", type=int, default=500)
    ap.add_argument("--n-eff", type=int, default=2000)
    ap.add_argument("--n-networks", type=int, default=1)
    ap.add_argument("--n-batch", type=int, default=1024)
    ap.add_argument("--box-sd", type=float, default=4.0)
    ap.add_argument("--max-steps", type=int, default=10000)
    ap.add_argument("--precond", action="store_true")
    ap.add_argument("--precond-components", type=int, default=12)
    ap.add_argument("--precond-limits", action="store_true",
                    help="add the limit fits' t-components (5 %% each) to the fitted mixture")
    ap.add_argument("--no-default", action="store_true", help="skip the default emcee runs")
    ap.add_argument("--tag", default="")
    args = ap.parse_args(argv)
    from hdid._fitting._identifiability import unknown_labels
    from hdid._posterior.result import _RunNames

    out_json = RESULTS / f"{NAME}.json"
    allres = json.loads(out_json.read_text()) if out_json.exists() else []
    for which in args.logs:
        fit, prior, truth, dens, found, fit_s, modes_s = log_and_optima(which)
        lp = dens.lp
        labels = unknown_labels(fit.problem, _RunNames(fit)) + ["log_noise_sigma"]
        box = reference_box(lp, fit, found, args.box_sd)
        dens0 = Density(lp)
        t2 = time.perf_counter()
        dens0(np.tile(lp.to_sampled_np(np.concatenate([dens.u_fit, [-8.0]])), (CHUNK, 1)))
        compile_s = time.perf_counter() - t2
        rec = {"log": which, "tag": args.tag, "src": _common.src_fingerprint(),
               "date_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
               "fit_s": fit_s, "mode_search_s": modes_s, "compile_s": compile_s,
               "n_modes": len(found), "modes": [m.to_dict() for m in found],
               "box_sd": args.box_sd, "truth": truth, "labels": labels,
               "box": [box[0].tolist(), box[1].tolist()], "nautilus": [], "emcee": []}
        rng = np.random.default_rng(0)
        runs = []
        for r in range(1, args.runs + 1):
            o, X, w = run_nautilus(lp, fit, box, r, args.n_live, args.n_eff, args.n_networks,
                                   args.n_batch, rng)
            print(which, "nautilus", json.dumps({k: o[k] for k in (
                "seed", "wall_s", "cpu_s", "n_like", "like_s", "log_z_unnorm", "kish", "edge_share_max",
                "share_k2_below_0.1_fit", "share_tau_c_below_1mNm", "band_ci95", "load_start")}),
                flush=True)
            rec["nautilus"].append(o)
            runs.append((o, X, w))
        if len(runs) >= 2:
            rec["nautilus_across"] = across_runs(lp, fit, labels, runs, rng)
            print(which, "across", json.dumps({k: rec["nautilus_across"][k] for k in (
                "rhat_max", "ess_bulk_min", "ess_tail_min", "worst", "draws_per_chain")}), flush=True)
        for s in ([] if args.no_default else args.emcee_seeds):
            la0, ta, ca = _load(), time.perf_counter(), time.process_time()
            post = hdid.sample_posterior(fit, seed=s, max_steps=args.max_steps, progress=False,
                                         modes=found, prior=prior)
            e = emcee_record(post, fit, s, time.perf_counter() - ta, time.process_time() - ca,
                             la0, _load())
            rec["emcee"].append(e)
            print(which, "emcee", json.dumps({k: e[k] for k in (
                "seed", "wall_s", "rhat_max", "ess_bulk_min", "tau_max",
                "share_k2_below_0.1_fit", "share_tau_c_below_1mNm", "band_ci95")}), flush=True)
        if args.precond and runs:
            Xp = np.concatenate([X for _, X, _ in runs])
            wp = np.concatenate([w / w.sum() for _, _, w in runs])
            rec["precond"] = []
            for s in args.emcee_seeds:
                rngp = np.random.default_rng(s)
                extra = None
                if args.precond_limits:
                    from hdid._posterior.moves import START_SCALE

                    lim = [m for m in found if m.kind != "optimum"]
                    s_mid = float(np.sum(wp * Xp[:, -1]))
                    em = lp.to_sampled_np(np.array([np.concatenate([m.u, [s_mid]]) for m in lim]))
                    ec = np.zeros((len(lim), lp.ndim, lp.ndim))
                    for k, m in enumerate(lim):
                        ec[k, :-1, :-1] = lp.sampled_cov_np(m.u, START_SCALE**2 * m.cov)
                        ec[k, -1, -1] = 0.6**2
                    extra = (em, ec, 0.05)
                moves, mix = precond_moves(Xp, wp, args.precond_components, rngp, extra=extra)
                W = max(32, 2 * lp.ndim)
                start = walker_modes(lp, found, Xp, wp, W, rngp)
                la0, ta, ca = _load(), time.perf_counter(), time.process_time()
                post = hdid.sample_posterior(fit, seed=s, max_steps=args.max_steps,
                                             progress=False, modes=start, moves=moves,
                                             prior=prior)
                e = emcee_record(post, fit, s, time.perf_counter() - ta,
                                 time.process_time() - ca, la0, _load())
                e["components"] = args.precond_components
                e["limit_components"] = bool(args.precond_limits)
                # the mixture's own importance ESS against the nautilus draws' log p
                rec["precond"].append(e)
                print(which, "precond", json.dumps({k: e[k] for k in (
                    "seed", "wall_s", "rhat_max", "ess_bulk_min", "tau_max", "move_acceptance",
                    "share_k2_below_0.1_fit", "band_ci95")}), flush=True)
        allres.append(rec)
        out_json.write_text(json.dumps(allres, indent=1, default=float))
    render(allres)


def _f(x, n=3):
    if x is None:
        return "–"
    if isinstance(x, (list, tuple)):
        return "[" + ", ".join(_f(v, n) for v in x) + "]"
    return f"{x:.{n}g}"


def render(allres):
    L = ["# Posterior: nautilus against the default emcee (issue 17, branch post9)\n",
         "Generated by `benchmarks/posterior_nautilus.py` from `posterior_nautilus.json`. "
         "One core (`taskset -c 0`); load = 1-min average at the start.\n"]
    for rec in allres:
        L += run_head(rec, f" {rec.get('tag', '')}",
                      f" ({rec['n_modes']}), compile {rec['compile_s']:.1f} s, box ± {rec['box_sd']} sd",
                      ["sampler", "seed", "wall s", "CPU s", "load", "density evals", "R-hat max",
                       "ESS bulk/tail min", "τ_max", "log Z", "k2→0 share", "tau_c < 1 mN m",
                       "tau_c 2.5 % [mN m]", "band 95 % [mrad]", "edge share"])
        for o in rec["nautilus"]:
            L.append(f"| nautilus (n_live {o['n_live']}) | {o['seed']} | {o['wall_s']:.0f} | {o['cpu_s']:.0f} | "
                     f"{o['load_start']} | {o['n_like']} ({o['like_s']:.0f} s) | | Kish {o['kish']:.0f} | | "
                     f"{o['log_z_unnorm']:.2f} | {o['share_k2_below_0.1_fit']:.4f} | "
                     f"{o['share_tau_c_below_1mNm']:.4f} | {1e3 * o['tau_c_q025']:.2f} | "
                     f"{_f([1e3 * b for b in o['band_ci95']])} | {o['edge_share_max']:.1e} |")
        a = rec.get("nautilus_across")
        if a:
            L.append(f"| nautilus, {len(rec['nautilus'])} runs as chains | | | | | | {a['rhat_max']:.3f} | "
                     f"{a['ess_bulk_min']:.0f} / {a['ess_tail_min']:.0f} (Kish Σ {a['kish_total']:.0f}) | | | | | | | |")
        for kind in ("emcee", "precond"):
            for e in rec.get(kind, []):
                name = ("default emcee" if kind == "emcee" else "emcee, nautilus-preconditioned"
                        + (" + limit components" if e.get("limit_components") else ""))
                L.append(f"| {name} | {e['seed']} | "
                         f"{e['wall_s']:.0f} | {e['cpu_s']:.0f} | {e['load_start']} | {e['n_like']} | "
                         f"{_f(e['rhat_max'], 4)} | {_f(e['ess_bulk_min'], 3)} / {_f(e['ess_tail_min'], 3)} | "
                         f"{e['tau_max']:.0f} | | {e['share_k2_below_0.1_fit']:.4f} | "
                         f"{e['share_tau_c_below_1mNm']:.4f} | {1e3 * e['tau_c_q025']:.2f} | "
                         f"{_f([1e3 * b for b in e['band_ci95']])} | |")
        for e in rec.get("precond", []):
            L.append(f"\nprecond seed {e['seed']}: move acceptance {json.dumps(e['move_acceptance'])}")
    (RESULTS / f"{NAME}.md").write_text("\n".join(L) + "\n")


if __name__ == "__main__":
    main()
