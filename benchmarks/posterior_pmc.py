"""Defensive adaptive importance sampling (population Monte Carlo, deterministic-mixture
weights) of the paper-design posterior (issue 17, branch ``post10``); measurement only.

Run (pinned to one core)::

    PYTHONPATH=src:benchmarks taskset -c 0 python benchmarks/posterior_pmc.py \
        --logs shipped --seed 1 --iters 10 --per-iter 200000

Per log: the fit, its optima and limit fits (``sampled_modes``, seed 1, as
``posterior_nautilus.py`` / ``posterior_nautilus_is.py``), then

- **frozen components** (never refitted): one multivariate t (ν = 4) at every optimum and
  limit fit of ``sampled_modes`` *and at every further point of each limit continuation*
  within ``MODE_DCHI2_MAX`` (``LimitFit.path``; post8's retired ``LIMIT_PATH_POINTS``
  idea), each with ``--inflate``² × its Laplace covariance (sampled coordinates), weights
  ½ Laplace (the optima's, as post9's IS) + ½ uniform over the components; log σ_n
  uniform over its prior. Iteration 0 draws from these alone (post9's IS proposal plus
  the path points).
- **adaptive components** from iteration 1: a Gaussian mixture over all D coordinates
  (σ_n included), fitted by weighted EM (a few steps from the previous one, covariances
  shrunk towards the previous with ``--shrink`` pseudo-draws, components below 1e-3 of
  the weight dropped) to *all* draws so far with their deterministic-mixture weights,
  proposed as t's (ν = 4) with ``--adapt-inflate``² × the fitted covariance.
  Iteration t ≥ 1 proposes from ``q_t = α q_frozen + (1 − α) q_adapt,t``
  (α = ``--defensive``, ½ by default), so the ridge and the k2 → 0 mode keep half the
  draws' components whatever the adaptation does.
- **weights** (DM-PMC, balance heuristic over every iteration's proposal): draw i has
  ``w_i = p̃(x_i) / Σ_t (N_t/N) q_t(x_i)``; each new proposal is evaluated at all earlier
  draws and each new draw at all earlier proposals.

Reported per iteration (cumulative): density evaluations, wall and CPU time (the density's
compile apart), Kish ESS overall and of the draws in each region (tau_c < 1 mN m; k2 <
0.1 × the fit's k2), the regions' shares, the band's 95 % interval, log ∫ p̃ =
log mean(w) (comparable with ``posterior_nautilus``'s ``log_z_unnorm``), the largest
normalised weight, the 1-min load; also the share beyond the edges of nautilus's 95 %
intervals on the shipped log (``REGIONS``: v_s > 7.5 rad/s, tau_c < 2.4 mN m), and per run
the ten heaviest draws (``top_weights``: values, nearest frozen component). ``--final N``:
a last plain (non-adaptive, so unbiased) IS pass of N draws from the final proposal.
Appends to ``results/posterior_pmc.json`` and rewrites ``results/posterior_pmc.md``.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
from _common import run_head  # noqa: E402
import argparse
import datetime as _dt
import json
import math
import time

import numpy as np
from scipy.special import gammaln, logsumexp

from posterior_nautilus import BAND, RESULTS, Density, _load, log_and_optima

NAME = "posterior_pmc"
NU = 4.0


class TMix:
    """A mixture of multivariate t's (ν = ``NU``) with per-component matmuls (BLAS), for
    evaluating many draws against many proposals."""

    def __init__(self, means, covs, weights, nu=NU):
        self.means = np.asarray(means, float)
        self.covs = np.asarray(covs, float)
        w = np.clip(np.asarray(weights, float), 1e-300, None)
        self.weights = w / w.sum()
        self.nu = nu
        D = self.means.shape[1]
        self.chols = np.array([np.linalg.cholesky(c + 1e-12 * np.trace(c) / D * np.eye(D)) for c in self.covs])
        self.linvT = np.array([np.linalg.inv(L).T for L in self.chols])
        self.lognorm = (gammaln(0.5 * (nu + D)) - gammaln(0.5 * nu) - 0.5 * D * math.log(nu * math.pi)
                        - np.sum(np.log(np.diagonal(self.chols, axis1=1, axis2=2)), axis=1))

    def logpdf(self, X, block=65536):
        D = self.means.shape[1]
        out = np.empty(len(X))
        for i in range(0, len(X), block):
            Xb = X[i: i + block]
            acc = np.full(len(Xb), -np.inf)
            for k in range(len(self.weights)):
                Z = (Xb - self.means[k]) @ self.linvT[k]
                lk = (math.log(self.weights[k]) + self.lognorm[k]
                      - 0.5 * (self.nu + D) * np.log1p(np.einsum("ij,ij->i", Z, Z) / self.nu))
                acc = np.logaddexp(acc, lk)
            out[i: i + block] = acc
        return out

    def sample(self, n, rng):
        k = rng.choice(len(self.weights), size=n, p=self.weights)
        z = rng.standard_normal((n, self.means.shape[1]))
        g = rng.chisquare(self.nu, size=n) / self.nu
        return self.means[k] + np.einsum("nij,nj->ni", self.chols[k], z) / np.sqrt(g)[:, None]


class Proposal:
    """α · (frozen t-mixture × uniform log σ_n) + (1 − α) · adaptive t-mixture (all D)."""

    def __init__(self, frozen, slo, shi, adapt=None, alpha=1.0):
        self.frozen, self.slo, self.shi, self.adapt = frozen, slo, shi, adapt
        self.alpha = 1.0 if adapt is None else alpha

    def sample(self, n, rng):
        nf = n if self.adapt is None else rng.binomial(n, self.alpha)
        Yf = np.column_stack([self.frozen.sample(nf, rng), rng.uniform(self.slo, self.shi, nf)])
        if self.adapt is None:
            return Yf
        X = np.concatenate([Yf, self.adapt.sample(n - nf, rng)])
        return X[rng.permutation(n)]

    def logpdf_frozen(self, X):
        ok = (X[:, -1] >= self.slo) & (X[:, -1] <= self.shi)
        return np.where(ok, self.frozen.logpdf(X[:, :-1]) - math.log(self.shi - self.slo), -np.inf)

    def logpdf(self, X, lq_frozen=None):
        lf = self.logpdf_frozen(X) if lq_frozen is None else lq_frozen
        if self.adapt is None:
            return lf
        return np.logaddexp(math.log(self.alpha) + lf, math.log1p(-self.alpha) + self.adapt.logpdf(X))


def weighted_em(X, w, means, covs, weights, shrink, steps=3, floor=1e-3):
    """Weighted Gaussian EM from ``(means, covs, weights)`` on draws ``X`` with normalised
    weights ``w``; covariances shrunk towards the starting ones with ``shrink``
    pseudo-draws (in units of the component's Kish ESS); components below ``floor`` of
    the weight dropped."""
    D = X.shape[1]
    for _ in range(steps):
        g = TMix(means, covs, weights, nu=1e6)  # ≈ Gaussian responsibilities
        lg = np.empty((len(X), len(weights)))
        for k in range(len(weights)):
            Z = (X - g.means[k]) @ g.linvT[k]
            lg[:, k] = math.log(g.weights[k]) + g.lognorm[k] - 0.5 * np.einsum("ij,ij->i", Z, Z)
        r = np.exp(lg - lg.max(1, keepdims=True))
        r /= r.sum(1, keepdims=True)
        nm, nc, nw = [], [], []
        for k in range(len(weights)):
            a = w * r[:, k]
            s = a.sum()
            if s < floor:
                continue
            ess = s**2 / np.sum(a**2)
            mu = a @ X / s
            d = X - mu
            S = (a[:, None] * d).T @ d / s
            lam = ess / (ess + shrink)
            C = lam * S + (1 - lam) * covs[k] + 1e-10 * np.eye(D)
            nm.append(lam * mu + (1 - lam) * means[k])
            nc.append(C)
            nw.append(s)
        means, covs, weights = np.array(nm), np.array(nc), np.array(nw) / np.sum(nw)
    return means, covs, weights


#: regions reported: ``name -> (share key, Kish key, draws key)``; the first two are the
#: brief's, the last two the edges of nautilus's 95 % intervals on the shipped log (post9:
#: v_s's 97.5 % point 6.6–7.5 rad/s, tau_c's 2.5 % point 2.41–2.47 mN m)
REGIONS = {
    "tau_c": ("share_tau_c_below_1mNm", "kish_tau_c_region", "draws_tau_c_region"),
    "k2": ("share_k2_below_0.1_fit", "kish_k2_region", "draws_k2_region"),
    "v_s_high": ("share_v_s_above_7.5", "kish_v_s_high_region", "draws_v_s_high_region"),
    "tau_c_ridge": ("share_tau_c_below_2.4mNm", "kish_tau_c_ridge_region", "draws_tau_c_ridge_region"),
}


def _masks(phys, k2_fit):
    return {"tau_c": phys["tau_c"] < 1e-3, "k2": phys["k2"] < 0.1 * k2_fit,
            "v_s_high": phys["v_s"] > 7.5, "tau_c_ridge": phys["tau_c"] < 2.4e-3}


def _normalised(lw):
    """``(w, finite, log mean(exp lw))`` of log weights ``lw`` (−inf outside the prior)."""
    ok = np.isfinite(lw)
    w = np.zeros(len(lw))
    w[ok] = np.exp(lw[ok] - lw[ok].max())
    return w / w.sum(), ok, float(logsumexp(lw[ok]) - math.log(len(lw)))


def _kish(v):
    return float(v.sum() ** 2 / np.sum(v**2)) if v.sum() > 0 else 0.0


def _summary(w, masks, X, lp, prob, rng):
    """Kish ESS, the largest weight, each region's share / Kish / draws, and the band's
    and the physical parameters' quantiles from 4000 draws resampled by ``w``."""
    from hdid._posterior.density import derived_np, to_physical

    out = {"kish": _kish(w), "max_weight": float(w.max())}
    for name, (ks, kk, kd) in REGIONS.items():
        m = masks[name]
        out[ks], out[kk], out[kd] = float(w[m].sum()), _kish(w[m]), int(m.sum())
    U = lp.from_sampled_np(X[rng.choice(len(w), size=4000, p=w)])
    phu = to_physical(prob, U)
    out["band_ci95"] = [float(v) for v in np.quantile(derived_np(prob, U)[BAND], [0.025, 0.975])]
    out["tau_c_ci95"] = [float(v) for v in np.quantile(phu["tau_c"], [0.025, 0.975])]
    out["physical_ci95"] = {k: [float(v) for v in np.quantile(a, [0.025, 0.5, 0.975])] for k, a in phu.items()}
    return out


def _largest_z(x, mix, k, labels, n=4):
    """The ``n`` coordinates where ``x`` is furthest from component ``k``'s mean, in its
    marginal sd (the frozen covariance, inflation included)."""
    z = (x - mix.means[k]) / np.sqrt(np.diag(mix.covs[k]))
    return {labels[i]: round(float(z[i]), 2) for i in np.argsort(-np.abs(z))[:n]}


def frozen_components(fit, lp, found, inflate):
    """Means, covariances and weights of the frozen t's: every optimum / limit fit of
    ``found`` and every further point of each limit continuation within
    ``MODE_DCHI2_MAX``."""
    from hdid._posterior.modes import MODE_DCHI2_MAX, _laplace

    prob = fit.problem
    us, covs, lw, kinds = [], [], [], []
    for m in found:
        us.append(m.u), covs.append(m.cov), lw.append(m.weight), kinds.append(m.kind)
    for m in found:
        if m.limit is None:
            continue
        for u, c in m.limit.path[1:]:  # path[0] is already a limit optimum of ``found``
            if c < MODE_DCHI2_MAX:
                _, cov, _ = _laplace(prob, u)
                us.append(np.asarray(u, float)), covs.append(cov), lw.append(0.0)
                kinds.append(f"path:{m.limit.name}")
    means = lp.to_sampled_np(np.array([np.concatenate([u, [0.0]]) for u in us]))[:, :-1]
    C = np.array([lp.sampled_cov_np(u, c) * inflate**2 for u, c in zip(us, covs)])
    lw = np.array(lw)
    w = 0.5 * lw / lw.sum() + 0.5 / len(us)
    return means, C, w, kinds


def run(which, args, rng_seed):
    from hdid._posterior.density import to_physical

    fit, prior, truth, dens, found, fit_s, modes_s = log_and_optima(which)
    lp = dens.lp
    prob = fit.problem
    q = float(prob.step)
    slo, shi = math.log(lp.sigma_bounds[0] * q), math.log(lp.sigma_bounds[1] * q)
    t2 = time.perf_counter()
    fm, fc, fw, kinds = frozen_components(fit, lp, found, args.inflate)
    frozen = TMix(fm, fc, fw)
    comp_s = time.perf_counter() - t2
    f = Density(lp)
    t3 = time.perf_counter()
    f(np.tile(np.concatenate([fm[0], [slo + 1]]), (128, 1)))
    compile_s = time.perf_counter() - t3
    f.n, f.t = 0, 0.0
    k2f = fit.values["k2"]
    rng = np.random.default_rng(rng_seed)

    rec = {"log": which, "seed": rng_seed, "src": _common.src_fingerprint(),
           "date_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
           "fit_s": fit_s, "mode_search_s": modes_s, "components_s": comp_s, "compile_s": compile_s,
           "n_frozen": len(kinds), "frozen_kinds": kinds, "defensive": args.defensive,
           "inflate": args.inflate, "adapt_inflate": args.adapt_inflate, "shrink": args.shrink,
           "per_iter": args.per_iter, "truth": truth, "iters": []}
    X = np.empty((0, lp.ndim))
    lpx = np.empty(0)
    lqf = np.empty(0)        # log q_frozen (σ_n uniform) at every draw
    sumq = np.empty(0)       # log Σ_t N_t q_t(x_i) over the proposals so far
    masks = {k: np.empty(0, bool) for k in REGIONS}
    props, Ns = [], []
    adapt = None
    la0, tw0, tc0 = _load(), time.perf_counter(), time.process_time()
    for it in range(args.iters):
        ti, ci = time.perf_counter(), time.process_time()
        prop = Proposal(frozen, slo, shi, adapt, args.defensive)
        N = args.per_iter
        Y = prop.sample(N, rng)
        ly = f(Y)
        ta = time.perf_counter()
        lqf_y = prop.logpdf_frozen(Y)
        # earlier draws under the new proposal; new draws under every proposal so far
        if len(X):
            lnew_old = math.log(N) + prop.logpdf(X, lqf)
            sumq = np.logaddexp(sumq, lnew_old)
        acc = np.full(N, -np.inf)
        for P_, n_ in zip(props + [prop], Ns + [N]):
            acc = np.logaddexp(acc, math.log(n_) + P_.logpdf(Y, lqf_y))
        props.append(prop), Ns.append(N)
        X, lpx, lqf, sumq = (np.concatenate([X, Y]), np.concatenate([lpx, ly]),
                             np.concatenate([lqf, lqf_y]), np.concatenate([sumq, acc]))
        mk = _masks(to_physical(prob, lp.from_sampled_np(Y)), k2f)
        masks = {k: np.concatenate([masks[k], v]) for k, v in mk.items()}
        Ntot = len(X)
        w, ok, log_z = _normalised(lpx - (sumq - math.log(Ntot)))
        # this iteration's own weights (its proposal alone): a check of the adaptation
        kish_iter = _kish(_normalised(ly - prop.logpdf(Y, lqf_y))[0])
        summ = _summary(w, masks, X, lp, prob, rng)
        adapt_s = 0.0
        if it + 1 < args.iters:
            # refit the adaptive part to every draw so far (DM weights), trimmed to the
            # draws carrying weight
            tb = time.perf_counter()
            keep = w > 1e-9 * w.max()
            if adapt is None:
                # start: every frozen component, σ_n at its weighted mean/var
                ms = np.sum(w * X[:, -1])
                vs = max(np.sum(w * (X[:, -1] - ms) ** 2), 1e-4)
                m0 = np.column_stack([fm, np.full(len(fm), ms)])
                c0 = np.zeros((len(fm), lp.ndim, lp.ndim))
                c0[:, :-1, :-1] = fc / args.inflate**2
                c0[:, -1, -1] = vs
                w0 = np.full(len(fm), 1.0 / len(fm))
            else:
                m0, c0, w0 = am, ac, aw
            am, ac, aw = weighted_em(X[keep], w[keep] / w[keep].sum(), m0, c0, w0, args.shrink)
            adapt = TMix(am, ac * args.adapt_inflate**2, aw)
            adapt_s = time.perf_counter() - tb
        row = {"iter": it, "evals": int(f.n), "draws_iter": N,
               "wall_s": time.perf_counter() - tw0, "cpu_s": time.process_time() - tc0,
               "iter_wall_s": time.perf_counter() - ti, "iter_cpu_s": time.process_time() - ci,
               "density_s": f.t, "weights_s": time.perf_counter() - ta - adapt_s, "adapt_s": adapt_s,
               "load": _load(), "n_adapt": 0 if props[-1].adapt is None else len(props[-1].adapt.weights),
               "finite_share": float(ok.mean()), "kish_iter": kish_iter, "log_z_unnorm": log_z, **summ}
        rec["iters"].append(row)
        print(which, rng_seed, json.dumps({k: (round(v, 5) if isinstance(v, float) else v)
                                           for k, v in row.items()}), flush=True)
    if args.final:
        # a plain (non-adaptive, unbiased) importance-sampling pass from the last
        # iteration's proposal, refitted to all draws: its weights are p/q_last alone
        prop = Proposal(frozen, slo, shi, adapt, args.defensive)
        ti, ci, laf = time.perf_counter(), time.process_time(), _load()
        Yf = prop.sample(args.final, rng)
        lyf = f(Yf)
        lwf = lyf - prop.logpdf(Yf)
        wf, _, log_zf = _normalised(lwf)
        mf = _masks(to_physical(prob, lp.from_sampled_np(Yf)), k2f)
        rec["final"] = {"draws": args.final, "wall_s": time.perf_counter() - ti,
                        "cpu_s": time.process_time() - ci, "load_start": laf, "load_end": _load(),
                        "n_adapt": len(adapt.weights), "log_z_unnorm": log_zf,
                        **_summary(wf, mf, Yf, lp, prob, rng)}
        print(which, rng_seed, "final", json.dumps(rec["final"]), flush=True)
    rec["load_start"], rec["load_end"] = la0, _load()
    # the DM weights' heaviest draws: which proposal component family they sit nearest
    top = np.argsort(-w)[:10]
    tclo, k2lo = masks["tau_c"], masks["k2"]
    from hdid._fitting._identifiability import unknown_labels
    from hdid._posterior.result import _RunNames

    labels = unknown_labels(prob, _RunNames(fit))
    ph = to_physical(prob, lp.from_sampled_np(X[top]))
    fr = frozen
    dist = np.array([[float(np.sum(((X[i, :-1] - fr.means[k]) @ fr.linvT[k]) ** 2)) for k in range(len(kinds))]
                     for i in top])
    rec["log_p_max"] = float(np.max(lpx[np.isfinite(lpx)]))
    rec["top_weights"] = [{"w": float(w[i]), "tau_c_below_1mNm": bool(tclo[i]), "k2_low": bool(k2lo[i]),
                           "log_p": float(lpx[i]), "log_q_frozen": float(lqf[i]),
                           "log_q_mix": float(sumq[i] - math.log(Ntot)),
                           "log_sigma_n": float(X[i, -1]), "sigma_bounds_log": [slo, shi],
                           "nearest_frozen": kinds[int(np.argmin(dist[j]))],
                           "nearest_frozen_maha2": float(dist[j].min()),
                           "values": {k: float(v[j]) for k, v in ph.items() if np.ndim(v) and len(v) == len(top)},
                           "largest_z_vs_nearest": _largest_z(X[i, :-1], fr, int(np.argmin(dist[j])), labels)}
                          for j, i in enumerate(top)]
    return rec


def render(allres):
    L = ["# Posterior: defensive adaptive importance sampling (issue 17, branch post10)\n",
         "Generated by `benchmarks/posterior_pmc.py` from `posterior_pmc.json`. One core "
         "(`taskset -c 0`); times cumulative from the first draw (fit, optima, components "
         "and the density's compile apart); load = 1-min average after the iteration.\n"]
    for rec in allres:
        L += run_head(rec, f", seed {rec['seed']}",
                      f", {rec['n_frozen']} frozen components ({rec['components_s']:.1f} s), compile "
                      f"{rec['compile_s']:.1f} s; defensive share {rec['defensive']}, frozen ×{rec['inflate']}, "
                      f"adaptive ×{rec['adapt_inflate']}, {rec['per_iter']} draws per iteration",
                      ["iter", "evals", "wall s", "CPU s", "load", "adaptive comps", "Kish (iter alone)",
                       "Kish all", "max w", "log Z", "tau_c<1 mN m share (Kish, draws)",
                       "k2→0 share (Kish, draws)", "band 95 % [mrad]"])
        for r in rec["iters"]:
            L.append(f"| {r['iter']} | {r['evals']} | {r['wall_s']:.0f} | {r['cpu_s']:.0f} | {r['load']} | "
                     f"{r['n_adapt']} | {r['kish_iter']:.0f} | {r['kish']:.0f} | {r['max_weight']:.3f} | "
                     f"{r['log_z_unnorm']:.2f} | {100 * r['share_tau_c_below_1mNm']:.2f} % "
                     f"({r['kish_tau_c_region']:.0f}, {r['draws_tau_c_region']}) | "
                     f"{100 * r['share_k2_below_0.1_fit']:.2f} % ({r['kish_k2_region']:.0f}, "
                     f"{r['draws_k2_region']}) | [{1e3 * r['band_ci95'][0]:.1f}, {1e3 * r['band_ci95'][1]:.1f}] |")
        r = rec.get("final")
        if r:
            L.append(f"| final plain IS pass | {r['draws']} | {r['wall_s']:.0f} | {r['cpu_s']:.0f} | "
                     f"{r['load_start']} | {r['n_adapt']} | {r['kish']:.0f} | | {r['max_weight']:.3f} | "
                     f"{r['log_z_unnorm']:.2f} | {100 * r['share_tau_c_below_1mNm']:.2f} % "
                     f"({r['kish_tau_c_region']:.0f}, {r['draws_tau_c_region']}) | "
                     f"{100 * r['share_k2_below_0.1_fit']:.2f} % ({r['kish_k2_region']:.0f}, "
                     f"{r['draws_k2_region']}) | [{1e3 * r['band_ci95'][0]:.1f}, {1e3 * r['band_ci95'][1]:.1f}] |")
        last = rec["iters"][-1]
        if "physical_ci95" in last:
            L.append("\n2.5 / 50 / 97.5 % at the last iteration: " + ", ".join(
                f"{k} {v[0]:.3g} / {v[1]:.3g} / {v[2]:.3g}" for k, v in last["physical_ci95"].items()))
    (RESULTS / f"{NAME}.md").write_text("\n".join(L) + "\n")


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", nargs="+", default=["shipped"])
    ap.add_argument("--seed", type=int, nargs="+", default=[1])
    ap.add_argument("--iters", type=int, default=10)
    ap.add_argument("--per-iter", type=int, default=200_000)
    ap.add_argument("--inflate", type=float, default=2.0)
    ap.add_argument("--adapt-inflate", type=float, default=1.2)
    ap.add_argument("--defensive", type=float, default=0.5)
    ap.add_argument("--shrink", type=float, default=20.0)
    ap.add_argument("--final", type=int, default=0,
                    help="draws of a last, non-adaptive IS pass from the final proposal")
    ap.add_argument("--out", default=NAME)
    args = ap.parse_args(argv)
    out_json = RESULTS / f"{args.out}.json"
    allres = json.loads(out_json.read_text()) if out_json.exists() else []
    for which in args.logs:
        for s in args.seed:
            rec = run(which, args, s)
            allres.append(rec)
            out_json.write_text(json.dumps(allres, indent=1, default=float))
            if args.out == NAME:
                render(allres)


if __name__ == "__main__":
    main()
