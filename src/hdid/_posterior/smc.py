"""Tempered sequential Monte Carlo from the optima's Laplace mixture to the posterior.

Path: ``π_β ∝ q^{1−β} p^β``, ``β`` from 0 to 1, where ``p`` is the log-posterior of
:mod:`.density` and ``q`` a normalised Student-t mixture with one component per optimum that
:func:`~hdid._posterior.modes.find_modes` finds (Laplace mean and covariance, widened by
``REF_SCALE``). Particles start as exact draws from ``q``; each step picks the next ``β``
so that the incremental weights keep an ESS of ``TARGET_ESS`` × N (as blackjax's
``adaptive_tempered_smc``), resamples (systematic) and moves every particle ``n_mcmc`` times
at the current ``β``, alternating two Metropolis–Hastings kernels: an independence proposal
from a t-mixture refitted to the run's own particles (``K_MIN`` components at least,
k-means start; exact for any mixture, and an accepted move replaces a resampled clone by a
fresh draw) and a random walk with the covariance of the particle's own component. Because
``q`` is normalised, the sum of the steps' log mean incremental weights estimates
``log ∫ p`` — the evidence under the sampler's prior (up to the flat boxes' constant, the
same for every model with the same free parameters).

Convergence (the honest SMC analogue of the chain criterion): ``n_runs`` independent runs;
their final particles, each run's sorted by ancestor (clones of one ancestor side by side,
so that arviz's autocorrelation sees them), are taken as chains: every sampled quantity and
the band must have rank-normalised R-hat ≤ 1.01 between runs and bulk and tail ESS ≥ 400.
At β = 1 the particles are moved in rounds and tested after each; the verdict is
"converged" once two consecutive rounds pass (``MAX_FINAL`` rounds at most).
"""

from __future__ import annotations

import math
import sys
import time

import jax.numpy as jnp
import numpy as np

#: Adaptive tempering keeps this fraction of the particles' ESS at every step.
TARGET_ESS = 0.5
#: Width of the reference mixture's components in units of the Laplace widths.
REF_SCALE = 1.5
#: Degrees of freedom of the reference t components (heavier tails than the posterior).
REF_NU = 5.0


def _kmeans_mixture(X, k, rng, nu, iters=10):
    """A ``k``-component t-mixture from k-means (++ seeding) in coordinates whitened by the
    particles' own covariance; each cluster's covariance shrunk towards the whole cloud's
    (``D`` pseudo-draws) so that a small cluster still gets a proper one."""
    from .moves import MixtureProposal

    n, D = X.shape
    S = np.cov(X.T) + 1e-12 * np.eye(D)
    L = np.linalg.cholesky(S + 1e-10 * np.trace(S) / D * np.eye(D))
    Z = np.linalg.solve(L, (X - X.mean(axis=0)).T).T
    c = [Z[rng.integers(n)]]
    for _ in range(1, k):
        d2 = np.min(((Z[:, None, :] - np.array(c)[None]) ** 2).sum(-1), axis=1)
        c.append(Z[rng.choice(n, p=d2 / d2.sum())] if d2.sum() > 0 else Z[rng.integers(n)])
    C = np.array(c)
    for _ in range(iters):
        lab = np.argmin(((Z[:, None, :] - C[None]) ** 2).sum(-1), axis=1)
        C = np.array([Z[lab == j].mean(axis=0) if np.any(lab == j) else C[j] for j in range(k)])
    lab = np.argmin(((Z[:, None, :] - C[None]) ** 2).sum(-1), axis=1)
    means, covs, w = [], [], []
    for j in range(k):
        m = lab == j
        if m.sum() < 2:
            continue
        Y = X[m]
        cj = np.cov(Y.T) if m.sum() > 1 else S
        covs.append((m.sum() * cj + D * S) / (m.sum() + D))
        means.append(Y.mean(axis=0))
        w.append(m.sum())
    return MixtureProposal(np.array(means), np.array(covs), np.array(w, dtype=float), nu=nu)


def _proposal_mixture(X, mix, rng, k_min):
    """The run's mixture refitted to its particles ``X``: EM from the previous one, which has
    one component per optimum at first; when it has fewer than ``k_min``, started afresh
    from k-means with ``k_min`` (a curved ridge needs several Gaussian pieces)."""
    if len(mix.weights) < k_min and len(X) >= 20 * k_min:
        mix = _kmeans_mixture(X, k_min, rng, mix.nu)
    return mix.refit(X)


