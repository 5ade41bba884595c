"""emcee in a normalizing flow's latent space against today's default, side by side
(issue 17, branch ``post5``).

Run (pinned to one core)::

    taskset -c 1 python benchmarks/posterior_flow_latent.py [--logs shipped,9100,9101]
        [--pilot smc] [--max-steps 20000] [--baseline-steps 20000] [--name posterior_flow_latent]

For each log (``shipped``: data/synthetic/csf8_paper.csv; an integer: a paper-design log of
the independent simulator drawn as ``posterior_sbc.py --prior physical`` draws them, that
seed) one fit and one mode search, then in the same process:

- ``default``: ``hdid.sample_posterior(fit, modes=...)`` (emcee from the optima, DE +
  t-mixture independence MH), capped at ``--baseline-steps``;
- ``flow``: a pilot (``smc``: tempered SMC 4 × 300 particles from the optima, the
  library's ``run_smc_np``; ``emcee``: the default's 400-step burn-in), a masked
  autoregressive spline flow fitted to its draws (``_posterior/flow.py``), ``--adapt``
  burn-in stages of emcee in the flow's latent space each followed by a refit of the flow to
  the stage's draws, then the kept chain in the latent space with the last flow, checked
  with the library's criterion (arviz rank R-hat ≤ 1.01, bulk/tail ESS ≥ 400 on every
  sampled quantity and the band, in the original coordinates) at the library's check
  schedule until converged or ``--max-steps``.

Reports τ (pooled about the ensemble mean, original coordinates), R-hat, ESS, acceptance
per move, wall time per stage (compile apart), the 95 % intervals, and the load average.
"""

from __future__ import annotations

import _common  # noqa: F401
import argparse
import datetime as _dt
import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
SHIPPED = ROOT / "data" / "synthetic" / "csf8_paper.csv"
sys.path.insert(0, str(ROOT / "benchmarks"))


def _load():
    return [round(x, 2) for x in os.getloadavg()]


def sbc_fit(seed):
    import hdid
    import posterior_sbc as sbc

    gen = _common.import_generate()
    rng = np.random.default_rng(seed)
    truth, df, info, notes = sbc.draw_physical(gen, rng, gen.PAPER_DESIGN, seed)
    cat = sbc.catalog_prior(gen)
    prior = {n: cat[n] for n in sbc.PHYSICAL_GIVEN}
    fit = hdid.fit(df, inertia=truth["inertia"])
    return fit, prior, (truth, info)


