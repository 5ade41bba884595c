"""Posterior sampling with emcee around a least-squares fit.

The sampled space is the fit's own unconstrained vector ``u`` (physical parameters in
their transformed space, per-run release instant and start angle, per-set-up offset)
plus ``log σ_n``, the encoder noise before quantization.

Likelihood. Default (``"auto"``): an encoder reading ``y`` is the model angle plus Gaussian
noise ``σ_n`` (fitted) plus the rounding to the step ``q`` treated as independent uniform
noise of variance ``q²/12`` (Widrow): Gaussian with ``σ² = σ_n² + q²/12``, never below the
quantization floor. ``likelihood="interval"`` instead treats each reading as an *interval*
of one count: ``P(y | θ) = Φ((y + q/2 − θ)/σ_n) − Φ((y − q/2 − θ)/σ_n)``. Measured on 20
noiseless rounded paper-design logs (benchmarks/results/posterior_likelihood.md): the
Gaussian puts the truth at 2Δlog L consistent with χ²₇ (mean 7.7, KS p = 0.31), the
interval likelihood at its flat top (2Δ ≤ 0.4); but on such data σ_n sits at its floor and
the interval likelihood is a flat top with sharp walls, on which the chain's τ doubles
(benchmarks/results/posterior_mixing.md) — hence the Gaussian default. Each stretch of
identical readings (pre-release hold, stuck tail) carries one observation's weight, as in
the fit (``weight²`` multiplies the log-likelihood). When the fit's residuals are
autocorrelated beyond what i.i.d. noise gives, the log-likelihood is tempered by the
effective-sample-size factor ``(1 − ρ₁)/(1 + ρ₁)``.

Priors (documented defaults, all in the sampled space):
- physical parameters: flat in the transformed space (flat in log for positive ones)
  within ``± PRIOR_HALF_WIDTH`` of the least-squares value, times the parameters' own
  weak priors (``v_s``, ``delta``) and the inertia prior when the inertia is free; the
  coefficients of terms that may vanish (``LINEAR_PRIOR``: ``k2``, ``c_v``) are flat in
  their value instead (same box);
- release instant: uniform on its bracket between samples; start angle flat within
  ±5 encoder steps of its least-squares value; offset flat;
- ``σ_n``: log-uniform between ``0.05 q`` (the simulator's accuracy) and ``20 q``.

``likelihood="gaussian"`` is the same as ``"auto"``: the ``q²/12`` term is added whenever
the encoder step is known (``fit.resolution_known``), and left out otherwise.

Sampling: emcee, in the fit's coordinates except that ``SAMPLE_LINEAR`` parameters (k1,
k2, τ_c, c_v) are moved in their value, where the data's constraints are straight lines
(the density carries the Jacobian). :func:`find_modes` restarts the local fit around the least-squares optimum
and keeps every distinct optimum with its Laplace mass; walkers start spread over them, and
the moves (:func:`default_moves`) are differential evolution plus an independence
Metropolis–Hastings proposal from a t-mixture over the modes (:class:`MixtureProposal`,
adapted during a discarded burn-in), which moves walkers between modes exactly. The kept
chain grows until it is ``MIN_TAU_MULTIPLE`` integrated autocorrelation times long (τ about
the ensemble mean as well as per walker, :func:`tau_pooled`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
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
#: Log-transformed parameters whose default prior is flat in the *value*, not in its log:
#: coefficients of terms that may be absent. A prior flat in log k2 (or log c_v) gives the
#: "no cubic stiffness" ("no viscous friction") end an unbounded volume as the box widens —
#: on the paper design that volume, not the data, pulled the posterior to k2 → 0 and a
#: 92 mrad band (benchmarks/results/posterior_calibration.md).
LINEAR_PRIOR = ("k2", "c_v")
#: Log-transformed parameters that are *sampled* in their value (relative to the
#: least-squares one) instead of their log. The data fix sums such as the stiffness torque
#: ``k1·d + k2·d³`` over the twists seen and the friction ``τ_c + c_v·v`` over the speeds
#: seen: straight lines in the values, bananas in their logs (k1–k2, τ_c–c_v on the paper
#: design), and emcee's affine-invariant moves only straighten straight lines. The target
#: density carries the Jacobian, so this changes the mixing, not the posterior
#: (benchmarks/results/posterior_coordinates.md).
SAMPLE_LINEAR = ("k1", "k2", "tau_c", "c_v")
#: Walkers start from each mode's Laplace approximation at this multiple of its width.
START_SCALE = 1.0
#: The burn-in is run in this many stages, the proposal adapted after each.
BURN_IN_STAGES = 4
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
    #: 1.0 at log-transformed parameters whose prior is flat in the value, not its log
    linear_prior: jax.Array | None = None
    #: 1.0 at log-transformed parameters *sampled* in their value relative to the
    #: least-squares one (``y = exp(u − centre)``, see ``SAMPLE_LINEAR``); ``None``: the
    #: sampled vector is ``u`` itself
    sample_linear: jax.Array | None = None

    @property
    def ndim(self) -> int:
        return self.problem.n_unknowns + 1

    def to_u(self, x):
        """``(u, log|du/dy|, inside)`` of one sampled vector's unknowns (JAX)."""
        u = x[:-1]
        m = self.sample_linear
        if m is None:
            return u, 0.0, True
        P = m.shape[0]
        y = u[:P]
        on = m > 0
        safe = jnp.where(on & (y > 0), y, 1.0)
        uP = jnp.where(on, self.centre[:P] + jnp.log(safe), y)
        return u.at[:P].set(uP), -jnp.sum(jnp.where(on, jnp.log(safe), 0.0)), ~jnp.any(on & (y <= 0))

    def to_sampled_np(self, U):
        """Sampled coordinates of unknowns ``U`` ``(..., n_unknowns + 1)`` (NumPy)."""
        X = np.array(U, dtype=float)
        if self.sample_linear is not None:
            on = np.flatnonzero(np.asarray(self.sample_linear) > 0)
            X[..., on] = np.exp(X[..., on] - np.asarray(self.centre)[on])
        return X

    def from_sampled_np(self, X):
        """Inverse of :meth:`to_sampled_np` (NumPy)."""
        U = np.array(X, dtype=float)
        if self.sample_linear is not None:
            on = np.flatnonzero(np.asarray(self.sample_linear) > 0)
            with np.errstate(divide="ignore", invalid="ignore"):
                U[..., on] = np.asarray(self.centre)[on] + np.log(U[..., on])
        return U

    def sampled_cov_np(self, u, cov):
        """Covariance ``cov`` of ``u`` carried to the sampled coordinates at ``u`` (linearised)."""
        if self.sample_linear is None:
            return np.asarray(cov, dtype=float)
        d = np.ones(len(u))
        on = np.flatnonzero(np.asarray(self.sample_linear) > 0)
        d[on] = np.exp(np.asarray(u)[on] - np.asarray(self.centre)[on])
        return d[:, None] * np.asarray(cov, dtype=float) * d[None, :]

    def log_prob(self, x):
        """Log-posterior of one sampled vector ``x`` (unknowns, then ``log σ_n``)."""
        return self._log_prob_given(x, self.problem.predict(self.to_u(x)[0]))

    def _log_prob_given(self, x, pred):
        """Log-posterior of ``x`` given its predicted readings ``pred`` ``(R, T)``."""
        p = self.problem
        u, log_jac, inside = self.to_u(x)
        log_sigma = x[-1]
        q = p.step
        sigma = jnp.exp(log_sigma)
        lp = self._log_prior(u, log_sigma)
        w2 = p.weight**2
        if self.quantized:
            ll = _log_interval(p.theta, pred, 0.5 * q, sigma)
        else:
            # Gaussian; on a quantized log the rounding error is added as uniform noise of
            # variance q²/12 (Widrow): the total noise never falls below that floor.
            var = sigma**2 + self.quant_var
            z2 = (p.theta - pred) ** 2 / var
            ll = -0.5 * z2 - 0.5 * jnp.log(2 * jnp.pi * var)
        total = lp + self.temper * jnp.sum(w2 * ll) + log_jac
        return jnp.where(jnp.isfinite(total) & jnp.isfinite(lp) & inside, total, -jnp.inf)

    def _log_prior(self, u, log_sigma):
        p = self.problem
        P, R = p.n_physical, p.n_runs
        lp = -0.5 * jnp.sum(p.prior_residuals(u) ** 2)
        if self.linear_prior is not None:
            # flat in x = exp(u): density in u is ∝ exp(u)
            lp += jnp.sum(self.linear_prior * (u[:P] - self.centre[:P]))
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

    def batch(self, X):
        """:meth:`log_prob` of every row of ``X`` ``(W, D)`` (NumPy or JAX); the walkers'
        runs are simulated in one loop (:meth:`Problem.predict_many`), not by ``vmap``."""
        return _batch_jit(self, X)


