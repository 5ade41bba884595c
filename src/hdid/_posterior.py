"""Posterior sampling with emcee around a least-squares fit.

The sampled space is the fit's own unconstrained vector ``u`` (physical parameters in
their transformed space, per-run release instant and start angle, per-set-up offset)
plus ``log σ_n``, the encoder noise before quantization.

Likelihood (quantization-aware). An encoder reading ``y`` is the model angle plus
Gaussian noise, rounded to the step ``q``: ``P(y | θ) = Φ((y + q/2 − θ)/σ_n) −
Φ((y − q/2 − θ)/σ_n)`` — an *interval* of one count, not a Gaussian point. With
sub-count noise the readings of repeated releases are identical and the interval is
what the data actually say. Each stretch of identical readings (pre-release hold, stuck
tail) carries one observation's weight, as in the fit (``weight²`` multiplies the
log-likelihood). When the fit's residuals are autocorrelated beyond what i.i.d. noise
gives, the log-likelihood is tempered by the effective-sample-size factor
``(1 − ρ₁)/(1 + ρ₁)``.

Priors (documented defaults, all in the sampled space):
- physical parameters: flat in the transformed space (flat in log for positive ones)
  within ``± PRIOR_HALF_WIDTH`` of the least-squares value, times the parameters' own
  weak priors (``v_s``, ``delta``) and the inertia prior when the inertia is free;
- release instant: uniform on its bracket between samples; start angle flat within
  ±5 encoder steps of its least-squares value; offset flat;
- ``σ_n``: log-uniform between ``0.05 q`` (the simulator's accuracy) and ``20 q``.

``likelihood="gaussian"`` instead treats the rounding as additive uniform noise of
variance ``q²/12`` (Widrow): Gaussian with ``σ² = σ_n² + q²/12``, never below the
quantization floor.

Sampling: emcee with differential-evolution moves (:func:`default_moves`), walkers started
from the least-squares (Laplace) approximation, a discarded burn-in, and a kept chain grown
until it is ``MIN_TAU_MULTIPLE`` integrated autocorrelation times long.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jax.scipy.special import log_ndtr

from . import _config  # noqa: F401
from ._identifiability import derived_quantities, unknown_labels
from ._problem import Problem
from ._transforms import from_unconstrained

#: Flat prior half-width around the least-squares value in the transformed space
#: (±7 in log ≈ a factor 1000 either way: uninformative but proper).
PRIOR_HALF_WIDTH = 7.0
#: Noise prior bounds, in encoder steps. The floor is the forward model's own accuracy:
#: the simulator's error at the default substep is ≤ 0.042 steps
#: (benchmarks/results/simulator_schemes.md); a smaller σ_n would claim the model reproduces
#: readings more exactly than it can compute them.
SIGMA_BOUNDS = (0.05, 20.0)
#: Chains shorter than this many integrated autocorrelation times get a warning.
MIN_TAU_MULTIPLE = 50
#: A chain this far (log p) above the least-squares optimum has found another mode
#: (Δχ² = 10 in the fit's units: beyond the 99.8 % point of χ²₁).
MODE_GAP = 5.0


def _log_interval(y, theta, half, sigma):
    """``log(Φ((y + half − θ)/σ) − Φ((y − half − θ)/σ))``, stable in both tails."""
    a = (y - half - theta) / sigma
    b = (y + half - theta) / sigma
    # Use the tail where both bounds are on the same side as far from the centre as
    # possible: for a > 0 reflect, Φ(b) − Φ(a) = Φ(−a) − Φ(−b).
    flip = a > 0
    lo = jnp.where(flip, -b, a)
    hi = jnp.where(flip, -a, b)
    l_hi = log_ndtr(hi)
    l_lo = log_ndtr(lo)
    return l_hi + jnp.log1p(-jnp.exp(jnp.minimum(l_lo - l_hi, -1e-300)))


class LogPosterior(eqx.Module):
    """Vectorised log-posterior over walkers: ``(W, D) -> (W,)``."""

    problem: Problem
    centre: jax.Array
    temper: jax.Array
    quantized: bool = eqx.field(static=True)
    sigma_bounds: tuple[float, float] = SIGMA_BOUNDS
    quant_var: float = 0.0

    @property
    def ndim(self) -> int:
        return self.problem.n_unknowns + 1

    def log_prob(self, x):
        p = self.problem
        u, log_sigma = x[:-1], x[-1]
        q = p.step
        sigma = jnp.exp(log_sigma)
        lp = self._log_prior(u, log_sigma)
        pred = p.predict(u)
        w2 = p.weight**2
        if self.quantized:
            ll = _log_interval(p.theta, pred, 0.5 * q, sigma)
        else:
            # Gaussian; on a quantized log the rounding error is added as uniform noise of
            # variance q²/12 (Widrow): the total noise never falls below that floor.
            var = sigma**2 + self.quant_var
            z2 = (p.theta - pred) ** 2 / var
            ll = -0.5 * z2 - 0.5 * jnp.log(2 * jnp.pi * var)
        total = lp + self.temper * jnp.sum(w2 * ll)
        return jnp.where(jnp.isfinite(total) & jnp.isfinite(lp), total, -jnp.inf)

    def _log_prior(self, u, log_sigma):
        p = self.problem
        P, R = p.n_physical, p.n_runs
        lp = -0.5 * jnp.sum(p.prior_residuals(u) ** 2)
        outside = jnp.any(jnp.abs(u[:P] - self.centre[:P]) > PRIOR_HALF_WIDTH)
        q = p.step
        lo, hi = jnp.log(self.sigma_bounds[0] * q), jnp.log(self.sigma_bounds[1] * q)
        outside |= (log_sigma < lo) | (log_sigma > hi)
        if p.release_free:
            v = u[P : P + R]
            # uniform on the bracket: density of the logistic variable is s(1 − s)
            lp += jnp.sum(-jax.nn.softplus(-v) - jax.nn.softplus(v))
        # start angle: within a few encoder steps of its least-squares value (the hold
        # reads it to ±½ step; a slow start can sit a few steps off the reading)
        i = P + (R if p.release_free else 0)
        outside |= jnp.any(jnp.abs(u[i : i + R] - self.centre[i : i + R]) > 5.0)
        return jnp.where(outside, -jnp.inf, lp)

    @eqx.filter_jit
    def batch(self, X):
        return jax.vmap(self.log_prob)(X)


@eqx.filter_jit
def _derived_batch(problem: Problem, X):
    def one(x):
        return derived_quantities(problem.model(x[:-1]))

    return jax.vmap(one)(X)


@eqx.filter_jit
def _predict_batch(problem: Problem, X, times):
    return jax.vmap(lambda x: problem.predict(x[:-1], times))(X)


@dataclass
class PosteriorResult:
    """Samples and summaries of the posterior (see :func:`sample_posterior`)."""

    samples: dict[str, np.ndarray]           # name -> (draws,) physical units
    derived: dict[str, np.ndarray]           # name -> (draws,)
    chain: np.ndarray                        # (steps, walkers, D) raw, sampled space
    labels: list[str]
    tau: np.ndarray                          # integrated autocorrelation time per dim
    acceptance: np.ndarray                   # per walker
    burn: int
    thin: int
    warnings: list[str]
    seed: int
    wall_time_s: float
    temper: float
    residual_rho1: float
    fit: Any = field(repr=False)
    draws: np.ndarray = field(repr=False)    # (draws, D) sampled space, after burn/thin
    burn_in: int = 0                         # steps run and discarded before ``chain``

    def summary(self) -> dict[str, dict[str, Any]]:
        """Median and central 68 % / 95 % intervals of every parameter and derived quantity."""
        out = {}
        for name, v in {**self.samples, **self.derived}.items():
            v = np.asarray(v)
            q = np.percentile(v, [2.5, 16, 50, 84, 97.5])
            out[name] = {
                "median": float(q[2]),
                "ci68": [float(q[1]), float(q[3])],
                "ci95": [float(q[0]), float(q[4])],
            }
        return out

    def to_dict(self) -> dict[str, Any]:
        s = self.summary()
        return {
            "posterior": s,
            "posterior_diagnostics": {
                "n_walkers": int(self.chain.shape[1]),
                "n_steps": int(self.chain.shape[0]),
                "burn_in": self.burn_in,
                "burn": self.burn,
                "thin": self.thin,
                "chain_in_tau_max": float(self.chain.shape[0] / np.nanmax(self.tau)),
                "converged": bool(self.chain.shape[0] >= MIN_TAU_MULTIPLE * np.nanmax(self.tau)),
                "n_draws": int(self.draws.shape[0]),
                "tau_max": float(np.nanmax(self.tau)),
                "tau": {l: float(t) for l, t in zip(self.labels, self.tau)},
                "acceptance_mean": float(np.mean(self.acceptance)),
                "acceptance_min": float(np.min(self.acceptance)),
                "residual_lag1_autocorrelation": self.residual_rho1,
                "likelihood_temper": self.temper,
                "seed": self.seed,
                "wall_time_s": self.wall_time_s,
                "warnings": list(self.warnings),
            },
        }

    def report(self) -> str:
        lines = ["posterior (median, 68 % and 95 % intervals):"]
        for name, s in self.summary().items():
            lines.append(
                f"  {name:<26} {s['median']:12.5g}  [{s['ci68'][0]:.4g}, {s['ci68'][1]:.4g}]"
                f"  [{s['ci95'][0]:.4g}, {s['ci95'][1]:.4g}]"
            )
        lines.append(
            f"  {self.chain.shape[1]} walkers × {self.chain.shape[0]} steps (after "
            f"{self.burn_in} burn-in), max τ {np.nanmax(self.tau):.0f} = chain / "
            f"{self.chain.shape[0] / np.nanmax(self.tau):.1f}, acceptance {np.mean(self.acceptance):.2f}, "
            f"{self.draws.shape[0]} draws, {self.wall_time_s:.1f} s"
        )
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def to_inference_data(self):
        """arviz InferenceData (posterior group: physical and derived quantities)."""
        import arviz as az

        steps, walkers, _ = self.chain.shape
        post = self.chain[self.burn :: self.thin]  # (S, W, D)
        flat = post.reshape(-1, post.shape[-1])
        phys = _to_physical(self.fit.problem, flat)
        der = {k: np.asarray(v) for k, v in _derived_batch(self.fit.problem, jnp.asarray(flat)).items()}
        data = {}
        shape = (walkers, post.shape[0])
        for k, v in {**phys, **der}.items():
            data[k.replace("/", "_per_")] = np.asarray(v).reshape(post.shape[0], walkers).T.reshape(shape)
        data["noise_sigma_rad"] = np.exp(flat[:, -1]).reshape(post.shape[0], walkers).T
        return az.from_dict(posterior=data, attrs={"source": self.fit.source, "seed": self.seed})

    def save(self, path) -> None:
        """Write the chains as arviz NetCDF (reopen with ``arviz.from_netcdf``)."""
        self.to_inference_data().to_netcdf(str(path))

    def plot_corner(self, path=None, names=None, fig=None):
        import corner

        names = names or [n for n in self.samples if np.ptp(self.samples[n]) > 0]
        data = np.column_stack([self.samples[n] for n in names])
        fig = corner.corner(data, labels=names, quantiles=[0.16, 0.5, 0.84], fig=fig,
                            show_titles=True, title_fmt=".3g")
        if path is not None:
            fig.savefig(path, dpi=90)
        return fig

    def plot_predictive(self, path=None, n_draws: int = 100, axes=None, seed: int = 0):
        from ._plot import plot_predictive

        return plot_predictive(self, path=path, n_draws=n_draws, axes=axes, seed=seed)

    def plot_band(self, path=None, ax=None):
        from ._plot import plot_band

        return plot_band(self, path=path, ax=ax)


def _to_physical(problem: Problem, flat: np.ndarray) -> dict[str, np.ndarray]:
    specs = problem.base.parameter_specs()
    out = {}
    for i, n in enumerate(problem.free):
        out[n] = np.asarray(from_unconstrained(specs[n], jnp.asarray(flat[:, i])))
    return out


def residual_autocorrelation(fit) -> float:
    """Lag-1 autocorrelation of the fit's residuals while the gear moves."""
    prob = fit.problem
    r = np.asarray(fit.predict()) - np.asarray(prob.theta)
    w = np.asarray(prob.weight)
    num = den = 0.0
    for i in range(r.shape[0]):
        moving = w[i] >= 1.0  # full-weight samples: the motion (not hold or stuck tail)
        x = r[i][moving]
        if x.size < 3:
            continue
        x = x - x.mean()
        num += float(np.sum(x[1:] * x[:-1]))
        den += float(np.sum(x * x))
    return num / den if den > 0 else 0.0


