"""The log-posterior: likelihood, priors, sampled coordinates and the batched evaluation.

The sampled space is the fit's own unconstrained vector ``u`` (physical parameters in
their transformed space, per-run release instant and start angle, per-set-up offset and
any further per-run unknowns the problem has) plus ``log σ_n``, the encoder noise before
quantization.

Likelihood: an encoder reading ``y`` is the model angle plus Gaussian noise ``σ_n``
(fitted) plus the rounding to the step ``q`` treated as independent uniform noise of
variance ``q²/12`` (Widrow): Gaussian with ``σ² = σ_n² + q²/12``, never below the
quantization floor (the ``q²/12`` term is left out when the encoder step is not known).
Measured on 20 noiseless rounded paper-design logs
(``docs/decisions/interval-likelihood.md``) it puts the truth at 2Δlog L consistent with χ²₇. Each stretch
of identical readings (pre-release hold, stuck tail) carries one observation's weight, as
in the fit (``weight²`` multiplies the log-likelihood). When the fit's residuals are
autocorrelated beyond what i.i.d. noise gives, the log-likelihood is tempered by the
effective-sample-size factor ``(1 − ρ₁)/(1 + ρ₁)``.

Priors (documented defaults, all in the sampled space):
- physical parameters, by default (issue 34, decision (a); :mod:`.priors`): Gaussian in
  the transformed space — log-normal for every positive scale (``k1``, ``k2``, ``tau_c``,
  ``tau_s``, ``c_v``, effects' amplitudes), centred on a scale of the log in hand, 95 % a
  factor 10.5 either way; ``v_s`` and ``delta`` the Stribeck law's physical priors — as
  each effect declares them (``posterior_prior``); a user's ``prior=`` replaces them; the
  orders effects declare (``tau_s ≥ tau_c``: zero density otherwise, :func:`ordered_pairs`).
  A parameter without a Gaussian prior (an ``"identity"`` one, or every positive one with
  ``default_prior="flat"``) has the earlier flat prior: the problem's own rows
  (``Problem.prior_on``, the inertia prior when the inertia is free) times a flat prior in
  the transformed space within ``± PRIOR_HALF_WIDTH`` of the least-squares value, flat in
  the value for the coefficients of terms that may vanish (declared ``flat_in_value``:
  ``k2``, ``c_v``, ``tau_c``; same box) — the flat option, not the default: a log-flat prior gives their "absent" end — no cubic spring, no
  viscous term, the Coulomb limit of the Stribeck law (a Stribeck hump on a viscous
  line) — equal mass per decade down to the box's floor wherever the data cannot exclude
  it (the paper design's k2 → 0; the shipped log's tau_c, flat from 3 mN m to < 10 µN m:
  ``effects/stribeck.py``); the posterior then reports when a chain's interval stops short
  of such an end that the data allow (:mod:`.limits`);
- release instant: uniform on its bracket between samples; start angle flat within
  ±5 encoder steps of its least-squares value; offset and other per-run unknowns flat;
- ``σ_n``: log-uniform between ``0.05 q`` (the simulator's accuracy) and ``20 q``.
"""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _config  # noqa: F401
from .._problems._evaluate import predict_rows
from .._problems._problem import Problem
from .._models._transforms import from_unconstrained