def _batch(lp: LogPosterior, X):
    U = jax.vmap(lambda x: lp.to_u(x)[0])(X)
    return jax.vmap(lp._log_prob_given)(X, lp.problem.predict_many(U))


# Plain jax.jit, not eqx.filter_jit: every leaf of a LogPosterior is an array or a float,
# and jax.jit's dispatch is 0.2 ms faster per call (0.54 vs 0.74 ms for 18 walkers), a
# fifth of the call at emcee's two calls per step.
_batch_jit = jax.jit(_batch)


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
    modes: list = field(default_factory=list)  # Mode: the optima the walkers started from
    mode_share: np.ndarray | None = None     # share of the kept chain nearest each mode
    tau_emcee: np.ndarray | None = None      # emcee's τ (walkers about their own means)
    mode_search_s: float = 0.0
    move_acceptance: dict = field(default_factory=dict)  # per move, kept chain only
    n_components: int = 0                    # components of the adapted mixture proposal
    pilot_ess: float | None = None           # ESS of the pilot's importance weights
    pilot_s: float = 0.0                     # wall time of the pilot chains

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
                "move_acceptance": dict(self.move_acceptance),
                "tau_max_emcee": (float(np.nanmax(self.tau_emcee))
                                  if self.tau_emcee is not None else None),
                "pilot_importance_ess": self.pilot_ess,
                "modes": [
                    {**m.to_dict(), "share_of_draws": (float(self.mode_share[i])
                                                      if self.mode_share is not None else None)}
                    for i, m in enumerate(self.modes)
                ],
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
        if self.move_acceptance:
            lines.append("  acceptance per move: " + ", ".join(
                f"{k} {v:.3f}" for k, v in self.move_acceptance.items()))
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


def default_moves(proposal=None):
    """emcee moves used by default: differential evolution (+ snooker, mode jumps) and,
    given a :class:`MixtureProposal`, independence Metropolis–Hastings from it.

    Measured on an 18-D Gaussian with the shipped log's least-squares covariance (36
    walkers, 20000 steps): emcee's default stretch move has τ ≈ 250–290 steps, the
    differential-evolution mixture ≈ 65 — the stretch move's efficiency falls with the
    dimension. DE only undoes *linear* correlations and moves walkers locally; the
    paper design's posterior has several modes and curved ridges
    (benchmarks/results/posterior_geometry.md), which the independence proposal
    crosses in one step (benchmarks/results/posterior_speed.md).
    """
    import emcee

    if proposal is None:
        return [
            (emcee.moves.DEMove(), 0.7),
            (emcee.moves.DEMove(gamma0=1.0), 0.1),
            (emcee.moves.DESnookerMove(), 0.2),
        ]
    return [
        (emcee.moves.DEMove(), 0.4),
        (emcee.moves.DEMove(gamma0=1.0), 0.05),
        (emcee.moves.DESnookerMove(), 0.2),
        (emcee.moves.MHMove(proposal), 0.35),
    ]


# ----------------------------------------------------------------------------- modes