def run_flow(fit, found, dens, seed, pilot, max_steps, adapt, adapt_steps, chunk=500,
             n_particles=1000):
    import emcee

    from hdid._identifiability import unknown_labels
    from hdid._posterior import flow as F
    from hdid._posterior import smc
    from hdid._posterior.diagnostics import convergence, diagnostic_stride, tau_pooled
    from hdid._posterior.density import derived_np
    from hdid._posterior.moves import MixtureProposal, _Counted, _move_name
    from hdid._posterior.result import BAND, _RunNames

    lp = dens.lp
    prob = fit.problem
    D = lp.ndim
    W = max(32, 2 * D)
    labels = unknown_labels(prob, _RunNames(fit)) + ["log_noise_sigma"]
    stage = {}

    def log_prob(X):
        return np.asarray(lp.batch(X))

    t = time.perf_counter()
    q = float(prob.step)
    bounds = dens.bounds
    log_lo = math.log(bounds[0] * q)
    log_rms = math.log(max(fit.rms_residual_rad, bounds[0] * q))
    s_mid = 0.5 * (log_lo + max(log_rms, log_lo + 0.5))
    means = lp.to_sampled_np(np.array([np.concatenate([m.u, [s_mid]]) for m in found]))
    covs = np.zeros((len(found), D, D))
    for k, m in enumerate(found):
        covs[k, :-1, :-1] = lp.sampled_cov_np(m.u, smc.REF_SCALE**2 * m.cov)
        covs[k, -1, -1] = 1.0
    ref = MixtureProposal(means, covs, [max(m.weight, 0.02) for m in found], nu=smc.REF_NU)
    if pilot == "smc":
        X, anc, log_z, steps = smc.run_smc_np(lp, ref, n_particles, 4, seed, smc.N_MCMC,
                                              imh=True, k_min=smc.K_MIN, final_rounds=2)
        P = X.reshape(-1, D)
        stage["pilot_steps"] = len(steps)
    else:
        raise ValueError(pilot)
    stage["pilot_s"] = time.perf_counter() - t
    print(f"  pilot {stage['pilot_s']:.1f} s", flush=True)
    t = time.perf_counter()
    fmap = F.fit_flow(P, seed, kind="coupling", layers=4, width=32)
    stage["flow_fit_s"] = [time.perf_counter() - t]
    print(f"  flow fit {stage['flow_fit_s'][0]:.1f} s", flush=True)
    rng = np.random.default_rng(seed)
    lpz = F.latent_log_prob(log_prob, fmap)
    moves = [(_Counted(m, _move_name(m) if not isinstance(getattr(m, "get_proposal", None), F.LatentT)
                       else "independence (latent t)"), w) for m, w in F.latent_moves(D)]
    t = time.perf_counter()
    pick = P[rng.choice(len(P), W, replace=False)]
    Z0 = fmap.inverse(pick)
    L0 = lpz(Z0)
    stage["compile_s"] = time.perf_counter() - t
    t_burn = time.perf_counter()
    state = None
    adapt_acc = []
    for a in range(adapt):
        sampler = emcee.EnsembleSampler(W, D, lpz, vectorize=True, moves=moves)
        st0 = emcee.State(Z0, log_prob=L0, random_state=np.random.RandomState(seed + a).get_state())
        state = sampler.run_mcmc(st0, adapt_steps, progress=False, skip_initial_state_check=True)
        adapt_acc.append({m.name: m.rate for m, _ in moves})
        print(f"  adapt stage {a}: {adapt_acc[-1]}", flush=True)
        for m, _ in moves:
            m.proposed = m.accepted = 0
        Zs = sampler.get_chain()[adapt_steps // 2:: 10].reshape(-1, D)
        Xs, _ = fmap.forward(Zs)
        Xnow, _ = fmap.forward(state.coords)
        t = time.perf_counter()
        # refit to the pilot and the stage's (thinned) draws: the stage alone has not mixed
        fmap = F.fit_flow(np.concatenate([P, Xs]), seed + 10 + a)
        stage["flow_fit_s"].append(time.perf_counter() - t)
        lpz = F.latent_log_prob(log_prob, fmap)
        Z0 = fmap.inverse(Xnow)
        L0 = lpz(Z0)
    stage["burn_in_s"] = time.perf_counter() - t_burn
    sampler = emcee.EnsembleSampler(W, D, lpz, vectorize=True, moves=moves)
    state = emcee.State(Z0, log_prob=L0, random_state=np.random.RandomState(seed + 99).get_state())

    def xchain():
        Zc = sampler.get_chain()
        S = Zc.shape[0]
        Xc, _ = fmap.forward(Zc.reshape(-1, D))
        return Xc.reshape(S, W, D)

    def conv_of(Xc):
        c = Xc[:: diagnostic_stride(Xc.shape[0])]
        S = c.shape[0]
        U = lp.from_sampled_np(c.reshape(-1, D))
        band = derived_np(prob, U)[BAND].reshape(S, W, 1)
        return convergence(np.concatenate([c, band], axis=2), labels + [BAND])

    done, next_check = 0, chunk
    t_kept = time.perf_counter()
    t_diag = 0.0
    conv = None
    while done < max_steps:
        step = min(max(next_check - done, 1), max_steps - done)
        state = sampler.run_mcmc(state, step, progress=False, skip_initial_state_check=True)
        done += step
        next_check = max(done + chunk, int(1.4 * done))
        td = time.perf_counter()
        conv = conv_of(xchain())
        print(f"  kept {done}: R-hat {np.max(conv.rhat):.3f} ESS {np.min(conv.ess_bulk):.0f} "
              f"{time.perf_counter() - t_kept:.1f} s", flush=True)
        t_diag += time.perf_counter() - td
        if conv.converged:
            break
    stage["kept_chain_s"] = time.perf_counter() - t_kept - t_diag
    stage["diagnostics_s"] = t_diag
    Xc = xchain()
    tau = tau_pooled(Xc)
    with np.errstate(invalid="ignore", divide="ignore"):
        tau_z = sampler.get_autocorr_time(tol=0)
    U = lp.from_sampled_np(Xc[Xc.shape[0] // 2 * 0:].reshape(-1, D))
    return {"steps": done, "converged": bool(conv.converged), "rhat_max": float(np.max(conv.rhat)),
            "ess_bulk_min": float(np.min(conv.ess_bulk)), "ess_tail_min": float(np.min(conv.ess_tail)),
            "worst": list(map(str, conv.worst)), "tau_max": float(np.nanmax(tau)),
            "tau_latent_max": float(np.nanmax(tau_z)),
            "tau": dict(zip(labels, map(float, tau))),
            "move_acceptance": {m.name: m.rate for m, _ in moves}, "adapt_acceptance": adapt_acc,
            "acceptance_mean": float(np.mean(sampler.acceptance_fraction)),
            "stage_s": stage, "U": U}


class FlowIndependence:
    """Exact independence MH proposal in the sampled coordinates from a flow (latent t,
    ``nu`` = 8): ``x = T(z)``, ``log q(x) = log t(z) − log|det ∂x/∂z|``."""

    def __init__(self, fmap, D):
        from hdid._posterior import flow as F

        self.fmap, self.t = fmap, F.LatentT(D)

    def logq(self, X):
        Z = self.fmap.inverse(X)
        _, ld = self.fmap.forward(Z)
        return self.t.logpdf(Z) - ld

    def __call__(self, coords, random):
        Z, _ = self.t(coords, random)
        X, ld = self.fmap.forward(Z)
        lq_new = self.t.logpdf(Z) - ld
        return X, self.logq(coords) - lq_new


def flow_mh_factory(fit, found, dens, seed, n_particles, info):
    """Moves for ``sample_posterior(moves=...)``: the default DE moves plus an independence
    move from a flow fitted to an SMC pilot (instead of the t-mixture)."""
    import emcee

    from hdid._posterior import flow as F
    from hdid._posterior import smc
    from hdid._posterior.moves import MixtureProposal

    def make(lp, proposal):
        D = lp.ndim
        q = float(fit.problem.step)
        log_lo = math.log(dens.bounds[0] * q)
        log_rms = math.log(max(fit.rms_residual_rad, dens.bounds[0] * q))
        s_mid = 0.5 * (log_lo + max(log_rms, log_lo + 0.5))
        means = lp.to_sampled_np(np.array([np.concatenate([m.u, [s_mid]]) for m in found]))
        covs = np.zeros((len(found), D, D))
        for k, m in enumerate(found):
            covs[k, :-1, :-1] = lp.sampled_cov_np(m.u, smc.REF_SCALE**2 * m.cov)
            covs[k, -1, -1] = 1.0
        ref = MixtureProposal(means, covs, [max(m.weight, 0.02) for m in found], nu=smc.REF_NU)
        t = time.perf_counter()
        X, *_ = smc.run_smc_np(lp, ref, n_particles, 4, seed, smc.N_MCMC, imh=True,
                               k_min=smc.K_MIN, final_rounds=2)
        info["pilot_s"] = time.perf_counter() - t
        t = time.perf_counter()
        fmap = F.fit_flow(X.reshape(-1, D), seed, kind="coupling", layers=4, width=32)
        info["flow_fit_s"] = time.perf_counter() - t
        return [
            (emcee.moves.DEMove(), 0.4),
            (emcee.moves.DEMove(gamma0=1.0), 0.05),
            (emcee.moves.DESnookerMove(), 0.2),
            (emcee.moves.MHMove(FlowIndependence(fmap, D)), 0.35),
        ]

    return make


def intervals(fit, U, prob):
    from hdid._posterior.density import derived_np, to_physical

    phys = to_physical(prob, U)
    der = derived_np(prob, U)
    out = {}
    for n in ("k1", "k2", "tau_c", "tau_s", "c_v", "v_s", "delta"):
        if n in phys:
            out[n] = [float(np.percentile(phys[n], p)) for p in (2.5, 50, 97.5)]
    out["band"] = [float(np.percentile(der["stick_band_halfwidth_rad"], p)) for p in (2.5, 50, 97.5)]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument("--logs", default="shipped")
    ap.add_argument("--pilot", default="smc")
    ap.add_argument("--max-steps", type=int, default=20000)
    ap.add_argument("--baseline-steps", type=int, default=20000)
    ap.add_argument("--adapt", type=int, default=1)
    ap.add_argument("--adapt-steps", type=int, default=1000)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--skip-baseline", action="store_true")
    ap.add_argument("--skip-flow", action="store_true")
    ap.add_argument("--flow-mh", action="store_true",
                    help="also: the default sampler with the flow as its independence move")
    ap.add_argument("--name", default="posterior_flow_latent")
    a = ap.parse_args(argv)
    import hdid
    from hdid._posterior.density import posterior_density
    from hdid._posterior.modes import sampled_modes

    rows = []
    out = RESULTS / f"{a.name}.json"
    for name in a.logs.split(","):
        t0 = time.perf_counter()
        if name == "shipped":
            fit, prior, truth = hdid.fit(str(SHIPPED)), None, None
        else:
            fit, prior, truth = sbc_fit(int(name))
        fit_s = time.perf_counter() - t0
        print(name, f"fit {fit_s:.1f} s", _load(), flush=True)
        dens = posterior_density(fit, prior=prior)
        t = time.perf_counter()
        found = sampled_modes(fit, "auto", a.seed, dens.u_fit, dens.lin, dens.lp.gauss_prior)
        modes_s = time.perf_counter() - t
        row = {"log": name, "fit_s": fit_s, "modes_s": modes_s, "n_modes": len(found)}
        if truth is not None:
            tr, info = truth
            row["truth"] = {**{k: float(v) for k, v in tr.items() if isinstance(v, (int, float))},
                            "band": float(info["stick_band_halfwidth"])}
        if a.flow_mh:
            info = {}
            la = _load()
            t = time.perf_counter()
            post = hdid.sample_posterior(fit, modes=found, seed=a.seed, prior=prior,
                                         max_steps=a.baseline_steps,
                                         moves=flow_mh_factory(fit, found, dens, a.seed, 1000, info))
            d = post.to_dict()["posterior_diagnostics"]
            row["flow_mh"] = {"wall_s": time.perf_counter() - t, "load_start": la, "load_end": _load(),
                              "steps": int(post.chain.shape[0]), "converged": bool(post.converged),
                              "rhat_max": d["convergence"]["rhat_max"],
                              "ess_bulk_min": d["convergence"]["ess_bulk_min"],
                              "ess_tail_min": d["convergence"]["ess_tail_min"],
                              "tau_max": d["tau_max"], "move_acceptance": d["move_acceptance"],
                              "stage_s": post.stage_s, **info,
                              "intervals": intervals(fit, post.draws, fit.problem)}
            print(name, "flow_mh", {k: row["flow_mh"][k] for k in ("steps", "converged", "rhat_max",
                                                                    "ess_bulk_min", "tau_max", "wall_s")},
                  row["flow_mh"]["move_acceptance"], info, flush=True)
        la = _load()
        t = time.perf_counter()
        r = None if a.skip_flow else run_flow(fit, found, dens, a.seed, a.pilot, a.max_steps, a.adapt, a.adapt_steps)
        if r is not None:
            U = r.pop("U")
            r.update(wall_s=time.perf_counter() - t, load_start=la, load_end=_load(),
                     intervals=intervals(fit, U, fit.problem))
            row["flow"] = r
            print(name, "flow", {k: r[k] for k in ("steps", "converged", "rhat_max", "ess_bulk_min",
                                                   "tau_max", "tau_latent_max", "wall_s")},
                  r["stage_s"], r["move_acceptance"], flush=True)
        if not a.skip_baseline:
            la = _load()
            t = time.perf_counter()
            post = hdid.sample_posterior(fit, modes=found, seed=a.seed, prior=prior,
                                         max_steps=a.baseline_steps)
            d = post.to_dict()["posterior_diagnostics"]
            row["default"] = {"wall_s": time.perf_counter() - t, "load_start": la, "load_end": _load(),
                              "steps": int(post.chain.shape[0]), "converged": bool(post.converged),
                              "rhat_max": d["convergence"]["rhat_max"],
                              "ess_bulk_min": d["convergence"]["ess_bulk_min"],
                              "ess_tail_min": d["convergence"]["ess_tail_min"],
                              "tau_max": d["tau_max"], "move_acceptance": d["move_acceptance"],
                              "stage_s": post.stage_s,
                              "intervals": intervals(fit, post.draws, fit.problem)}
            print(name, "default", {k: row["default"][k] for k in ("steps", "converged", "rhat_max",
                                                                    "ess_bulk_min", "tau_max", "wall_s")},
                  flush=True)
        rows.append(row)
        out.write_text(json.dumps({"generated": _dt.datetime.now(_dt.timezone.utc).isoformat(),
                                   "args": vars(a), "fingerprint": _common.src_fingerprint(),
                                   "rows": rows}, indent=1, default=float))


if __name__ == "__main__":
    main()