def default_moves():
    """emcee moves used by default: differential evolution, with snooker and mode jumps.

    Measured on an 18-D Gaussian with the shipped log's least-squares covariance (36
    walkers, 20000 steps): emcee's default stretch move has τ ≈ 250–290 steps, the
    differential-evolution mixture ≈ 65 — the stretch move's efficiency falls with the
    dimension, and at 18 unknowns it alone cannot reach 50 τ in a minute. ``γ = 1`` DE
    steps (ter Braak 2006) let walkers jump between separated modes (the paper design's
    stick band can be bimodal).
    """
    import emcee

    return [
        (emcee.moves.DEMove(), 0.7),
        (emcee.moves.DEMove(gamma0=1.0), 0.1),
        (emcee.moves.DESnookerMove(), 0.2),
    ]


def _laplace_start(fit, x0, lp_batch, W, rng, sigma_lo, sigma_hi, scale=0.5):
    """Walkers drawn from the least-squares (Laplace) approximation, scaled by ``scale``.

    The interval likelihood is sharper than the ``q/√12`` Gaussian the fit's covariance
    assumes (posterior spreads are 0.4–1× the least-squares ones on the shipped log), so
    half the Laplace width starts the ensemble inside the bulk yet spread over it; the
    noise ``log σ_n`` starts uniform between its prior floor and the fit's RMS. Walkers
    with zero prior density are pulled back towards the optimum.
    """
    D = x0.size
    cov = np.asarray(fit.covariance, dtype=float)
    cov = 0.5 * (cov + cov.T)
    w, V = np.linalg.eigh(cov)
    L = V * np.sqrt(np.clip(w, 0.0, None))
    z = rng.standard_normal((W, D - 1))
    P0 = np.empty((W, D))
    P0[:, :-1] = x0[:-1] + scale * z @ L.T
    P0[:, -1] = rng.uniform(sigma_lo, max(sigma_hi, sigma_lo + 0.5), W)
    lp0 = lp_batch(P0)
    for _ in range(60):
        bad = ~np.isfinite(lp0)
        if not bad.any():
            break
        P0[bad, :-1] = x0[:-1] + 0.7 * (P0[bad, :-1] - x0[:-1])
        lp0[bad] = lp_batch(P0[bad])
    return P0, lp0


