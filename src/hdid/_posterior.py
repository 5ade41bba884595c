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
- ``σ_n``: log-uniform between ``0.02 q`` and ``20 q``.
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
#: Noise prior bounds, in encoder steps.
SIGMA_BOUNDS = (0.02, 20.0)
#: Chains shorter than this many integrated autocorrelation times get a warning.
MIN_TAU_MULTIPLE = 50


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
            z = (p.theta - pred) / sigma
            ll = -0.5 * z**2 - log_sigma - 0.5 * jnp.log(2 * jnp.pi)
        total = lp + self.temper * jnp.sum(w2 * ll)
        return jnp.where(jnp.isfinite(total) & jnp.isfinite(lp), total, -jnp.inf)

    def _log_prior(self, u, log_sigma):
        p = self.problem
        P, R = p.n_physical, p.n_runs
        lp = -0.5 * jnp.sum(p.prior_residuals(u) ** 2)
        outside = jnp.any(jnp.abs(u[:P] - self.centre[:P]) > PRIOR_HALF_WIDTH)
        q = p.step
        lo, hi = jnp.log(SIGMA_BOUNDS[0] * q), jnp.log(SIGMA_BOUNDS[1] * q)
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
                "burn": self.burn,
                "thin": self.thin,
                "n_draws": int(self.draws.shape[0]),
                "tau_max": float(np.max(self.tau)),
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
            f"  {self.chain.shape[1]} walkers × {self.chain.shape[0]} steps, max τ "
            f"{np.max(self.tau):.0f}, acceptance {np.mean(self.acceptance):.2f}, "
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


def sample_posterior(
    fit,
    *,
    n_walkers: int | None = None,
    n_steps: int | None = None,
    max_steps: int = 20000,
    chunk: int = 500,
    seed: int = 0,
    progress: bool = False,
    likelihood: str = "auto",
    moves=None,
) -> PosteriorResult:
    """Run emcee from the least-squares optimum of ``fit``.

    Parameters
    ----------
    fit:
        A :class:`~hdid.FitResult`.
    n_walkers:
        Default ``max(32, 2·D + 2)`` (emcee needs at least twice the dimension).
    n_steps:
        Fixed chain length; default: run in chunks until the chain is at least
        ``MIN_TAU_MULTIPLE`` integrated autocorrelation times long (or ``max_steps``).
    seed:
        Seed of the walkers' initial ball and of emcee's moves (reproducible).
    progress:
        Show a progress bar (tqdm).
    likelihood:
        ``"interval"`` (quantization-aware), ``"gaussian"`` or ``"auto"`` (interval when
        the log is quantized).
    moves:
        emcee moves (default: emcee's stretch move; a differential-evolution + snooker
        mixture was not faster on the shipped example: τ_max 368 vs 312 steps).
    """
    import emcee

    t0 = time.perf_counter()
    prob: Problem = fit.problem
    warnings: list[str] = []
    quantized = likelihood == "interval" or (likelihood == "auto" and fit.resolution_known)
    rho1 = residual_autocorrelation(fit)
    n_moving = int(np.sum(np.asarray(prob.weight) >= 1.0))
    temper = 1.0
    if n_moving > 3 and rho1 > 2.0 / math.sqrt(n_moving):
        temper = (1.0 - rho1) / (1.0 + rho1)
        warnings.append(
            f"fit residuals are autocorrelated (lag-1 r = {rho1:.2f}); the likelihood is "
            f"tempered by the effective-sample-size factor {temper:.2f}"
        )
    centre = jnp.asarray(fit.u)
    lp = LogPosterior(problem=prob, centre=centre, temper=jnp.asarray(temper), quantized=quantized)
    D = lp.ndim
    W = n_walkers or max(32, 2 * D + 2)
    if W < 2 * D:
        raise ValueError(f"n_walkers = {W}: emcee needs at least 2 × {D} walkers; raise n_walkers")

    rng = np.random.default_rng(seed)
    std_u = np.sqrt(np.clip(np.diag(fit.covariance), 1e-12, 1.0))
    sigma0 = math.log(max(fit.rms_residual_rad, 0.1 * float(prob.step)))
    x0 = np.concatenate([np.asarray(fit.u), [sigma0]])
    scale = np.concatenate([0.1 * std_u, [0.05]])
    P0 = x0 + scale * rng.standard_normal((W, D))
    lp0 = np.asarray(lp.batch(jnp.asarray(P0)))
    for _ in range(50):  # pull starting walkers with zero posterior density back in
        bad = ~np.isfinite(lp0)
        if not bad.any():
            break
        P0[bad] = x0 + 0.3 * (P0[bad] - x0)
        lp0 = np.asarray(lp.batch(jnp.asarray(P0)))
    if not np.all(np.isfinite(lp0)):
        raise RuntimeError("could not place the walkers where the posterior is positive")

    def log_prob(X):
        return np.asarray(lp.batch(jnp.asarray(X)))

    sampler = emcee.EnsembleSampler(W, D, log_prob, vectorize=True, moves=moves)
    # emcee draws its moves from the state's random state: seeding it makes runs repeatable.
    state = emcee.State(P0, log_prob=lp0, random_state=np.random.RandomState(seed).get_state())
    total = n_steps or max_steps
    done = 0
    tau = np.full(D, np.nan)
    while done < total:
        step = min(chunk if n_steps is None else total, total - done)
        state = sampler.run_mcmc(state, step, progress=progress, skip_initial_state_check=True)
        done += step
        tau = sampler.get_autocorr_time(tol=0)
        if n_steps is None and np.all(np.isfinite(tau)) and done >= MIN_TAU_MULTIPLE * np.max(tau):
            break
    finite_tau = np.isfinite(tau)
    tau_max = float(np.max(tau[finite_tau])) if finite_tau.any() else float(done)
    if not finite_tau.all():
        warnings.append(
            "the autocorrelation time could not be estimated for every quantity (a walker "
            "that never moves gives NaN); treat the intervals as unreliable"
        )
    if done < MIN_TAU_MULTIPLE * tau_max:
        warnings.append(
            f"chain of {done} steps is shorter than {MIN_TAU_MULTIPLE} autocorrelation "
            f"times ({MIN_TAU_MULTIPLE} × {tau_max:.0f}); intervals are rough — run longer"
        )
    acc = sampler.acceptance_fraction
    if np.any(acc < 0.05):
        warnings.append(
            f"{int(np.sum(acc < 0.05))} walker(s) accepted < 5 % of moves (stuck); "
            "results may under-cover — check the chains"
        )
    burn = int(min(2 * tau_max, done // 2))
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
        labels=unknown_labels(prob, _RunNames(fit)) + ["log_noise_sigma"],
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
    )


class _RunNames:
    """Adapter giving ``unknown_labels`` the run and set-up names of a FitResult."""

    def __init__(self, fit):
        self.run_names = [r.name for r in fit.runs]
        self.setup_names = list(fit.setups)