#: Flat prior half-width around the least-squares value in the transformed space
#: (±7 in log ≈ a factor 1000 either way: uninformative but proper).
PRIOR_HALF_WIDTH = 7.0
#: Noise prior bounds, in encoder steps. The floor is the forward model's own accuracy:
#: the simulator's error at the default substep is ≤ 0.042 steps
#: (docs/decisions/simulator-scheme.md); a smaller σ_n would claim the model reproduces
#: readings more exactly than it can compute them.
SIGMA_BOUNDS = (0.05, 20.0)
#: Which log-transformed parameters have a default prior flat in their *value* (not
#: their log) and which the walkers move in their value is declared by each effect's
#: parameters (``Parameter.flat_in_value``, ``Parameter.sample_in_value``: the library
#: declares ``k2``, ``c_v`` and ``tau_c`` flat in value — coefficients of terms that may
#: vanish, whose "absent" end a log-flat prior gives an unbounded volume that pulled the
#: paper design to k2 → 0 and a 92 mrad band, and made the shipped log's tau_c interval
#: one of the box's floor (docs/decisions/tau-c-flat-in-value.md) — and samples ``k1``, ``k2``, ``tau_c``, ``c_v`` in value — the
#: data fix ``k1·d + k2·d³`` and ``τ_c + c_v·v`` as straight lines, bananas in their logs;
#: docs/decisions/posterior-moves.md).
#: Where the fit's RMS residual is beyond the noise bound in steps, σ_n is bounded by this
#: many times the residual instead (a step that does not describe the readings' noise).
NOISE_BOUND_OVER_RMS = 4.0
#: Half-width of the start angle's flat prior around its least-squares value [encoder steps].
START_ANGLE_HALF_WIDTH = 5.0


class LogPosterior(eqx.Module):
    """Vectorised log-posterior over walkers: ``(W, D) -> (W,)``."""

    problem: Problem
    centre: jax.Array
    temper: jax.Array
    sigma_bounds: tuple[float, float] = SIGMA_BOUNDS
    quant_var: float = 0.0
    #: half-width of the start angles' flat prior [their unit, the encoder step]
    start_half_width: float = START_ANGLE_HALF_WIDTH
    #: 1.0 at log-transformed parameters whose prior is flat in the value, not its log
    linear_prior: jax.Array | None = None
    #: 1.0 at log-transformed parameters *sampled* in their value relative to the
    #: least-squares one (``y = exp(u − centre)``, declared ``sample_in_value``); ``None``: the
    #: sampled vector is ``u`` itself
    sample_linear: jax.Array | None = None
    #: ``(3, P)``: mean, sd and on/off (1/0) of a Gaussian prior in the transformed space
    #: of each free physical parameter given one (``sample_posterior(prior=...)``); it
    #: replaces the default prior (box, weak prior, linear prior) of that parameter
    gauss_prior: jax.Array | None = None
    #: ``(K, 2)`` index pairs ``(i, j)`` of free physical parameters with ``value_i ≤
    #: value_j`` imposed (:func:`ordered_pairs`: ``tau_c ≤ tau_s``); ``None``: none
    order: jax.Array | None = None

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
        lp = self._log_prior(u, log_sigma)
        # Gaussian; on a quantized log the rounding error is added as uniform noise of
        # variance q²/12 (Widrow): the total noise never falls below that floor.
        var = jnp.exp(2 * log_sigma) + self.quant_var
        ll = -0.5 * (p.theta - pred) ** 2 / var - 0.5 * jnp.log(2 * jnp.pi * var)
        total = lp + self.temper * jnp.sum(p.weight**2 * ll) + log_jac
        return jnp.where(jnp.isfinite(total) & jnp.isfinite(lp) & inside, total, -jnp.inf)

    def _log_prior(self, u, log_sigma):
        p = self.problem
        P, R = p.n_physical, p.n_runs
        default = jnp.ones(P, dtype=bool)
        lp = 0.0
        if self.gauss_prior is not None:
            mean, sd, on = self.gauss_prior
            default = on <= 0
            z = (u[:P] - mean) / sd
            # normalised, so that the evidence is comparable between priors
            lp += jnp.sum(jnp.where(default, 0.0, -0.5 * z * z - jnp.log(sd)
                                    - 0.5 * jnp.log(2 * jnp.pi)))
        lp += -0.5 * jnp.sum(jnp.where(default, p.prior_residuals(u), 0.0) ** 2)
        if self.linear_prior is not None:
            # flat in x = exp(u): density in u is ∝ exp(u)
            lp += jnp.sum(jnp.where(default, self.linear_prior * (u[:P] - self.centre[:P]), 0.0))
        outside = jnp.any(default & (jnp.abs(u[:P] - self.centre[:P]) > PRIOR_HALF_WIDTH))
        if self.order is not None:
            outside |= jnp.any(u[self.order[:, 1]] < u[self.order[:, 0]])
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
        outside |= jnp.any(jnp.abs(u[i : i + R] - self.centre[i : i + R]) > self.start_half_width)
        return jnp.where(outside, -jnp.inf, lp)

    def batch(self, X):
        """:meth:`log_prob` of every row of ``X`` ``(W, D)`` (NumPy or JAX); the walkers'
        runs are simulated in one loop (:meth:`Problem.predict_many`), not by ``vmap``."""
        return _batch_jit(self, X)


