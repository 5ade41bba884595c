"""The emcee ensemble of :func:`~hdid._posterior.driver.sample_posterior`: start, staged burn-in,
growth until converged (arviz), the chain's warnings and the result."""

from __future__ import annotations

import math
import time

import numpy as np

from .._fitting._identifiability import unknown_labels
from .density import (
    PRIOR_HALF_WIDTH,
    derived_np,
    physical_draws,
    posterior_density,
    to_physical,
)
from .diagnostics import (
    ESS_MIN,
    RHAT_MAX,
    TAU_MULTIPLE,
    convergence,
    tau_outlasts_chain,
    diagnostic_stride,
    mode_shares,
    tau_pooled,
    width_ratios,
)
from .limits import assess_limits, limit_proposal_weights, limit_shares
from .modes import RIDGE_SAMPLERS, found_limits, sampled_modes
from .moves import (
    START_SCALE,
    MixtureProposal,
    _Adaptive,
    _Counted,
    _mode_start,
    _move_name,
    _reset_outliers,
    default_moves,
)
from .errors import PosteriorError, walkers_enough
from .result import BAND, PosteriorResult, _RunNames

#: The burn-in is run in this many stages, the proposal adapted after each. The DE step may
#: grow ×1.5 a stage (:func:`_tune`): with 4 stages (×5 at most) SBC paper logs 36008 and
#: 36003 kept DE acceptance at 0.52 / 0.48 in the kept chain (walkers packed along the
#: Coulomb–viscous ridge), τ of tau_c/c_v 25 600 / 3 700, not converged in 40 000 steps; with
#: 8 stages of 1000 steps: acceptance 0.27 / 0.35, τ 3 400 / 477, 36003 converged at 26 550
#: steps (docs/decisions/emcee-calibration-logs.md).
BURN_IN_STAGES = 8
#: Default burn-in [steps] of a chain grown until it converges. The walkers start at the
#: optima's Laplace width, narrower than the posterior along the Stribeck ridge: after 400
#: steps the shipped paper log's ensemble spread in v_s and delta was 0.63-0.65 of the kept
#: chain's, and the kept chain spent its first thousands of steps widening (τ of tau_c
#: 843-1076 on 10 000 steps after 400; 321-363 on 6 400-8 400 after 2 000-4 000; R-hat
#: lower on all 4 pairs; 30 000 kept steps: τ 636 after 4 000, 680 after 8 000):
#: docs/decisions/emcee-burn-in.md. 8000 since the stages doubled (:data:`BURN_IN_STAGES`),
#: each stage as long as before: ≈ +10 s of CPU on a paper log.
BURN_IN = 8000
#: Burn-in of a chain of fixed length (``n_steps``, a quick look): ``n_steps`` itself
#: between this and :data:`BURN_IN`.
SHORT_BURN_IN = 400
#: The ensemble rule's τ multiple (:data:`~hdid._posterior.diagnostics.TAU_MULTIPLE`).
MIN_TAU_MULTIPLE = TAU_MULTIPLE
#: A chain this far (log p) above the least-squares optimum has found another mode
#: (Δχ² = 10 in the fit's units: beyond the 99.8 % point of χ²₁).
MODE_GAP = 5.0
#: The convergence check runs after ``chunk`` steps, then each time the chain has grown by
#: this factor (at least ``chunk`` more steps): at most ~10 checks up to 20 000 steps.
CHECK_GROWTH = 1.4


def default_burn_in(n_steps: int | None) -> int:
    """:data:`BURN_IN` for a chain grown until converged; ``n_steps`` clipped to
    [:data:`SHORT_BURN_IN`, :data:`BURN_IN`] for a chain of fixed length."""
    return BURN_IN if n_steps is None else min(BURN_IN, max(SHORT_BURN_IN, int(n_steps)))


def _no_start(fit):
    return PosteriorError(
        f"{fit.source}: could not place the posterior's walkers where the density is "
        "positive — every start around the least-squares optimum has zero posterior "
        "density, so the fit itself is likely bad: read its warnings, refit (other starts: "
        "--start / start_from_model=True; fixed parameters: --fix / fix=) or check the log "
        "(--resolution / resolution= if its encoder step is not the readings')"
    )