def _rw_chols(X, mix, scale):
    """Per-particle random-walk Cholesky factors: the covariance of the particle's own
    cluster (the component of ``mix`` it belongs to), times ``scale``."""
    comp = np.argmax(mix.component_logpdf(X), axis=1)
    D = X.shape[1]
    chols = np.empty((len(mix.weights), D, D))
    for k, c in enumerate(mix.covs):
        c = 0.5 * (c + c.T)
        chols[k] = np.linalg.cholesky(c + 1e-10 * np.trace(c) / D * np.eye(D))
    return scale * chols[comp]


def _systematic(rng, w, n):
    u = (rng.random() + np.arange(n)) / n
    return np.minimum(np.searchsorted(np.cumsum(w), u), len(w) - 1)


def _next_delta(ll, beta, n_target):
    """Largest ``Δβ ≤ 1 − β`` whose incremental weights ``exp(Δβ·ll)`` keep an ESS of
    ``n_target`` (bisection; equal weights before the step, as after resampling)."""
    ok = np.isfinite(ll)
    if not ok.any():
        return 1.0 - beta

    def ess(d):
        a = np.where(ok, d * np.where(ok, ll, 0.0), -np.inf)
        a = np.exp(a - a.max())
        return a.sum() ** 2 / np.sum(a * a)

    hi = 1.0 - beta
    if ess(hi) >= n_target:
        return hi
    lo = 0.0
    for _ in range(60):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if ess(mid) >= n_target else (lo, mid)
    return max(lo, 1e-12)


def run_smc_np(lp, ref, n_particles: int, n_runs: int, seed: int, n_mcmc: int = 10,
               max_steps: int = 100, progress=None, final_rounds: int = 1, imh: bool = True,
               k_min: int = 1, check=None, max_final: int | None = None,
               target_ess: float = TARGET_ESS):
    """``n_runs`` independent adaptive tempered SMC runs moved together (their particles in
    one batched log-posterior call). Returns ``(X, ancestors, log_z, steps)``: final
    particles ``(R, N, D)`` (sampled coordinates, equal weights: resampled and moved at
    ``β = 1``), each one's ancestor at the last resampling ``(R, N)``, the log-evidence
    estimate of each run ``(R,)`` and per-step diagnostics.

    Moves at each step (``n_mcmc`` in all, each one batched log-posterior call):
    with ``imh`` they alternate between an independence Metropolis–Hastings proposal from
    the run's mixture refitted to its particles (``k_min`` components at least: exact for
    any mixture, and it decorrelates resampled clones in one accepted step) and a random
    walk with the particle's cluster covariance; without, random walk only.

    Once every run is at ``β = 1`` the particles are moved ``final_rounds`` more rounds
    (no resampling: the weights are equal); given ``check(X, anc) -> bool``, rounds go on
    after that until ``check`` passes at two consecutive rounds (one pass can be a
    fluctuation) or ``max_final`` rounds; ``max_steps`` steps in all at most."""
    rng = np.random.default_rng(seed)
    R, N = n_runs, n_particles
    D = ref.ndim

    def logp(X):
        v = np.asarray(lp.batch(X.reshape(-1, D)), dtype=float).reshape(X.shape[:-1])
        return np.where(np.isfinite(v), v, -np.inf)

    def logq(X):
        return ref.logpdf(X.reshape(-1, D)).reshape(X.shape[:-1])

    X = ref.sample(R * N, rng).reshape(R, N, D)
    LP, LQ = logp(X), logq(X)
    beta = np.zeros(R)
    log_z = np.zeros(R)
    anc = np.tile(np.arange(N), (R, 1))
    scale = np.full(R, 2.38 / math.sqrt(D))
    mixes = [ref] * R
    steps = []
    rounds_at_one = 0
    passes = 0
    max_final = final_rounds if max_final is None or check is None else max(max_final, final_rounds)
    for it in range(max_steps):
        t_step = time.perf_counter()
        final = beta >= 1.0
        # reweight to the next temperature, then resample
        for r in range(R):
            if final[r]:
                continue
            ll = LP[r] - LQ[r]
            d = _next_delta(ll, beta[r], target_ess * N)
            a = np.where(np.isfinite(ll), d * np.where(np.isfinite(ll), ll, 0.0), -np.inf)
            m = a.max()
            log_z[r] += m + math.log(np.mean(np.exp(a - m)))
            w = np.exp(a - m)
            beta[r] = min(1.0, beta[r] + d) if beta[r] + d < 1.0 - 1e-12 else 1.0
            # systematic resampling, then a random order: the particles' position carries
            # no genealogy, so that sorting by the last ancestor groups clones and only them
            idx = _systematic(rng, w / w.sum(), N)[rng.permutation(N)]
            X[r], LP[r], LQ[r], anc[r] = X[r, idx], LP[r, idx], LQ[r, idx], idx
        # move at the new β: the run's mixture refitted to its particles (its own only: the
        # runs stay independent, which is what their agreement tests)
        chols = np.empty((R, N, D, D))
        for r in range(R):
            mixes[r] = _proposal_mixture(X[r], mixes[r], rng, k_min)
            chols[r] = _rw_chols(X[r], mixes[r], 1.0)
        b = beta[:, None]
        acc = np.zeros(R)
        acc_imh = np.zeros(R)
        n_rw = n_imh = 0
        for j in range(n_mcmc):
            if imh and j % 2 == 0:
                Y = np.stack([mixes[r].sample(N, rng) for r in range(R)])
                lg = np.stack([mixes[r].logpdf(np.concatenate([X[r], Y[r]])) for r in range(R)])
                hast = lg[:, :N] - lg[:, N:]
            else:
                Z = rng.standard_normal((R, N, D))
                Y = X + scale[:, None, None] * np.einsum("rnij,rnj->rni", chols, Z)
                hast = 0.0
            LPy, LQy = logp(Y), logq(Y)
            with np.errstate(invalid="ignore"):
                la = (b * LPy + (1 - b) * LQy) - (b * LP + (1 - b) * LQ) + hast
            take = np.log(rng.random((R, N))) < np.where(np.isfinite(la), la, -np.inf)
            X = np.where(take[..., None], Y, X)
            LP, LQ = np.where(take, LPy, LP), np.where(take, LQy, LQ)
            if imh and j % 2 == 0:
                acc_imh += take.mean(axis=1)
                n_imh += 1
            else:
                acc += take.mean(axis=1)
                n_rw += 1
        if n_rw:
            acc /= n_rw
            scale *= np.clip(np.exp(2.0 * (acc - 0.25)), 0.5, 2.0)
        st = {"beta": beta.tolist(), "acceptance": acc.tolist(),
              "wall_s": time.perf_counter() - t_step}
        if n_imh:
            st["acceptance_imh"] = (acc_imh / n_imh).tolist()
        steps.append(st)
        if progress is not None:
            progress(it, st)
        if np.all(final):
            rounds_at_one += 1
            if check is not None and rounds_at_one >= final_rounds:
                ok = bool(check(X, anc))
                st["check"] = ok
                passes = passes + 1 if ok else 0
                if passes >= 2:
                    break
            elif check is None and rounds_at_one >= final_rounds:
                break
            if rounds_at_one >= max_final:
                break
    return X, anc, log_z, steps


