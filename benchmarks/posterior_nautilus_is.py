"""An independent check of nautilus's weights (issue 17, ``post9``): plain importance
sampling of the same posterior from a defensive t-mixture over the optima and limit
fits, with many draws (the density costs ~0.05 ms per row in chunks of 128).

Run (pinned)::

    PYTHONPATH=src:benchmarks taskset -c 0 python benchmarks/posterior_nautilus_is.py \
        --logs shipped --draws 1000000 --inflate 2.0

Proposal: one multivariate t (ν = 4) per optimum / limit fit of ``sampled_modes`` (seed 1,
as ``posterior_nautilus.py``), centred there with ``inflate``² × its Laplace covariance
(sampled coordinates), weights ½ Laplace + ½ uniform over the components (so the
Coulomb-limit and k2 → 0 components get ≥ 1/(2K) of the draws); log σ_n uniform over its
prior. Self-normalised IS: the k2 → 0 share, tau_c's lower tail, the band's interval, Kish
ESS, and log ∫ p̃ = log mean(p̃/q) (comparable with ``posterior_nautilus``'s
``log_z_unnorm``). The share estimates are trustworthy only where the Kish ESS of the
draws in that region is large: reported per region. Appends to
``results/posterior_nautilus_is.json``.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import argparse
import datetime as _dt
import json
import math
import time

import numpy as np

import hdid
from posterior_nautilus import BAND, RESULTS, Density, _load, make_log


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", nargs="+", default=["shipped"])
    ap.add_argument("--draws", type=int, default=1_000_000)
    ap.add_argument("--inflate", type=float, default=2.0)
    ap.add_argument("--block", type=int, default=65536)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    from scipy.special import logsumexp

    from hdid._posterior.density import derived_np, posterior_density, to_physical
    from hdid._posterior.modes import sampled_modes
    from hdid._posterior.moves import MixtureProposal

    out_json = RESULTS / "posterior_nautilus_is.json"
    allres = json.loads(out_json.read_text()) if out_json.exists() else []
    for which in args.logs:
        fit, prior, truth = make_log(which)
        dens = posterior_density(fit, prior=prior)
        lp = dens.lp
        found = sampled_modes(fit, "auto", 1, dens.u_fit, dens.lin, lp.gauss_prior)
        D = lp.ndim
        q = float(fit.problem.step)
        slo, shi = math.log(lp.sigma_bounds[0] * q), math.log(lp.sigma_bounds[1] * q)
        means = lp.to_sampled_np(np.array([np.concatenate([m.u, [0.0]]) for m in found]))[:, :-1]
        covs = np.array([lp.sampled_cov_np(m.u, m.cov) * args.inflate**2 for m in found])
        lw = np.array([m.weight for m in found])
        wts = 0.5 * lw / lw.sum() + 0.5 / len(found)
        mix = MixtureProposal(means, covs, wts, nu=4.0)
        rng = np.random.default_rng(args.seed)
        f = Density(lp)
        f(np.tile(np.concatenate([means[0], [slo + 1]]), (128, 1)))  # compile
        f.n, f.t = 0, 0.0
        la0, t0, c0 = _load(), time.perf_counter(), time.process_time()
        Xs, lws = [], []
        for i in range(0, args.draws, args.block):
            n = min(args.block, args.draws - i)
            Y = mix.sample(n, rng)
            s = rng.uniform(slo, shi, n)
            X = np.column_stack([Y, s])
            lq = mix.logpdf(Y) - math.log(shi - slo)
            lpx = f(X)
            lws.append(lpx - lq)
            Xs.append(X)
        X, lwt = np.concatenate(Xs), np.concatenate(lws)
        wall, cpu, la1 = time.perf_counter() - t0, time.process_time() - c0, _load()
        ok = np.isfinite(lwt)
        log_z = float(logsumexp(lwt[ok]) - math.log(len(lwt)))
        w = np.zeros(len(lwt))
        w[ok] = np.exp(lwt[ok] - lwt[ok].max())
        w /= w.sum()
        U = lp.from_sampled_np(X)
        phys = to_physical(fit.problem, U)
        k2lo = phys["k2"] < 0.1 * fit.values["k2"]
        tclo = phys["tau_c"] < 1e-3
        idx = rng.choice(len(w), size=4000, p=w)
        band = derived_np(fit.problem, U[idx])[BAND]

        def kish(m):
            v = w[m]
            return float(v.sum() ** 2 / np.sum(v**2)) if v.sum() > 0 else 0.0

        rec = {"log": which, "date_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
               "src": _common.src_fingerprint(), "draws": len(w), "inflate": args.inflate, "seed": args.seed,
               "wall_s": wall, "cpu_s": cpu, "like_s": f.t, "load_start": la0, "load_end": la1,
               "finite_share": float(ok.mean()), "kish": kish(np.ones(len(w), bool)),
               "max_weight": float(w.max()), "log_z_unnorm": log_z,
               "share_k2_below_0.1_fit": float(w[k2lo].sum()), "kish_k2_region": kish(k2lo),
               "draws_k2_region": int(k2lo.sum()),
               "share_tau_c_below_1mNm": float(w[tclo].sum()), "kish_tau_c_region": kish(tclo),
               "draws_tau_c_region": int(tclo.sum()),
               "band_ci95": [float(v) for v in np.quantile(band, [0.025, 0.975])],
               "n_components": len(found)}
        print(json.dumps(rec), flush=True)
        allres.append(rec)
        out_json.write_text(json.dumps(allres, indent=1))


if __name__ == "__main__":
    main()