#: Local optima more than this far above the best (χ² in the fit's q/√12 units) carry
#: a posterior mass ``exp(−Δχ²/2) < 1e-13`` of the best one's: ignored.
MODE_DCHI2_MAX = 60.0
#: Two optima joined by a straight path whose cost rises less than this above the worse
#: of the two are one mode (a flat, curved valley on which the optimiser stopped twice).
MODE_BARRIER = 4.0
#: Variance of the flat ±PRIOR_HALF_WIDTH prior, added as a ridge to the Gauss–Newton
#: precision so that directions the data cannot see get the prior's width, not infinity.
_BOX_PRECISION = 12.0 / (2 * PRIOR_HALF_WIDTH) ** 2


@dataclass
class Mode:
    """One local optimum of the least-squares cost and its Laplace approximation."""

    u: np.ndarray            # unknowns (the fit's space)
    cost: float              # Σ r² (data and weak-prior rows) in q/√12 units
    cov: np.ndarray          # Laplace covariance of u (Gauss–Newton, prior ridge)
    log_evidence: float      # −cost/2 + ½ log det(2π cov): relative Laplace mass
    weight: float = 1.0      # normalised share of the posterior mass (Laplace)
    values: dict[str, float] = field(default_factory=dict)
    #: share of the posterior mass estimated by importance sampling from the pilot
    #: chains (:func:`sample_posterior`); ``None`` without a pilot
    pilot_mass: float | None = None

    def to_dict(self) -> dict[str, Any]:
        return {"cost": self.cost, "weight": self.weight, "log_evidence": self.log_evidence,
                "pilot_mass": self.pilot_mass, "values": dict(self.values)}


@eqx.filter_jit
def _rj(problem: Problem, u):
    return problem.residuals_and_jacobian(u)


@eqx.filter_jit
def _path_costs(problem: Problem, U):
    return jax.vmap(problem.cost)(U)


def _laplace(problem: Problem, u) -> tuple[float, np.ndarray, float]:
    r, J = map(np.asarray, _rj(problem, jnp.asarray(u)))
    cost = float(np.sum(r**2))
    # cost = Σ r² ⇒ −log p = cost/2, Gauss–Newton Hessian JᵀJ.
    H = J.T @ J + _BOX_PRECISION * np.eye(J.shape[1])
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    w = np.clip(w, _BOX_PRECISION, None)
    cov = (V / w) @ V.T
    logdet_cov = -float(np.sum(np.log(w)))
    return cost, cov, -0.5 * cost + 0.5 * logdet_cov + 0.5 * w.size * math.log(2 * math.pi)


def _restart_candidates(fit, rng, n_random: int) -> np.ndarray:
    """Starting vectors around ``fit``: the fit's own starts, Stribeck-shape variants, a
    k1 shift of ±2 sd, and draws from the widened Laplace approximation."""
    prob: Problem = fit.problem
    u0 = np.asarray(fit.u, dtype=float)
    free = list(prob.free)
    specs = prob.base.parameter_specs()
    from ._transforms import to_unconstrained

    def with_values(vals):
        u = u0.copy()
        for n, v in vals.items():
            if n in free and np.isfinite(v) and v > 0:
                u[free.index(n)] = float(to_unconstrained(specs[n], v))
        return u

    cands = [u0]
    st = fit.starts
    for i in range(len(st.costs)):
        if np.isfinite(st.costs[i]) and st.costs[i] - st.costs[st.best] < 1e3 and i != st.best:
            cands.append(with_values({n: float(v[i]) for n, v in st.values.items()}))
    vals = fit.values
    for fs, fv, fk in ((1.6, 0.2, 1.0), (1.6, 0.2, 0.1), (1.6, 1.0, 1.0), (0.75, 4.0, 1.0),
                       (1.0, 4.0, 1.5), (1.0, 0.2, 1.0), (1.3, 0.5, 0.3)):
        v = {}
        if "tau_s" in vals and "tau_c" in vals:
            v["tau_s"] = max(fs * vals["tau_s"], 1.05 * vals["tau_c"])
        if "v_s" in vals:
            v["v_s"] = fv * vals["v_s"]
        if "k2" in vals:
            v["k2"] = fk * vals["k2"]
        cands.append(with_values(v))
    if "k1" in free:
        j = free.index("k1")
        sd = math.sqrt(max(float(fit.covariance[j, j]), 0.0))
        if np.isfinite(sd) and sd > 0:
            for t in (-2.0, 2.0):
                u = u0.copy()
                u[j] += t * sd
                cands.append(u)
    if n_random:
        _, cov, _ = _laplace(prob, u0)
        P = prob.n_physical
        L = np.linalg.cholesky(cov + 1e-12 * np.eye(cov.shape[0]))
        z = rng.standard_normal((n_random, u0.size))
        U = u0 + 1.5 * z @ L.T
        U[:, P:] = u0[P:]  # nuisances stay; the physical part explores
        lim = u0[:P] + np.clip(U[:, :P] - u0[:P], -3.0, 3.0)
        U[:, :P] = lim
        cands += list(U)
    return np.array(cands)


#: Restarts drawn from the widened Laplace approximation in :func:`find_modes`. 30 instead
#: of 6 found more optima (paper log 1007 with seed 0: the one nearest the truth, which 6
#: missed; with seed 7 not) but did not change the coverage on 14 paper logs (95 %
#: intervals 86 % vs 84 %, band 12/14 both; benchmarks/results/posterior_calibration_paper30.md)
#: and costs ≈ 8 s more per call.
N_RANDOM_RESTARTS = 6