def converge_smc(runs, lp, prob, labels):
    """arviz R-hat / ESS of independent SMC runs as chains (particles sorted by ancestor)."""
    from .diagnostics import convergence
    from .density import derived_np

    chains = []
    for X, anc in runs:
        order = np.argsort(anc, kind="stable")
        chains.append(X[order])
    n = min(len(c) for c in chains)
    C = np.stack([c[:n] for c in chains], axis=1)  # (N, runs, D) sampled coordinates
    S, R, D = C.shape
    U = lp.from_sampled_np(C.reshape(-1, D))
    band = derived_np(prob, U)["stick_band_halfwidth_rad"].reshape(S, R, 1)
    return convergence(np.concatenate([C, band], axis=2), labels + ["stick_band_halfwidth_rad"]), C




def _failed(conv):
    """``conv`` marked as failing (tempering not finished: R-hat set to infinity)."""
    from .diagnostics import Convergence

    return Convergence(list(conv.names), np.full(len(conv.names), np.inf), conv.ess_bulk,
                       conv.ess_tail)


def _setup(fit, seed, sigma_floor=None, modes="auto", prior=None, default_prior="weak"):
    """Log-posterior, optima and reference mixture, as :func:`sample_posterior` builds them."""
    from .density import posterior_density
    from .modes import found_limits, sampled_modes
    from .moves import MixtureProposal

    prob = fit.problem
    warnings = []
    dens = posterior_density(fit, sigma_floor, prior=prior, default_prior=default_prior)
    lp, temper, rho1, lin, bounds, u_fit = (dens.lp, dens.temper, dens.rho1, dens.lin,
                                            dens.bounds, dens.u_fit)
    warnings += dens.warnings
    t = time.perf_counter()
    found = sampled_modes(fit, modes, seed, u_fit, lin, lp.gauss_prior)
    limits = found_limits(fit, found, modes, lin, lp.gauss_prior, seed)
    warnings += [m.note for m in found if m.note]
    t_modes = time.perf_counter() - t
    q = float(prob.step)
    log_lo = math.log(bounds[0] * q)
    log_rms = math.log(max(fit.rms_residual_rad, bounds[0] * q))
    s_mid, s_sd = 0.5 * (log_lo + max(log_rms, log_lo + 0.5)), 1.0
    D = lp.ndim
    means = lp.to_sampled_np(np.array([np.concatenate([m.u, [s_mid]]) for m in found]))
    covs = np.zeros((len(found), D, D))
    for k, m in enumerate(found):
        covs[k, :-1, :-1] = lp.sampled_cov_np(m.u, REF_SCALE**2 * m.cov)
        covs[k, -1, -1] = s_sd**2
    weights = [max(m.weight, 0.02) for m in found]
    ref = MixtureProposal(means, covs, weights, nu=REF_NU)
    return lp, found, ref, warnings, temper, rho1, lin, t_modes, limits