#: Rows per simulation loop in :meth:`LogPosterior.batch` (0: all rows in one loop). The
#: batched simulator integrates until *every* run of the batch has stuck, so one slow row
#: (little friction: it rings for the whole log) makes every row pay for its length; in
#: chunks each loop ends with its own slowest row (docs/decisions/posterior-moves.md).
BATCH_CHUNK = 128


def _batch_rows(lp: LogPosterior, X):
    U, _, inside = jax.vmap(lp.to_u)(X)
    # Rows of zero prior density are not simulated: their runs are replaced by the
    # least-squares optimum's (which sticks within a few samples). The batched loop lasts
    # until its slowest run sticks, and such rows (Stribeck velocity 10⁴ rad/s, static
    # friction near zero: a ring-down over the whole log) made one call of 2000 SMC
    # reference draws cost 4 s instead of 0.4 s (docs/decisions/posterior-moves.md).
    ok = inside & jnp.isfinite(jax.vmap(lp._log_prior)(U, X[:, -1]))
    U_sim = jnp.where(ok[:, None], U, lp.centre[None, :])
    out = jax.vmap(lp._log_prob_given)(X, lp.problem.predict_many(U_sim))
    return jnp.where(ok, out, -jnp.inf)


def _batch(lp: LogPosterior, X):
    n, c = X.shape[0], BATCH_CHUNK
    if c <= 0 or n <= c:
        return _batch_rows(lp, X)
    k = -(-n // c)
    Xp = jnp.concatenate([X, jnp.broadcast_to(X[:1], (k * c - n, X.shape[1]))]) if k * c > n else X
    out = jax.lax.map(lambda Xc: _batch_rows(lp, Xc), Xp.reshape(k, c, X.shape[1]))
    return out.reshape(-1)[:n]


# Plain jax.jit, not eqx.filter_jit: every leaf of a LogPosterior is an array or a float,
# and jax.jit's dispatch is 0.2 ms faster per call (0.54 vs 0.74 ms for 18 walkers), a
# fifth of the call at emcee's two calls per step.
_batch_jit = jax.jit(_batch)


@eqx.filter_jit
def _derived_batch(problem: Problem, X):
    def one(x):
        return problem.derived(x[:-1])

    return jax.vmap(one)(X)


#: Rows per call of :func:`derived_np` (one compiled shape, whatever the number of draws).
DERIVED_BLOCK = 4096


def derived_np(problem: Problem, X) -> dict[str, np.ndarray]:
    """Derived quantities of every row of ``X`` ``(N, D)`` (unknowns, then ``log σ_n``), in
    padded blocks of ``DERIVED_BLOCK`` rows so that any ``N`` reuses one compiled program."""
    X = np.asarray(X, dtype=float)
    n = X.shape[0]
    out: dict[str, list] = {}
    for i in range(0, max(n, 1), DERIVED_BLOCK):
        blk = X[i : i + DERIVED_BLOCK]
        k = blk.shape[0]
        if k < DERIVED_BLOCK:
            blk = np.concatenate([blk, np.repeat(X[:1], DERIVED_BLOCK - k, axis=0)])
        for name, v in _derived_batch(problem, jnp.asarray(blk)).items():
            out.setdefault(name, []).append(np.asarray(v)[:k])
    return {name: np.concatenate(v) for name, v in out.items()}


_predict_batch = predict_rows  # predictions of every row (unknowns, then log σ_n)


def to_physical(problem: Problem, flat: np.ndarray) -> dict[str, np.ndarray]:
    """Free physical parameter values of each row of ``flat`` (unknowns first)."""
    specs = problem.base.parameter_specs()
    return {n: np.asarray(from_unconstrained(specs[n], flat[:, i], np), dtype=float)
            for i, n in enumerate(problem.free)}


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


class PosteriorDensity(NamedTuple):
    """The log-posterior of a fit as both samplers build it, with what they report."""

    lp: LogPosterior
    warnings: list
    temper: float
    rho1: float
    lin: np.ndarray
    bounds: tuple[float, float]
    u_fit: np.ndarray


def gaussian_prior(problem: Problem, prior: dict | None, default: str = "weak",
                   exclude: tuple[str, ...] = ()):
    """``(3, P)`` array (mean, sd, on) of the Gaussian priors in the transformed space —
    the defaults (:func:`~hdid._posterior.priors.default_priors`: ``default="weak"``, the
    log-normal priors around the log's scales; ``"flat"``, the effects' tuple priors only)
    with the user's ``prior`` in place of those it names — and the ordered pairs
    (:func:`ordered_pairs`, imposed with or without a prior of the user's). ``on`` is 2 for
    a user's prior, 1 for a default one, 0 for a flat one (the mode search also starts
    from draws of the user's priors, :func:`~hdid._posterior.modes.with_user_prior`).
    ``prior`` maps a free physical parameter's name to ``(centre value, sd)``: the centre
    in the parameter's unit, the sd in its transformed space — log for positive
    parameters (a log-normal: 0.2 is ±20 %), logit of the interval for ``delta``.
    ``exclude``: names whose default prior is left flat (an explicit ``linear_prior``).
    ``(None, ordered pairs)`` when no parameter has a Gaussian prior."""
    from .priors import default_priors, with_user

    free = list(problem.free)
    prior = dict(prior or {})
    unknown = [n for n in prior if n not in free]
    if unknown:
        from .errors import PosteriorError

        raise PosteriorError(f"the prior (prior= / --prior NAME=VALUE,SD) names {unknown}, "
                             f"not free physical parameters of this fit (free: {free})")
    for n, (centre, sd) in prior.items():
        if not (np.isfinite(centre) and np.isfinite(sd) and sd > 0):
            from .errors import PosteriorError

            raise PosteriorError(f"the prior of {n} (prior= / --prior {n}=VALUE,SD) is "
                                 f"{(centre, sd)}: give a finite centre and an sd > 0")
    specs = with_user(default_priors(problem, default), problem, prior)
    G = np.zeros((3, len(free)))
    G[1] = 1.0
    for i, n in enumerate(free):
        p = specs[n]
        if np.isfinite(p.mean) and (n in prior or n not in exclude):
            G[:, i] = p.mean, p.sd, 2.0 if n in prior else 1.0
    return (G if G[2].any() else None), ordered_pairs(problem)


def ordered_pairs(problem: Problem) -> np.ndarray | None:
    """``(K, 2)`` indices ``(i, j)`` into the free physical parameters of every pair an
    effect declares ordered (``AbstractEffect.ordered``, e.g. Stribeck's ``tau_c ≤
    tau_s``: breakaway at least Coulomb friction), both free and log-transformed (then
    the order of the values is the order of the sampled logs); ``None`` if there is none.
    The posterior gives the other side zero density."""
    specs = problem.base.parameter_specs()
    free = list(problem.free)
    pairs = [(free.index(a), free.index(b))
             for e in problem.base.effects for a, b in e.ordered
             if a in free and b in free
             and specs[a].transform == "log" and specs[b].transform == "log"]
    return np.array(pairs, dtype=int).reshape(-1, 2) if pairs else None


def declared(specs, flag: str) -> tuple[str, ...]:
    """Names whose declaration sets ``flag`` (``"flat_in_value"``, ``"sample_in_value"``)."""
    return tuple(n for n, s in specs.items() if getattr(s, flag, False))


def posterior_density(fit, sigma_floor=None, linear_prior=None,
                      sample_linear=None, prior=None, default_prior: str = "weak"
                      ) -> PosteriorDensity:
    """:class:`LogPosterior` of ``fit``: tempered by the residuals' lag-1 autocorrelation
    (effective sample size), σ bounded in steps, a flat prior in the value of the
    log-transformed parameters named in ``linear_prior`` and sampling in the value of
    those in ``sample_linear`` (``None``: as the effects declare them, see above); ``prior`` (:func:`gaussian_prior`) replaces the default
    prior of the parameters it names."""
    import math

    prob = fit.problem
    warnings: list[str] = []
    quant_var = float(prob.step) ** 2 / 12.0 if fit.resolution_known else 0.0
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
    # The noise the fit's residual shows bounds σ_n from above, not the step alone: a step
    # far finer than the readings' noise (a wrong --resolution, a grid read from a print
    # unit) would put the residual outside the prior and every walker at zero density.
    step = float(prob.step)
    rms_steps = float(fit.rms_residual_rad) / step if step > 0 else math.inf
    start_half_width = START_ANGLE_HALF_WIDTH
    if math.isfinite(rms_steps) and NOISE_BOUND_OVER_RMS * rms_steps > bounds[1]:
        bounds = (bounds[0], NOISE_BOUND_OVER_RMS * rms_steps)
        if prob.theta0_scale is None:  # start angles in steps: read to the noise, not a step
            start_half_width = START_ANGLE_HALF_WIDTH * max(rms_steps, 1.0)
        warnings.append(
            f"the fit's RMS residual {fit.rms_residual_rad:.3g} rad is {rms_steps:.3g} "
            f"encoder steps of {step:.3g} rad, beyond the noise prior's {SIGMA_BOUNDS[1]:g} "
            f"steps: σ_n is bounded by {NOISE_BOUND_OVER_RMS:g}× the residual instead (the "
            "noise the log shows) — the step looks wrong for this log (pass --resolution "
            "with the encoder's step) or the log is noisier than its encoder"
        )
    u_fit = np.asarray(fit.u, dtype=float)
    specs = prob.base.parameter_specs()
    explicit = tuple(linear_prior or ())
    if linear_prior is None:
        linear_prior = declared(specs, "flat_in_value")
    if sample_linear is None:
        sample_linear = declared(specs, "sample_in_value")
    lin = np.array([1.0 if (n in linear_prior and specs[n].transform == "log") else 0.0
                    for n in prob.free])
    samp = np.array([1.0 if (n in sample_linear and specs[n].transform == "log") else 0.0
                     for n in prob.free])
    G, order = gaussian_prior(prob, prior, default_prior, exclude=explicit)
    if G is not None:
        lin = np.where(G[2] > 0, 0.0, lin)
    lp = LogPosterior(problem=prob, centre=jnp.asarray(u_fit), temper=jnp.asarray(temper),
                      sigma_bounds=bounds, quant_var=quant_var,
                      start_half_width=float(start_half_width),
                      linear_prior=jnp.asarray(lin) if lin.any() else None,
                      sample_linear=jnp.asarray(samp) if samp.any() else None,
                      gauss_prior=None if G is None else jnp.asarray(G),
                      order=None if order is None else jnp.asarray(order))
    return PosteriorDensity(lp, warnings, temper, rho1, lin, bounds, u_fit)


def physical_draws(problem: Problem, model, phys: dict, U: np.ndarray):
    """The draws ``U`` (rows of the fit's unknowns + log σ_n) as the result holds them:
    every parameter of ``model`` by name in physical units (``phys``, from
    :func:`to_physical`; a fixed one at its constant value, so every name is present), and
    the derived quantities with the noise scale ``noise_sigma_rad``."""
    values = model.float_values()
    phys = {n: phys[n] if n in phys else np.full(U.shape[0], values[n]) for n in values}
    der = derived_np(problem, U)
    der["noise_sigma_rad"] = np.exp(U[:, -1])
    return phys, der