def find_modes(fit, *, n_random: int = N_RANDOM_RESTARTS, seed: int = 0, max_steps: int = 150,
               dchi2_max: float = MODE_DCHI2_MAX) -> list[Mode]:
    """Distinct local optima of the fit's cost near ``fit`` and their Laplace masses.

    Local Levenberg–Marquardt fits (hdid's own, vmapped) are started from the fit's
    optimum, the other starts of the fit's multi-start, Stribeck-shape variants (static
    friction ×0.75–1.6, Stribeck velocity ×0.2–4, k2 ×0.1–1.5), k1 ± 2 sd and
    ``n_random`` draws from the widened Laplace approximation. Optima within
    ``dchi2_max`` of the best are merged when a straight path between them rises less
    than ``MODE_BARRIER``, and each remaining one is weighted by its Laplace evidence.
    Sorted by weight, largest first.
    """
    from . import _fit as fitmod

    prob: Problem = fit.problem
    rng = np.random.default_rng(seed)
    U0 = _restart_candidates(fit, rng, n_random)
    U, costs, ok, _ = map(np.asarray, fitmod._solve_many(
        prob, jnp.asarray(U0), jnp.ones(len(U0), dtype=bool), jnp.asarray(fitmod.PHASE1_STEPS)))
    U, costs = np.array(U), np.array(costs)
    costs[~np.isfinite(costs)] = np.inf
    active = (costs - np.min(costs) < 10 * dchi2_max) & ~ok
    used = fitmod.PHASE1_STEPS
    while active.any() and used < max_steps:
        U2, c2, d2, _ = map(np.asarray, fitmod._solve_many(
            prob, jnp.asarray(U), jnp.asarray(active), jnp.asarray(fitmod.PHASE2_CHUNK)))
        U[active], costs[active] = U2[active], np.where(np.isfinite(c2[active]), c2[active], np.inf)
        used += fitmod.PHASE2_CHUNK
        active = active & ~d2 & (costs - np.min(costs) < dchi2_max)
    # the fit's own optimum is always a candidate at its own cost
    keep = np.flatnonzero(costs - np.min(costs) < dchi2_max)
    keep = keep[np.argsort(costs[keep])]
    modes: list[Mode] = []
    for i in keep:
        u = U[i]
        cost, cov, logz = _laplace(prob, u)
        merged = False
        for m in modes:
            path = m.u + np.linspace(0.0, 1.0, 9)[:, None] * (u - m.u)
            pc = np.asarray(_path_costs(prob, jnp.asarray(path)))
            if np.all(np.isfinite(pc)) and np.max(pc) - max(cost, m.cost) < MODE_BARRIER:
                merged = True
                break
        if not merged:
            modes.append(Mode(u=u, cost=cost, cov=cov, log_evidence=logz,
                              values=prob.values_np(u)))
    lz = np.array([m.log_evidence for m in modes])
    w = np.exp(lz - lz.max())
    w /= w.sum()
    for m, wi in zip(modes, w):
        m.weight = float(wi)
    return sorted(modes, key=lambda m: -m.weight)



# ----------------------------------------------------------------------------- proposal


class MixtureProposal:
    """Independence Metropolis–Hastings proposal: a mixture of multivariate t's.

    One component per posterior mode (mean, covariance, weight); used through
    ``emcee.moves.MHMove(proposal)``. It proposes every walker afresh from the mixture,
    wherever it is, so walkers jump between modes (and across a curved ridge) in one
    step; the Hastings factor ``log q(x) − log q(x')`` keeps the chain exact for any
    mixture, so a poor one costs acceptance, never correctness. Student-t tails
    (``nu`` degrees of freedom) are heavier than the posterior's, which keeps the
    importance ratio bounded. Adapt it (:meth:`refit`) during the burn-in only.
    """

    def __init__(self, means, covs, weights, nu: float = 8.0):
        self.means = np.atleast_2d(np.asarray(means, dtype=float))
        self.covs = np.asarray(covs, dtype=float).reshape(len(self.means), *self.means.shape[1:] * 2)
        w = np.clip(np.asarray(weights, dtype=float), 1e-12, None)
        self.weights = w / w.sum()
        self.nu = float(nu)
        D = self.means.shape[1]
        self.chols = np.array([np.linalg.cholesky(c + 1e-12 * np.trace(c) / D * np.eye(D))
                               for c in self.covs])
        from scipy.special import gammaln

        self._linv = np.array([np.linalg.inv(L) for L in self.chols])
        self._lognorm = (gammaln(0.5 * (self.nu + D)) - gammaln(0.5 * self.nu)
                         - 0.5 * D * math.log(self.nu * math.pi)
                         - np.sum(np.log(np.diagonal(self.chols, axis1=1, axis2=2)), axis=1))

    @property
    def ndim(self) -> int:
        return self.means.shape[1]

    def component_logpdf(self, X) -> np.ndarray:
        """``(N, K)``: log weight + log density of each component."""
        X = np.atleast_2d(X)
        D = self.ndim
        # (X − μ_k) L_k⁻ᵀ for every component at once (plain matmuls: this runs at every
        # independence step, so no per-call scipy overhead)
        Z = np.einsum("kij,nkj->nki", self._linv, X[:, None, :] - self.means[None])
        m = np.sum(Z * Z, axis=2)
        return (np.log(self.weights) + self._lognorm)[None] - 0.5 * (self.nu + D) * np.log1p(m / self.nu)

    def logpdf(self, X) -> np.ndarray:
        c = self.component_logpdf(X)
        top = np.max(c, axis=1)
        return top + np.log(np.sum(np.exp(c - top[:, None]), axis=1))

    def sample(self, n: int, random) -> np.ndarray:
        k = random.choice(len(self.weights), size=n, p=self.weights)
        z = random.standard_normal((n, self.ndim))
        g = random.chisquare(self.nu, size=n) / self.nu
        return self.means[k] + np.einsum("nij,nj->ni", self.chols[k], z) / np.sqrt(g)[:, None]

    def __call__(self, coords, random):
        new = self.sample(coords.shape[0], random)
        return new, self.logpdf(coords) - self.logpdf(new)

    def refit(self, X, shrink: float = 20.0, iterations: int = 3) -> MixtureProposal:
        """A mixture fitted to draws ``X`` (EM from this one; covariances shrunk towards
        the current ones with ``shrink`` pseudo-draws; weights kept if a component gets
        no draws)."""
        X = np.asarray(X, dtype=float)
        means, covs, weights = self.means.copy(), self.covs.copy(), self.weights.copy()
        cur = self
        for _ in range(iterations):
            lg = cur.component_logpdf(X)
            r = np.exp(lg - lg.max(axis=1, keepdims=True))
            r /= r.sum(axis=1, keepdims=True)
            nk = r.sum(axis=0)
            for k in range(len(weights)):
                if nk[k] < 2.0:
                    continue
                mu = (r[:, k] @ X) / nk[k]
                d = X - mu
                S = (r[:, k, None] * d).T @ d / nk[k]
                covs[k] = (nk[k] * S + shrink * self.covs[k]) / (nk[k] + shrink)
                means[k] = mu
            total = nk.sum()
            if total > 0:
                weights = np.where(nk >= 2.0, nk / total, self.weights * 0.5)
            cur = MixtureProposal(means, covs, weights, self.nu)
        return cur