#: Particles per run and independent runs (the runs are the "chains" of the convergence test).
#: 300 (with the independence moves) converged on the shipped paper log with ESS ≥ 900
#: (docs/decisions/posterior-moves.md); 500 without them did not (R-hat 1.011).
N_PARTICLES = 300
N_RUNS = 4
#: Moves per tempering step (and per round at β = 1), alternating independence MH from the
#: run's refitted mixture and a random walk (``IMH``).
N_MCMC = 6
#: Independence Metropolis–Hastings moves from the run's mixture (half of the moves): each
#: accepted one replaces a resampled clone by a fresh draw (accepted 20–40 % on the shipped
#: log, where random-walk moves alone left the runs disagreeing).
IMH = True
#: Components of that mixture at least (k-means start when the optima give fewer): the
#: curved Stribeck ridge needs several Gaussian pieces.
K_MIN = 4
#: Steps in all at most (tempering, then the rounds at β = 1).
MAX_ROUNDS = 40
#: Rounds of moves at β = 1 after the tempering before the first convergence test.
FINAL_ROUNDS = 1
#: Rounds at β = 1 at most: the test is repeated after each round from ``FINAL_ROUNDS`` on
#: and passes when it holds at two consecutive rounds (one pass can be a fluctuation;
#: ``MAX_FINAL = FINAL_ROUNDS``: one test after a fixed protocol).
MAX_FINAL = 10