class _Ensemble:
    """One emcee run of :func:`sample_posterior`, in the order a reader follows it:
    :meth:`start` (density, optima, walkers, proposal, moves), :meth:`burn_in`,
    :meth:`grow` (the kept chain until converged) and :meth:`result` (warnings, draws)."""

    @classmethod
    def start(cls, fit, n_walkers, seed, sigma_floor, linear_prior, sample_linear, prior,
              default_prior, modes, moves):
        """The log-posterior, the optima it starts from (and the limit fits), the walkers
        spread over the optima's Laplace approximations, the independence proposal (one t
        component per optimum) and the moves."""
        import emcee

        self = cls()
        self.fit = fit
        self.prob = prob = fit.problem
        self.warnings = []
        dens = posterior_density(fit, sigma_floor, linear_prior, sample_linear, prior,
                                 default_prior)
        self.lp, self.temper, self.rho1, self.lin, bounds, self.u_fit = (
            dens.lp, dens.temper, dens.rho1, dens.lin, dens.bounds, dens.u_fit)
        lp = self.lp
        self.warnings += dens.warnings
        self.D = D = lp.ndim
        W = n_walkers or max(32, 2 * D)
        walkers_enough(W, D)
        self.rng = np.random.default_rng(seed)
        q = float(prob.step)
        t_modes = time.perf_counter()
        self.found = found = sampled_modes(fit, modes, seed, self.u_fit, self.lin, lp.gauss_prior,
                                                 ridges="emcee" in RIDGE_SAMPLERS)
        self.limits = found_limits(fit, found, modes, self.lin, lp.gauss_prior, seed)
        self.warnings += [m.note for m in found if m.note]
        self.t_modes = time.perf_counter() - t_modes
        self.log_lo = log_lo = math.log(bounds[0] * q)
        self.log_rms = log_rms = math.log(max(fit.rms_residual_rad, bounds[0] * q))
        # compile the log-posterior for the two shapes emcee uses (half and whole ensemble)
        t_compile = time.perf_counter()
        x_fit = lp.to_sampled_np(np.concatenate([self.u_fit, [log_rms]]))
        self.log_prob(np.tile(x_fit, (W // 2, 1)))
        self.log_prob(np.tile(x_fit, (W, 1)))
        self.t_compile = time.perf_counter() - t_compile
        P0, lp0 = _mode_start(found, lambda U: self.log_prob(lp.to_sampled_np(U)), W, self.rng,
                              log_lo + 0.05, log_rms)
        P0 = lp.to_sampled_np(P0)
        if not np.all(np.isfinite(lp0)):
            raise _no_start(fit)
        # Independence proposal: one t component per mode; log σ_n from the start spread.
        s_mid, s_sd = 0.5 * (log_lo + max(log_rms, log_lo + 0.5)), 0.6
        means = lp.to_sampled_np(np.array([np.concatenate([m.u, [s_mid]]) for m in found]))
        covs = np.zeros((len(found), D, D))
        for k, m in enumerate(found):
            covs[k, :-1, :-1] = lp.sampled_cov_np(m.u, START_SCALE**2 * m.cov)
            covs[k, -1, -1] = s_sd**2
        self.start_mix = MixtureProposal(means, covs, [m.weight for m in found])
        # the limit optima the data allow keep a share of the proposal through the burn-in
        w_prop, frozen = limit_proposal_weights(found)
        self.proposal = _Adaptive(MixtureProposal(means, covs, w_prop, frozen=frozen))
        if moves is None:
            moves = default_moves(self.proposal)
        elif callable(moves) and not hasattr(moves, "propose"):
            # a factory for moves that need the log-posterior itself (e.g. gradient-based)
            moves = moves(lp, self.proposal)
        if not isinstance(moves, list):
            moves = [(moves, 1.0)]
        moves = [m if isinstance(m, tuple) else (m, 1.0) for m in moves]
        self.counted = [(_Counted(m, _move_name(m)), w) for m, w in moves]
        self.sampler = emcee.EnsembleSampler(W, D, self.log_prob, vectorize=True,
                                             moves=self.counted)
        # emcee draws its moves from the state's random state: seeding it makes runs repeatable.
        self.state = emcee.State(P0, log_prob=lp0,
                                 random_state=np.random.RandomState(seed).get_state())
        self.labels = unknown_labels(prob, _RunNames(fit)) + ["log_noise_sigma"]
        return self

    def log_prob(self, X):
        return np.asarray(self.lp.batch(X))

    def burn_in(self, burn_in: int, progress) -> int:
        """``burn_in`` steps in ``BURN_IN_STAGES`` stages (discarded); after each: re-seed
        stranded walkers, refit the mixture to the walkers' positions, and scale the local
        DE step towards ~25 % acceptance (emcee's 2.38/√(2D) is tuned for a Gaussian; on
        this thin curved ridge it accepts < 1 %). Returns the walkers restarted."""
        sampler, D, n_reset = self.sampler, self.D, 0
        if burn_in > 0:
            n_stage = BURN_IN_STAGES if burn_in >= 40 * BURN_IN_STAGES else 1
            sizes = [burn_in // n_stage] * n_stage
            sizes[-1] += burn_in - sum(sizes)
            for h in sizes:
                self.state = sampler.run_mcmc(self.state, h, progress=progress,
                                              skip_initial_state_check=True)
                self.state, nr = _reset_outliers(self.state, self.rng, D)
                n_reset += nr
                if nr:
                    self.state.log_prob = self.log_prob(self.state.coords)
                burn_draws = sampler.get_chain()[h // 2 :].reshape(-1, D)
                self.proposal.mix = self.proposal.mix.refit(burn_draws)
                _tune(self.counted, burn_draws, D)
                sampler.reset()
        for m, _ in self.counted:
            m.proposed = m.accepted = 0
        return n_reset

    def grow(self, n_steps, max_steps: int, chunk: int, progress):
        """The kept chain: checked after ``chunk`` steps, then at every growth by
        ``CHECK_GROWTH``, until converged (or ``max_steps``; ``n_steps`` fixes its length).
        Returns ``(steps, convergence, kept-chain s, diagnostics s)``."""
        sampler = self.sampler
        total = n_steps or max_steps
        done, conv = 0, None
        self.tau_history = []  # (steps, largest τ) at each check: does τ outgrow the chain?
        t_kept = time.perf_counter()
        t_diag = 0.0
        next_check = chunk
        while done < total:
            step = min(max(next_check - done, 1) if n_steps is None else total, total - done)
            self.state = sampler.run_mcmc(self.state, step, progress=progress,
                                          skip_initial_state_check=True)
            done += step
            # checks at chunk, then ×CHECK_GROWTH: the diagnostics' cost stays a few checks
            next_check = max(done + chunk, int(CHECK_GROWTH * done))
            if n_steps is None or done >= total:
                td = time.perf_counter()
                short = done < total and _short_of_tau(sampler, done, self.tau_history)
                if short:
                    # a chain under 50 τ of its sampled coordinates: arviz (≈ 1–2 s a check)
                    # only once it may pass; check again where 50 τ is (≤ ×CHECK_GROWTH on)
                    next_check = max(done + chunk, min(next_check, int(1.05 * short)))
                else:
                    conv = _converge(sampler, self.lp, self.prob, self.labels)
                    if conv.tau is not None and np.all(np.isfinite(conv.tau)):
                        self.tau_history.append((done, float(np.max(conv.tau))))
                t_diag += time.perf_counter() - td
                if n_steps is None and not short and conv.converged:
                    break
        return done, conv, time.perf_counter() - t_kept, t_diag

    def _chain_warnings(self, done, conv, burn_in, n_reset):
        """NOT CONVERGED, stranded and STUCK walkers."""
        out = []
        if not conv.converged and (grew := tau_outlasts_chain(getattr(self, "tau_history", []))):
            name, what = conv.worst
            out.append(
                f"NOT CONVERGED: after {done} steps ({burn_in} burn-in before) the worst quantity "
                f"is {name} ({what}), the chain {conv.chain_in_tau:.1f} τ long, and τ grew with "
                f"the chain (τ ∝ steps^{grew[0]:.2f} over the last ×{grew[1]:.1f} in steps): the "
                "walkers do not cross between optima or along a ridge, so a longer chain will not "
                f"converge either; the criterion is bulk/tail ESS ≥ {ESS_MIN} and R-hat ≤ "
                f"{RHAT_MAX} or a chain ≥ {TAU_MULTIPLE} τ. Check the modes and the trace plot; "
                "fix a parameter the log does not determine (--fix / fix=), give it a prior "
                "(--prior / prior=) or log releases that separate it (hdid design)"
            )
        elif not conv.converged:
            name, what = conv.worst
            out.append(
                f"NOT CONVERGED: after {done} steps ({burn_in} burn-in before) the worst quantity "
                f"is {name} ({what}), the chain {conv.chain_in_tau:.1f} τ long; the criterion is "
                f"bulk/tail ESS ≥ {ESS_MIN} and R-hat ≤ {RHAT_MAX} or a chain ≥ {TAU_MULTIPLE} τ, on "
                f"every sampled quantity and the band. Run longer (max_steps (--steps) ≥ {2 * done}); if "
                "R-hat stays high the walkers sit in optima they do not leave — check the "
                "modes and the trace plot"
            )
        acc = self.sampler.acceptance_fraction
        if n_reset:
            out.append(
                f"{n_reset} walker(s) were stranded far below the bulk during the burn-in and "
                "were restarted from good walkers (a minor mode may be under-represented)"
            )
        stuck = acc < 0.25 * np.median(acc)
        if np.any(stuck) or np.any(acc < 0.01):
            out.append(
                f"STUCK WALKERS: {int(np.sum(stuck | (acc < 0.01)))} walker(s) accepted far fewer "
                f"moves than the rest (min {np.min(acc):.3f}, median {np.median(acc):.3f}); "
                "intervals may under-cover — check the chains (trace plot)"
            )
        return out

    def _mode_warnings(self, chain_s):
        """The draws' share in each optimum, and MULTIMODAL when there are several or the
        chain climbed well above the best one found."""
        found, D, out = self.found, self.D, []
        # Share of the kept draws in each mode: the mode whose (weighted) Laplace density is
        # highest at the draw (the adapted mixture's components drift, so not those).
        share, multi = mode_shares(found, self.start_mix, chain_s.reshape(-1, D), "draws",
                                   "the walkers started in all of them and the independence "
                                   "move lets them change mode — see `modes` for their "
                                   "parameters")
        if multi:
            out.append(multi)
        # A chain that climbs well above the best mode found has found yet another one.
        lp = self.lp
        grid = np.linspace(self.log_lo, max(self.log_rms, self.log_lo + math.log(2.0)) + 1.0, 25)
        ref = max(float(np.max(self.log_prob(lp.to_sampled_np(
            np.column_stack([np.tile(m.u, (grid.size, 1)), grid]))))) for m in found)
        best = float(np.max(self.sampler.get_log_prob()))
        if best > ref + MODE_GAP:
            out.append(
                f"MULTIMODAL: the chain reached log p {best - ref:+.1f} above the best optimum "
                "found — the posterior has a mode the search missed; intervals from a chain "
                "that has not mixed between modes are unreliable"
            )
        return share, out

    def result(self, done, conv, burn_in, n_reset, seed, t0, stage_s):
        """The :class:`PosteriorResult`: the draws (thinned by τ/2) in physical units, the
        derived quantities, the warnings, the limits' verdicts and the widths."""
        sampler, lp, prob, fit, D = self.sampler, self.lp, self.prob, self.fit, self.D
        warnings = self.warnings + self._chain_warnings(done, conv, burn_in, n_reset)
        tau_e, tau = _taus(sampler)
        finite_tau = np.isfinite(tau)
        tau_max = float(np.max(tau[finite_tau])) if finite_tau.any() else float(done)
        burn = 0
        thin = max(1, int(tau_max / 2))
        chain_s = sampler.get_chain()  # sampled coordinates
        chain = lp.from_sampled_np(chain_s)  # the fit's unknowns u (+ log σ_n)
        draws = lp.from_sampled_np(sampler.get_chain(discard=burn, thin=thin, flat=True))
        share, more = self._mode_warnings(chain_s)
        warnings += more
        phys = to_physical(prob, draws)
        # the ends of value-flat parameters the data allow, and whether the chain reached them
        warnings += assess_limits(self.limits, lp, self.lin,
                                  [m.u for m in self.found if m.kind == "optimum"] or [self.u_fit],
                                  self.log_prob, (self.log_lo, self.log_rms), phys, fit.values,
                                  limit_shares(self.found, share))
        phys, der = physical_draws(prob, fit.model, phys, draws)
        widths = width_ratios(prob, chain.reshape(-1, D), self.u_fit, PRIOR_HALF_WIDTH, self.lin,
                              lp.gauss_prior)
        return PosteriorResult(
            samples=phys, derived=der, chain=chain, labels=self.labels, tau=np.asarray(tau),
            acceptance=np.asarray(sampler.acceptance_fraction), burn=burn, thin=thin,
            warnings=warnings, seed=seed, wall_time_s=time.perf_counter() - t0,
            temper=self.temper, residual_rho1=self.rho1, fit=fit, draws=draws,
            burn_in=burn_in, modes=self.found, mode_share=share, tau_emcee=np.asarray(tau_e),
            mode_search_s=self.t_modes,
            move_acceptance={m.name: m.rate for m, _ in self.counted},
            n_components=len(self.proposal.mix.weights), convergence=conv, widths=widths,
            limits=[lim.to_dict() for lim in self.limits], compile_s=self.t_compile,
            stage_s={"mode_search": self.t_modes, "compile": self.t_compile, **stage_s},
        )


def _tune(counted, burn_draws, D):
    """After a burn-in stage: hand the stage to moves that tune themselves, scale the
    local DE step towards 25 % acceptance, and reset the counters."""
    import emcee

    for m, _ in counted:
        inner = m.move
        if hasattr(inner, "burn_in_update") and m.proposed > 0:
            inner.burn_in_update(m.rate, burn_draws)
        if isinstance(inner, emcee.moves.DEMove) and inner.gamma0 != 1.0 and m.proposed > 0:
            g = inner.gamma0 if inner.gamma0 is not None else 2.38 / math.sqrt(2 * D)
            inner.gamma0 = g * float(np.clip(m.rate / 0.25, 0.2, 1.5))
        m.proposed = m.accepted = 0


#: τ is estimated on the kept chain thinned to at most this many steps: the FFTs of a
#: 40 000-step chain cost as much as arviz's check; the ensemble rule's boundary is
#: τ = steps / 50 ≥ 80 × the stride, where thinning moves the estimate by < 1 %.
TAU_MAX_STEPS = 4000


def _taus(sampler):
    """emcee's τ (walkers about their own means) and the larger of it and the ensemble-mean
    τ (:func:`tau_pooled`) of each sampled coordinate of the kept chain, in steps (from the
    chain thinned to ≤ ``TAU_MAX_STEPS``, times the stride)."""
    chain = sampler.get_chain()
    thin = max(1, math.ceil(chain.shape[0] / TAU_MAX_STEPS))
    with np.errstate(invalid="ignore", divide="ignore"):  # a walker that never moved
        tau_e = sampler.get_autocorr_time(tol=0, thin=thin)
    return tau_e, np.fmax(tau_e, thin * tau_pooled(chain[::thin]))


def _short_of_tau(sampler, done: int, history: list | None = None) -> int:
    """``TAU_MULTIPLE`` × the largest τ of the sampled coordinates when the chain is shorter
    than that (0 otherwise): the ensemble rule cannot pass yet, and R-hat ≤ 1.01 with walkers
    as chains came only at ≈ 85–125 τ on the paper design (diagnostics module), so the
    arviz check is put off. Conservative: a check put off can only lengthen the chain."""
    t = _taus(sampler)[1]
    if not np.all(np.isfinite(t)):
        return 0
    if history is not None:  # (steps, largest τ): the grown chain's record
        history.append((done, float(np.max(t))))
    need = TAU_MULTIPLE * float(np.max(t))
    return int(math.ceil(need)) if done < need else 0


def _converge(sampler, lp, prob, labels):
    """arviz diagnostics and τ of the kept chain's sampled quantities and the band."""
    full = sampler.get_chain()
    stride = diagnostic_stride(full.shape[0])
    chain = full[::stride]
    S, W, D = chain.shape
    U = lp.from_sampled_np(chain.reshape(-1, D))
    band = derived_np(prob, U)[BAND].reshape(S, W, 1)
    # the band's τ from the thinned chain, in full steps: never below the stride, so an
    # over-estimate where τ is near it (the rule stays conservative)
    tau = np.concatenate([_taus(sampler)[1], stride * tau_pooled(band)])
    return convergence(np.concatenate([chain, band], axis=2), labels + [BAND],
                       tau=tau, steps=full.shape[0])