def tau_pooled(chain: np.ndarray, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time per dimension with the ACF about the *ensemble*
    mean (emcee centres each walker on its own mean, which hides walkers that sit in
    different modes and never swap: this estimate does not).

    ``chain`` is ``(steps, walkers, D)``; Sokal's automatic window as in emcee.
    """
    n = chain.shape[0]
    m = 1 << (2 * n - 1).bit_length()
    out = np.empty(chain.shape[2])
    for d in range(chain.shape[2]):
        x = chain[:, :, d] - np.mean(chain[:, :, d])
        f = np.fft.rfft(x, n=m, axis=0)
        acov = np.fft.irfft(f * np.conjugate(f), n=m, axis=0)[:n].mean(axis=1)
        if not acov[0] > 0:
            out[d] = np.nan
            continue
        taus = 2.0 * np.cumsum(acov / acov[0]) - 1.0
        # Sokal's window: the first lag m ≥ c·τ(m); none (emcee would return lag 0): the
        # correlations outlast the chain, τ is at least the whole estimate.
        closed = np.flatnonzero(np.arange(n) >= c * taus)
        out[d] = taus[closed[0]] if closed.size else taus[-1]
    return out


def _mode_start(modes, lp_batch, W, rng, sigma_lo, sigma_hi, scale=START_SCALE):
    """Walkers drawn from each mode's Laplace approximation (``scale`` × its width), as
    many per mode as its Laplace weight asks for (largest remainder, at least one for a
    mode of weight ≥ 1/W).

    Full width (``START_SCALE``): an ensemble started narrower than the posterior stays
    too narrow for many autocorrelation times, and with chains that are not 50 τ long
    that under-covers — the calibration with a 0.5 start covered tau_c 5/16 against the
    least-squares intervals' 14/16. Walkers that land off a ridge are pulled back (zero
    prior density) or re-seeded after the first burn-in stage (stranded). The noise
    ``log σ_n`` starts uniform between its prior floor and the fit's RMS.
    """
    w = np.array([m.weight for m in modes])
    share = w * W
    n = np.floor(share).astype(int)
    n[(n == 0) & (share >= 1.0)] = 1
    while n.sum() < W:
        n[int(np.argmax(share - n))] += 1
    while n.sum() > W:
        n[int(np.argmax(n))] -= 1
    rows, centres = [], []
    for m, k in zip(modes, n):
        if k == 0:
            continue
        cov = 0.5 * (m.cov + m.cov.T)
        ev, V = np.linalg.eigh(cov)
        L = V * np.sqrt(np.clip(ev, 0.0, None))
        z = rng.standard_normal((k, m.u.size))
        rows.append(m.u + scale * z @ L.T)
        centres.append(np.tile(m.u, (k, 1)))
    D = modes[0].u.size + 1
    P0 = np.empty((W, D))
    P0[:, :-1] = np.concatenate(rows)
    C = np.concatenate(centres)
    P0[:, -1] = rng.uniform(sigma_lo, max(sigma_hi, sigma_lo + 0.5), W)
    lp0 = np.array(lp_batch(P0))  # writable: re-placed walkers are filled in below
    for _ in range(60):
        bad = ~np.isfinite(lp0)
        if not bad.any():
            break
        P0[bad, :-1] = C[bad] + 0.7 * (P0[bad, :-1] - C[bad])
        lp0[bad] = lp_batch(P0[bad])
    return P0, lp0


#: Steps of the per-mode pilot chains (:func:`_pilot`, ``sample_posterior(pilot_steps=)``)
#: as benchmarked; not the default (0): on 4 paper-design logs × 2 sampler seeds the pooled
#: τ went up as often as down (benchmarks/results/posterior_pilot.md).
PILOT_STEPS = 200
#: Draws from the pilot mixture used to estimate the modes' masses by importance sampling.
PILOT_IS_DRAWS = 4000


@dataclass
class _Pilot:
    mixture: MixtureProposal   # one t component per mode, fitted to its pilot chain
    start: np.ndarray          # (W, D) walkers, sampled coordinates
    start_log_prob: np.ndarray
    mass: np.ndarray           # importance-sampling share of the posterior per mode
    ess: float                 # effective sample size of those importance weights
    kept: list                 # indices of the modes a pilot could start in


def _pilot(modes, log_prob, lp, W, rng, seed, steps, sigma_lo, sigma_hi,
           n_is: int = PILOT_IS_DRAWS) -> _Pilot:
    """Local chains in each mode, a mixture fitted to them, the modes' masses by
    importance sampling from it, and start walkers drawn from the pilots in proportion.

    Why: a Gauss–Newton Laplace approximation at an optimum on a kink of the cost (where a
    run's stick sample changes) can be far too wide or too narrow, and its evidence off by
    orders of magnitude. On the shipped paper log the optimum at cost 13.0 got a Laplace
    weight of 0.07 and no draws at all, while chains started in it sit 6.7 higher in
    log p than the main chain (benchmarks/results/posterior_pilot.md). Each pilot is an
    ensemble of ``W`` walkers started from one mode's Laplace approximation and moved by
    differential evolution alone for ``steps`` steps (the first half discarded, stranded
    walkers re-seeded after it); its draws give that component's mean and covariance.
    The masses ``Z_k`` come from ``n_is`` draws of the equal-weight mixture, each importance
    weight ``p(x)/q(x)`` shared among the components by their responsibility for ``x``.
    The main chain's independence move corrects any error in these exactly: they set
    where the walkers start and how often each mode is proposed, not the posterior.
    """
    import emcee

    D = lp.ndim
    means, covs, ends, end_lp, kept = [], [], [], [], []
    for k, m in enumerate(modes):
        U0, l0 = _mode_start([replace(m, weight=1.0)], lambda U: log_prob(lp.to_sampled_np(U)),
                             W, rng, sigma_lo, sigma_hi)
        if not np.all(np.isfinite(l0)):
            continue
        sampler = emcee.EnsembleSampler(
            W, D, log_prob, vectorize=True,
            moves=[(emcee.moves.DEMove(), 0.8), (emcee.moves.DESnookerMove(), 0.2)])
        state = emcee.State(lp.to_sampled_np(U0), log_prob=l0,
                            random_state=np.random.RandomState(seed + 1 + k).get_state())
        state = sampler.run_mcmc(state, steps // 2, skip_initial_state_check=True)
        state, nr = _reset_outliers(state, rng, D)
        if nr:
            state.log_prob = log_prob(state.coords)
        sampler.reset()
        state = sampler.run_mcmc(state, steps - steps // 2, skip_initial_state_check=True)
        X = sampler.get_chain(flat=True)
        means.append(X.mean(axis=0))
        covs.append(np.cov(X, rowvar=False) + 1e-12 * np.eye(D))
        ends.append(np.asarray(state.coords))
        end_lp.append(np.asarray(state.log_prob))
        kept.append(k)
    K = len(means)
    if K == 0:
        raise RuntimeError("could not place the walkers where the posterior is positive")
    mix = MixtureProposal(np.array(means), np.array(covs), np.full(K, 1.0 / K))
    X = mix.sample(n_is, np.random.RandomState(seed))
    n_is = W * max(1, n_is // W)  # whole batches of W: the log-posterior's compiled shape
    X = X[:n_is]
    lw = np.concatenate([log_prob(X[i : i + W]) for i in range(0, n_is, W)]) - mix.logpdf(X)
    c = mix.component_logpdf(X)
    resp = np.exp(c - c.max(axis=1, keepdims=True))
    resp /= resp.sum(axis=1, keepdims=True)
    ok = np.isfinite(lw)
    w = np.where(ok, np.exp(lw - np.max(lw[ok])), 0.0) if ok.any() else np.zeros(n_is)
    mass = (w[:, None] * resp).sum(axis=0)
    ess = float(w.sum() ** 2 / np.sum(w**2)) if w.sum() > 0 else 0.0
    # every mode keeps a floor share (a noisy estimate must not switch a mode off)
    mass = np.clip(mass / mass.sum(), 0.5 / W, None) if mass.sum() > 0 else np.full(K, 1.0 / K)
    mass /= mass.sum()
    mix = MixtureProposal(np.array(means), np.array(covs), mass)
    # start: walkers from each pilot's last positions, as many as its mass asks for
    share = mass * W
    n = np.floor(share).astype(int)
    while n.sum() < W:
        n[int(np.argmax(share - n))] += 1
    rows = [rng.choice(W, size=nk, replace=False) for nk in n]
    start = np.concatenate([ends[k][r] for k, r in enumerate(rows)])
    start_lp = np.concatenate([end_lp[k][r] for k, r in enumerate(rows)])
    return _Pilot(mixture=mix, start=start, start_log_prob=start_lp, mass=mass, ess=ess,
                  kept=kept)


def _fit_mode(fit) -> Mode:
    """The fit's own optimum as the only mode (``modes="fit"``)."""
    cost, cov, logz = _laplace(fit.problem, np.asarray(fit.u, dtype=float))
    return Mode(u=np.asarray(fit.u, dtype=float), cost=cost, cov=cov, log_evidence=logz,
                weight=1.0, values=fit.problem.values_np(fit.u))


class _Counted:
    """An emcee move that counts its proposals and acceptances (per-move diagnostics)."""

    def __init__(self, move, name: str):
        self.move, self.name = move, name
        self.proposed = 0
        self.accepted = 0

    def propose(self, model, state):
        state, accepted = self.move.propose(model, state)
        self.proposed += int(np.size(accepted))
        self.accepted += int(np.sum(accepted))
        return state, accepted

    @property
    def rate(self) -> float:
        return self.accepted / self.proposed if self.proposed else float("nan")


def _move_name(move) -> str:
    import emcee

    if isinstance(move, emcee.moves.MHMove) and isinstance(move.get_proposal, _Adaptive):
        return "independence (mixture)"
    if isinstance(move, emcee.moves.DEMove) and move.gamma0 == 1.0:
        return "DE gamma=1"
    return type(move).__name__


class _Adaptive:
    """Holds the current :class:`MixtureProposal`; swapped between burn-in stages."""

    def __init__(self, mix: MixtureProposal):
        self.mix = mix

    def __call__(self, coords, random):
        return self.mix(coords, random)


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


def _no_start(fit):
    from ._errors import FitError

    return FitError(
        f"{fit.source}: could not place the posterior's walkers where the density is "
        "positive — every start around the least-squares optimum has zero posterior "
        "density, so the fit itself is likely bad: read its warnings, refit (other starts, "
        "fixed parameters) or check the log"
    )


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
    modes="auto",
    linear_prior: tuple[str, ...] = LINEAR_PRIOR,
    sample_linear: tuple[str, ...] = SAMPLE_LINEAR,
    pilot_steps: int = 0,
) -> PosteriorResult:
    """Run emcee from the least-squares optimum (or optima) of ``fit``.

    Modes: with ``modes="auto"`` (default) :func:`find_modes` restarts the local fit
    around ``fit`` and keeps every distinct optimum with its Laplace mass; the walkers
    start spread over them in proportion to that mass, and an independence proposal (a
    mixture of multivariate t's centred on them, :class:`MixtureProposal`) lets walkers
    move between modes with the exact Metropolis–Hastings correction, so the final
    proportions are the posterior's, not the Laplace guesses. ``modes="fit"`` uses the
    fit's optimum only; a list of :class:`Mode` is used as given.

    A burn-in of ``burn_in`` steps is run in two halves; after each the mixture is
    refitted to the walkers' positions (adaptation happens only here) and stranded
    walkers are re-seeded; it is then discarded. The kept chain grows in chunks until it
    is ``MIN_TAU_MULTIPLE`` integrated autocorrelation times long, or runs exactly
    ``n_steps`` steps. τ is the larger of emcee's estimate (each walker about its own
    mean) and :func:`tau_pooled` (about the ensemble mean, which also sees walkers
    that do not move between modes).

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
        Seed of the mode search, the walkers' start and emcee's moves (reproducible).
    progress:
        Show a progress bar (tqdm).
    likelihood:
        ``"interval"`` (quantization-aware), ``"gaussian"`` or ``"auto"`` (Gaussian with
        the ``q²/12`` rounding variance added when the encoder step is known).
    moves:
        emcee moves (a move, a list of moves or of ``(move, weight)``), or a callable
        ``(log_posterior, proposal) -> moves`` for moves that need the
        :class:`LogPosterior` itself; default :func:`default_moves` with the mixture
        proposal. A move with a ``burn_in_update(acceptance, draws)`` method is given its
        acceptance rate and the stage's draws after each burn-in stage (to tune itself;
        never during the kept chain).
    sigma_floor:
        Lower bound of the noise prior in encoder steps (default ``SIGMA_BOUNDS[0]``).
    modes:
        ``"auto"``, ``"fit"`` or a list of :class:`Mode` (see above).
    sample_linear:
        Log-transformed parameters the walkers move in the *value* of (relative to the
        least-squares value) rather than its log; the density carries the Jacobian, so
        only the mixing changes (default ``SAMPLE_LINEAR``; ``()`` for the fit's own
        coordinates). The returned chain and draws are in the fit's coordinates either way.
    pilot_steps:
        With ``N > 0``, run an ``N``-step differential-evolution pilot in each optimum
        first and build the independence proposal, the modes' masses and the start from
        the pilots instead of the Laplace approximations (:func:`_pilot`; e.g.
        ``PILOT_STEPS``). Off by default: it did not shorten τ consistently
        (benchmarks/results/posterior_pilot.md).
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
    specs = prob.base.parameter_specs()
    lin = np.array([1.0 if (n in linear_prior and specs[n].transform == "log") else 0.0
                    for n in prob.free])
    samp = np.array([1.0 if (n in sample_linear and specs[n].transform == "log") else 0.0
                     for n in prob.free])
    lp = LogPosterior(problem=prob, centre=centre, temper=jnp.asarray(temper),
                      quantized=quantized, sigma_bounds=bounds, quant_var=quant_var,
                      linear_prior=jnp.asarray(lin) if lin.any() else None,
                      sample_linear=jnp.asarray(samp) if samp.any() else None)
    D = lp.ndim
    W = n_walkers or max(32, 2 * D)
    if W < 2 * D:
        raise ValueError(f"n_walkers = {W}: emcee needs at least 2 × {D} walkers; raise n_walkers")

    def log_prob(X):
        return np.asarray(lp.batch(X))

    rng = np.random.default_rng(seed)
    q = float(prob.step)
    t_modes = time.perf_counter()
    if isinstance(modes, str):
        if modes == "auto":
            found = find_modes(fit, seed=seed)
        elif modes == "fit":
            found = [_fit_mode(fit)]
        else:
            raise ValueError(f"modes must be 'auto', 'fit' or a list of Mode, not {modes!r}")
    else:
        found = [replace(m) for m in modes]  # weights are re-set below: leave the caller's
    t_modes = time.perf_counter() - t_modes
    # Modes outside the prior box around the fit (±PRIOR_HALF_WIDTH) cannot be sampled.
    P = prob.n_physical
    found = [m for m in found if np.all(np.abs(m.u[:P] - np.asarray(fit.u)[:P]) < PRIOR_HALF_WIDTH)]
    if not found:
        found = [_fit_mode(fit)]
    # Laplace weights under the sampled prior (the fit's cost has the log-flat one).
    lz = np.array([m.log_evidence + float(lin @ (m.u[:P] - np.asarray(fit.u)[:P])) for m in found])
    wz = np.exp(lz - lz.max())
    for m, wi in zip(found, wz / wz.sum()):
        m.weight = float(wi)
    log_lo = math.log(bounds[0] * q)
    log_rms = math.log(max(fit.rms_residual_rad, bounds[0] * q))
    t_pilot = time.perf_counter()
    pilot = None
    if pilot_steps > 0:
        pilot = _pilot(found, log_prob, lp, W, rng, seed, pilot_steps, log_lo + 0.05, log_rms)
        P0, lp0, start_mix = pilot.start, pilot.start_log_prob, pilot.mixture
        found = [replace(found[k], pilot_mass=float(pm)) for k, pm in zip(pilot.kept, pilot.mass)]
        if not np.all(np.isfinite(lp0)):
            raise _no_start(fit)
    else:
        P0, lp0 = _mode_start(found, lambda U: log_prob(lp.to_sampled_np(U)), W, rng,
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
        start_mix = MixtureProposal(means, covs, [m.weight for m in found])
    t_pilot = time.perf_counter() - t_pilot
    proposal = _Adaptive(start_mix)
    if moves is None:
        moves = default_moves(proposal)
    elif callable(moves) and not hasattr(moves, "propose"):
        # a factory for moves that need the log-posterior itself (e.g. gradient-based)
        moves = moves(lp, proposal)
    if not isinstance(moves, list):
        moves = [(moves, 1.0)]
    moves = [m if isinstance(m, tuple) else (m, 1.0) for m in moves]
    counted = [(_Counted(m, _move_name(m)), w) for m, w in moves]
    sampler = emcee.EnsembleSampler(W, D, log_prob, vectorize=True, moves=counted)
    # emcee draws its moves from the state's random state: seeding it makes runs repeatable.
    state = emcee.State(P0, log_prob=lp0, random_state=np.random.RandomState(seed).get_state())
    n_reset = 0
    if burn_in > 0:
        # Burn-in in stages; after each: re-seed stranded walkers, refit the mixture to the
        # walkers' positions, and scale the local DE step towards ~25 % acceptance (emcee's
        # 2.38/√(2D) is tuned for a Gaussian; on this thin curved ridge it accepts < 1 %).
        n_stage = BURN_IN_STAGES if burn_in >= 40 * BURN_IN_STAGES else 1
        sizes = [burn_in // n_stage] * n_stage
        sizes[-1] += burn_in - sum(sizes)
        for h in sizes:
            state = sampler.run_mcmc(state, h, progress=progress, skip_initial_state_check=True)
            state, nr = _reset_outliers(state, rng, D)
            n_reset += nr
            if nr:
                state.log_prob = log_prob(state.coords)
            burn_chain = sampler.get_chain()[h // 2 :].reshape(-1, D)
            proposal.mix = proposal.mix.refit(burn_chain)
            for m, _ in counted:
                inner = m.move
                if hasattr(inner, "burn_in_update") and m.proposed > 0:
                    inner.burn_in_update(m.rate, burn_chain)
                if (isinstance(inner, emcee.moves.DEMove) and inner.gamma0 != 1.0
                        and m.proposed > 0):
                    g = inner.gamma0 if inner.gamma0 is not None else 2.38 / math.sqrt(2 * D)
                    inner.gamma0 = g * float(np.clip(m.rate / 0.25, 0.2, 1.5))
                m.proposed = m.accepted = 0
            sampler.reset()
        for m, _ in counted:
            m.proposed = m.accepted = 0
    total = n_steps or max_steps
    done = 0
    tau = np.full(D, np.nan)
    tau_e = np.full(D, np.nan)
    while done < total:
        step = min(chunk if n_steps is None else total, total - done)
        if n_steps is None and done > 0 and np.all(np.isfinite(tau)):
            # jump straight to the length the current τ asks for (plus 10 %)
            need = int(1.1 * MIN_TAU_MULTIPLE * np.max(tau)) - done
            step = int(min(max(step, need), total - done))
        state = sampler.run_mcmc(state, step, progress=progress, skip_initial_state_check=True)
        done += step
        with np.errstate(invalid="ignore", divide="ignore"):  # a walker that never moved
            tau_e = sampler.get_autocorr_time(tol=0)
        tau = np.fmax(tau_e, tau_pooled(sampler.get_chain()))
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
            f"{n_reset} walker(s) were stranded far below the bulk during the burn-in and "
            "were restarted from good walkers (a minor mode may be under-represented)"
        )
    stuck = acc < 0.25 * np.median(acc)
    if np.any(stuck) or np.any(acc < 0.01):
        warnings.append(
            f"STUCK WALKERS: {int(np.sum(stuck | (acc < 0.01)))} walker(s) accepted far fewer "
            f"moves than the rest (min {np.min(acc):.3f}, median {np.median(acc):.3f}); "
            "intervals may under-cover — check the chains (trace plot)"
        )
    burn = 0
    thin = max(1, int(tau_max / 2))
    chain_s = sampler.get_chain()  # sampled coordinates
    chain = lp.from_sampled_np(chain_s)  # the fit's unknowns u (+ log σ_n)
    draws = lp.from_sampled_np(sampler.get_chain(discard=burn, thin=thin, flat=True))
    # Share of the kept draws in each mode: the mode whose (weighted) Laplace density is
    # highest at the draw (the adapted mixture's components drift, so not those).
    comp = np.argmax(start_mix.component_logpdf(chain_s.reshape(-1, D)), axis=1)
    share = np.bincount(comp, minlength=len(found)) / comp.size
    if len(found) > 1:
        warnings.append(
            f"MULTIMODAL: {len(found)} separate optima of the fit's cost (Laplace weights "
            + ", ".join(f"{m.weight:.2f}" for m in found)
            + ("; pilot masses " + ", ".join(f"{m.pilot_mass:.2f}" for m in found)
               if pilot is not None else "")
            + "; share of the draws " + ", ".join(f"{s:.2f}" for s in share)
            + "); the walkers started in all of them and the independence move lets them "
            "change mode — see `modes` for their parameters"
        )
    # A chain that climbs well above the best mode found has found yet another one.
    grid = np.linspace(log_lo, max(log_rms, log_lo + math.log(2.0)) + 1.0, 25)
    ref = max(float(np.max(log_prob(lp.to_sampled_np(
        np.column_stack([np.tile(m.u, (grid.size, 1)), grid]))))) for m in found)
    best = float(np.max(sampler.get_log_prob()))
    if best > ref + MODE_GAP:
        warnings.append(
            f"MULTIMODAL: the chain reached log p {best - ref:+.1f} above the best optimum "
            "found — the posterior has a mode the search missed; intervals from a chain "
            "that has not mixed between modes are unreliable"
        )
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
        modes=found,
        mode_share=share,
        tau_emcee=np.asarray(tau_e),
        mode_search_s=t_modes,
        move_acceptance={m.name: m.rate for m, _ in counted},
        n_components=len(proposal.mix.weights),
        pilot_ess=pilot.ess if pilot is not None else None,
        pilot_s=t_pilot,
    )


class _RunNames:
    """Adapter giving ``unknown_labels`` the run and set-up names of a FitResult."""

    def __init__(self, fit):
        self.run_names = [r.name for r in fit.runs]
        self.setup_names = list(fit.setups)