def sample_smc(fit, *, n_particles: int = N_PARTICLES, n_runs: int = N_RUNS,
               n_mcmc: int | None = None, max_rounds: int = MAX_ROUNDS, seed: int = 0,
               progress: bool = False, sigma_floor: float | None = None, modes="auto",
               final_rounds: int | None = None, imh: bool | None = None,
               k_min: int | None = None, max_final: int | None = None, prior=None,
               target_ess: float = TARGET_ESS, default_prior: str = "weak"):
    """Tempered SMC posterior of ``fit`` (see the module docstring); a
    :class:`PosteriorResult` whose ``chain`` is ``(n_particles, n_runs, D)``."""
    from .._fitting._identifiability import unknown_labels
    from .density import PRIOR_HALF_WIDTH, physical_draws, to_physical
    from .diagnostics import width_ratios
    from .limits import assess_limits, limit_shares
    from .diagnostics import mode_shares
    from .result import BAND, _RunNames
    from .result import PosteriorResult

    n_mcmc = N_MCMC if n_mcmc is None else n_mcmc
    final_rounds = FINAL_ROUNDS if final_rounds is None else final_rounds
    imh = IMH if imh is None else imh
    k_min = K_MIN if k_min is None else k_min
    max_final = MAX_FINAL if max_final is None else max_final
    t0 = time.perf_counter()
    prob = fit.problem
    lp, found, ref, warnings, temper, rho1, lin, t_modes, limits = _setup(
        fit, seed, sigma_floor, modes, prior, default_prior)
    D = lp.ndim
    labels = unknown_labels(prob, _RunNames(fit)) + ["log_noise_sigma"]
    t_c = time.perf_counter()
    lp.batch(np.tile(ref.means[0], (n_runs * n_particles, 1)))  # compile (or cache read)
    t_compile = time.perf_counter() - t_c

    def show(i, st):
        print(f"SMC step {i}: beta {min(st['beta']):.3f}, acceptance "
              f"{np.mean(st['acceptance']):.2f}, {st['wall_s']:.1f} s", file=sys.stderr)

    t_s = time.perf_counter()
    t_check = [0.0]
    last = {}

    def check(X, anc):
        td = time.perf_counter()
        last["conv"] = converge_smc(list(zip(X, anc)), lp, prob, labels)
        t_check[0] += time.perf_counter() - td
        return last["conv"][0].converged

    X, anc, log_z, steps = run_smc_np(lp, ref, n_particles, n_runs, seed, n_mcmc,
                                      max_steps=max_rounds, final_rounds=final_rounds,
                                      progress=show if progress else None, imh=imh,
                                      k_min=k_min, check=check if max_final > final_rounds else None,
                                      max_final=max_final, target_ess=target_ess)
    t_s = time.perf_counter() - t_s - t_check[0]
    td = time.perf_counter()
    if "check" in steps[-1]:  # the last round was tested: its particles are X
        conv, C = last["conv"]
    else:
        conv, C = converge_smc(list(zip(X, anc)), lp, prob, labels)
    t_diag = time.perf_counter() - td + t_check[0]
    n_temps = sum(1 for st in steps if min(st["beta"]) < 1.0) + 1
    reached = min(steps[-1]["beta"]) >= 1.0
    if not reached:
        warnings.append(
            f"NOT CONVERGED: the tempering stopped at beta = {min(steps[-1]['beta']):.3g} < 1 "
            f"after {len(steps)} steps (max_rounds): the particles are not posterior draws. "
            "Raise max_rounds")
    elif not conv.converged:
        name, what = conv.worst
        warnings.append(
            f"NOT CONVERGED: {n_runs} SMC runs of {n_particles} particles, {len(steps)} steps "
            f"({n_temps} temperatures, then {len(steps) - n_temps} rounds of {n_mcmc} moves at beta = 1); the worst "
            f"quantity is {name} ({what}); the criterion is R-hat <= 1.01 between runs and "
            "bulk/tail ESS >= 400 (particles sorted by ancestor) on every sampled quantity "
            f"and the band. Raise n_particles (--particles) to {2 * n_particles}: the runs disagree by more than their particles' spread")
    sd_z = float(np.std(log_z, ddof=1)) if n_runs > 1 else float("nan")
    if n_runs > 1 and sd_z > 1.0:
        warnings.append(
            f"the runs' log-evidence estimates disagree (sd {sd_z:.2f} > 1): a mode may be "
            "found by some runs only; raise n_particles (--particles)")
    U = lp.from_sampled_np(C.reshape(-1, D))
    chain = U.reshape(C.shape)
    phys = to_physical(prob, U)
    phys, der = physical_draws(prob, fit.model, phys, U)
    share, multi = mode_shares(found, ref, C.reshape(-1, D), "particles",
                               "SMC weighs them by their posterior mass — see `modes`")
    if multi:
        warnings.append(multi)
    q = float(prob.step)
    log_lo = math.log(lp.sigma_bounds[0] * q)
    warnings += assess_limits(
        limits, lp, lin, [m.u for m in found if m.kind == "optimum"] or [np.asarray(fit.u)],
        lambda X: np.asarray(lp.batch(X)), (log_lo, math.log(max(fit.rms_residual_rad, q * lp.sigma_bounds[0]))),
        phys, fit.values, limit_shares(found, share))
    acc = np.array([np.mean(st["acceptance"]) for st in steps])
    widths = width_ratios(prob, U, np.asarray(fit.u, dtype=float), PRIOR_HALF_WIDTH, lin,
                          lp.gauss_prior)
    res = PosteriorResult(
        samples=phys, derived=der, chain=chain, labels=labels,
        tau=np.ones(D), acceptance=acc, burn=0, thin=1, warnings=warnings, seed=seed,
        wall_time_s=time.perf_counter() - t0, temper=temper, residual_rho1=rho1, fit=fit,
        draws=U, burn_in=0, modes=found, mode_share=share, mode_search_s=t_modes,
        move_acceptance={"random_walk": float(np.mean(acc))}, n_components=len(found),
        convergence=conv if reached else _failed(conv), widths=widths, compile_s=t_compile,
        limits=[lim.to_dict() for lim in limits],
        stage_s={"mode_search": t_modes, "compile": t_compile, "smc": t_s,
                 "diagnostics": t_diag},
        method="smc",
        smc={"n_particles": n_particles, "n_runs": n_runs, "n_mcmc": n_mcmc,
             "steps": len(steps), "temperatures": n_temps,
             "log_evidence": [float(z) for z in log_z], "log_evidence_sd": sd_z,
             "imh": imh, "k_min": k_min, "rounds_at_one": len(steps) - n_temps,
             "step_wall_s": [st["wall_s"] for st in steps],
             "acceptance_imh": [float(np.mean(st["acceptance_imh"])) for st in steps
                                if "acceptance_imh" in st],
             "betas": [st["beta"] for st in steps]},
    )
    _ = BAND
    return res