def _reset_outliers(state, rng, ndim):
    """Move walkers stranded far below the bulk onto copies of good walkers (burn-in only).

    Under a roughly Gaussian posterior ``2·(log p_max − log p)`` of a draw is χ²_D; a
    walker beyond the 0.9999 quantile is stuck (a minor mode or a ridge it cannot leave),
    not sampling. Done once, at the end of the burn-in that is then discarded, it does
    not bias the kept chain.
    """
    from scipy.stats import chi2

    lp = np.asarray(state.log_prob)
    cut = np.max(lp) - 0.5 * chi2.ppf(0.9999, ndim)
    bad = np.flatnonzero(~(lp >= cut))
    good = np.flatnonzero(lp >= cut)
    if bad.size == 0 or good.size < 2:
        return state, 0
    X = np.array(state.coords)
    L = np.array(lp)
    spread = np.std(X[good], axis=0)
    pick = rng.choice(good, size=bad.size)
    X[bad] = X[pick] + 1e-3 * spread * rng.standard_normal((bad.size, X.shape[1]))
    L[bad] = np.nan  # recomputed by the caller
    import emcee

    return emcee.State(X, log_prob=L, random_state=state.random_state), int(bad.size)


def sample_posterior(
    fit,
    *,
    n_walkers: int | None = None,
    n_steps: int | None = None,
    max_steps: int = 20000,
    burn_in: int = 400,
    chunk: int = 1000,
    seed: int = 0,
    progress: bool = False,
    likelihood: str = "auto",
    moves=None,
    sigma_floor: float | None = None,
) -> PosteriorResult:
    """Run emcee from the least-squares optimum of ``fit``.

    A burn-in of ``burn_in`` steps (walkers started from the Laplace approximation,
    stranded walkers re-seeded at its end) is run and discarded; the kept chain then grows
    in chunks until it is ``MIN_TAU_MULTIPLE`` integrated autocorrelation times long (τ
    estimated on the kept chain), or for exactly ``n_steps`` steps.

    Parameters
    ----------
    fit:
        A :class:`~hdid.FitResult`.
    n_walkers:
        Default ``max(32, 2·D)`` (emcee's red-blue moves need at least twice the dimension).
    n_steps:
        Fixed length of the kept chain; default: adaptive (see above) up to ``max_steps``.
    burn_in:
        Steps run and discarded before the kept chain.
    seed:
        Seed of the walkers' start and of emcee's moves (reproducible).
    progress:
        Show a progress bar (tqdm).
    likelihood:
        ``"interval"`` (quantization-aware), ``"gaussian"`` or ``"auto"`` (interval when
        the log is quantized).
    moves:
        emcee moves; default :func:`default_moves` (differential evolution).
    sigma_floor:
        Lower bound of the noise prior in encoder steps (default ``SIGMA_BOUNDS[0]``).
    """
    import emcee

    t0 = time.perf_counter()
    prob: Problem = fit.problem
    warnings: list[str] = []
    if likelihood not in ("auto", "gaussian", "interval"):
        raise ValueError(f"likelihood must be 'auto', 'gaussian' or 'interval', not {likelihood!r}")
    quantized = likelihood == "interval"
    quant_var = float(prob.step) ** 2 / 12.0 if (not quantized and fit.resolution_known) else 0.0
    rho1 = residual_autocorrelation(fit)
    n_moving = int(np.sum(np.asarray(prob.weight) >= 1.0))
    temper = 1.0
    if n_moving > 3 and rho1 > 2.0 / math.sqrt(n_moving):
        temper = (1.0 - rho1) / (1.0 + rho1)
        warnings.append(
            f"fit residuals are autocorrelated (lag-1 r = {rho1:.2f}); the likelihood is "
            f"tempered by the effective-sample-size factor {temper:.2f}"
        )
    bounds = (SIGMA_BOUNDS[0] if sigma_floor is None else float(sigma_floor), SIGMA_BOUNDS[1])
    centre = jnp.asarray(fit.u)
    lp = LogPosterior(problem=prob, centre=centre, temper=jnp.asarray(temper),
                      quantized=quantized, sigma_bounds=bounds, quant_var=quant_var)
    D = lp.ndim
    W = n_walkers or max(32, 2 * D)
    if W < 2 * D:
        raise ValueError(f"n_walkers = {W}: emcee needs at least 2 × {D} walkers; raise n_walkers")

    def log_prob(X):
        return np.asarray(lp.batch(jnp.asarray(X)))

    rng = np.random.default_rng(seed)
    q = float(prob.step)
    x0 = np.concatenate([np.asarray(fit.u), [math.log(max(fit.rms_residual_rad, bounds[0] * q))]])
    P0, lp0 = _laplace_start(
        fit, x0, log_prob, W, rng, math.log(bounds[0] * q) + 0.05,
        math.log(max(fit.rms_residual_rad, bounds[0] * q)),
    )
    if not np.all(np.isfinite(lp0)):
        raise RuntimeError("could not place the walkers where the posterior is positive")

    moves = default_moves() if moves is None else moves
    sampler = emcee.EnsembleSampler(W, D, log_prob, vectorize=True, moves=moves)
    # emcee draws its moves from the state's random state: seeding it makes runs repeatable.
    state = emcee.State(P0, log_prob=lp0, random_state=np.random.RandomState(seed).get_state())
    n_reset = 0
    if burn_in > 0:
        state = sampler.run_mcmc(state, burn_in, progress=progress, skip_initial_state_check=True)
        state, n_reset = _reset_outliers(state, rng, D)
        if n_reset:
            state.log_prob = log_prob(state.coords)
        sampler.reset()
    total = n_steps or max_steps
    done = 0
    tau = np.full(D, np.nan)
    while done < total:
        step = min(chunk if n_steps is None else total, total - done)
        if n_steps is None and done > 0 and np.all(np.isfinite(tau)):
            # jump straight to the length the current τ asks for (plus 10 %)
            need = int(1.1 * MIN_TAU_MULTIPLE * np.max(tau)) - done
            step = int(min(max(step, need), total - done))
        state = sampler.run_mcmc(state, step, progress=progress, skip_initial_state_check=True)
        done += step
        tau = sampler.get_autocorr_time(tol=0)
        if n_steps is None and np.all(np.isfinite(tau)) and done >= MIN_TAU_MULTIPLE * np.max(tau):
            break
    finite_tau = np.isfinite(tau)
    tau_max = float(np.max(tau[finite_tau])) if finite_tau.any() else float(done)
    labels = unknown_labels(prob, _RunNames(fit)) + ["log_noise_sigma"]
    if not finite_tau.all():
        warnings.append(
            "the autocorrelation time could not be estimated for every quantity (a walker "
            "that never moves gives NaN); treat the intervals as unreliable"
        )
    if done < MIN_TAU_MULTIPLE * tau_max:
        worst = labels[int(np.nanargmax(tau))] if finite_tau.any() else "?"
        warnings.append(
            f"NOT CONVERGED: the chain ({done} steps after {burn_in} burn-in) is only "
            f"{done / tau_max:.1f} autocorrelation times long (τ_max = {tau_max:.0f} steps, "
            f"{worst}); {MIN_TAU_MULTIPLE} τ are needed for reliable intervals — run longer "
            f"(n_steps ≥ {int(MIN_TAU_MULTIPLE * tau_max)}, or raise max_steps)"
        )
    acc = sampler.acceptance_fraction
    if n_reset:
        warnings.append(
            f"{n_reset} walker(s) were stranded far below the bulk after the burn-in and "
            "were restarted from good walkers (a minor mode may be under-represented)"
        )
    stuck = acc < 0.25 * np.median(acc)
    if np.any(stuck) or np.any(acc < 0.01):
        warnings.append(
            f"STUCK WALKERS: {int(np.sum(stuck | (acc < 0.01)))} walker(s) accepted far fewer "
            f"moves than the rest (min {np.min(acc):.3f}, median {np.median(acc):.3f}); "
            "intervals may under-cover — check the chains (trace plot)"
        )
    # A chain that climbs well above the least-squares optimum has found another mode: the
    # fit is a local optimum and the posterior is multimodal (the reference is the best
    # log-posterior at the fit's u over a grid of noise levels).
    grid = np.linspace(math.log(bounds[0] * q), math.log(max(fit.rms_residual_rad, 2 * bounds[0] * q)) + 1.0, 25)
    ref = float(np.max(log_prob(np.column_stack([np.tile(x0[:-1], (grid.size, 1)), grid]))))
    best = float(np.max(sampler.get_log_prob()))
    if best > ref + MODE_GAP:
        warnings.append(
            f"MULTIMODAL: the chain reached log p {best - ref:+.1f} above the least-squares "
            "optimum — the fit is a local optimum and the posterior has another mode; "
            "intervals from a chain that has not mixed between modes are unreliable"
        )
    burn = 0
    thin = max(1, int(tau_max / 2))
    chain = sampler.get_chain()
    draws = sampler.get_chain(discard=burn, thin=thin, flat=True)
    phys = _to_physical(prob, draws)
    # Fixed parameters appear with their constant value so every name is present.
    values = fit.model.float_values()
    for n in values:
        if n not in phys:
            phys[n] = np.full(draws.shape[0], values[n])
    phys = {n: phys[n] for n in values}
    der = {k: np.asarray(v) for k, v in _derived_batch(prob, jnp.asarray(draws)).items()}
    der["noise_sigma_rad"] = np.exp(draws[:, -1])
    return PosteriorResult(
        samples=phys,
        derived=der,
        chain=chain,
        labels=labels,
        tau=np.asarray(tau),
        acceptance=np.asarray(acc),
        burn=burn,
        thin=thin,
        warnings=warnings,
        seed=seed,
        wall_time_s=time.perf_counter() - t0,
        temper=temper,
        residual_rho1=rho1,
        fit=fit,
        draws=draws,
        burn_in=burn_in,
    )


class _RunNames:
    """Adapter giving ``unknown_labels`` the run and set-up names of a FitResult."""

    def __init__(self, fit):
        self.run_names = [r.name for r in fit.runs]
        self.setup_names = list(fit.setups)
