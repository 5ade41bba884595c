"""Flow preconditioning: emcee's ensemble moves in a normalizing flow's latent space.

A flow ``x = m + L·T(z)`` (``m``, ``L``: mean and Cholesky factor of the training draws;
``T``: a small masked autoregressive flow with rational-quadratic splines, flowjax) is
fitted by maximum likelihood to draws that already cover the posterior. The walkers then
sample ``z`` from ``p(m + L·T(z))·|det ∂x/∂z|`` — the same posterior in other
coordinates, so the chain stays exact whatever the flow; a good flow makes the curved
Stribeck ridge (and the spread between nearby optima) nearly Gaussian there, where
differential evolution mixes in a few tens of steps. The kept chain is mapped back to
``x`` and judged there (arviz, :func:`~hdid._posterior.diagnostics.convergence`).

The flow is fitted (and refitted) only during the burn-in, which is discarded; the kept
chain uses one fixed flow.
"""

from __future__ import annotations

import numpy as np

#: Flow size: autoregressive layers, spline knots, hidden width (one hidden layer).
FLOW_LAYERS = 4
FLOW_KNOTS = 8
FLOW_WIDTH = 32
#: Spline interval in whitened units (identity outside: the tails stay affine).
FLOW_INTERVAL = 5.0
#: Training: at most this many epochs, Adam learning rate, batch size.
FLOW_EPOCHS = 60
FLOW_LR = 2e-3
FLOW_BATCH = 256


class FlowMap:
    """``x = m + L·T(z)`` and its inverse, batched and jitted (float64)."""

    def __init__(self, flow, mean, chol):
        import equinox as eqx
        import jax
        import jax.numpy as jnp

        self.flow = flow
        self.mean = np.asarray(mean, dtype=float)
        self.chol = np.asarray(chol, dtype=float)
        self.logdet_l = float(np.sum(np.log(np.diag(self.chol))))
        m, L = jnp.asarray(self.mean), jnp.asarray(self.chol)
        bij = flow.bijection

        @eqx.filter_jit
        def fwd(b, Z):
            Y, ld = jax.vmap(b.transform_and_log_det)(Z)
            return m + Y @ L.T, ld

        @eqx.filter_jit
        def inv(b, X):
            Y = jax.scipy.linalg.solve_triangular(L, (X - m).T, lower=True).T
            return jax.vmap(b.inverse_and_log_det)(Y)

        self._fwd = lambda Z: fwd(bij, jnp.asarray(Z))
        self._inv = lambda X: inv(bij, jnp.asarray(X))

    def forward(self, Z):
        """``(X, log|det ∂x/∂z|)`` of latent rows ``Z`` ``(n, D)``."""
        X, ld = self._fwd(Z)
        return np.asarray(X), np.asarray(ld) + self.logdet_l

    def inverse(self, X):
        """Latent rows of ``X`` ``(n, D)``."""
        Z, _ = self._inv(X)
        return np.asarray(Z)


def fit_flow(X, seed: int = 0, *, layers: int = FLOW_LAYERS, knots: int = FLOW_KNOTS,
             width: int = FLOW_WIDTH, epochs: int = FLOW_EPOCHS, init: FlowMap | None = None,
             kind: str = "coupling", dedupe: bool = True):
    """A :class:`FlowMap` fitted to draws ``X`` ``(n, D)`` (whitened by their own mean and
    covariance first); ``init``: start from that flow (its whitening kept)."""
    import jax
    import jax.numpy as jnp
    from flowjax.bijections import RationalQuadraticSpline
    from flowjax.distributions import Normal
    from flowjax.flows import coupling_flow, masked_autoregressive_flow
    from flowjax.train import fit_to_data

    X = np.asarray(X, dtype=float)
    X = X[np.all(np.isfinite(X), axis=1)]
    if dedupe:  # resampled clones are not independent draws: a flow fitted to them spikes
        X = np.unique(X, axis=0)
    n, D = X.shape
    if init is not None:
        mean, L, flow = init.mean, init.chol, init.flow
    else:
        mean = X.mean(axis=0)
        S = np.cov(X.T) + 1e-12 * np.eye(D)
        L = np.linalg.cholesky(S + 1e-9 * np.trace(S) / D * np.eye(D))
        make = coupling_flow if kind == "coupling" else masked_autoregressive_flow
        flow = make(
            jax.random.PRNGKey(seed), base_dist=Normal(jnp.zeros(D)),
            transformer=RationalQuadraticSpline(knots=knots, interval=FLOW_INTERVAL),
            flow_layers=layers, nn_width=width)
    Y = np.linalg.solve(L, (X - mean).T).T
    flow, _ = fit_to_data(jax.random.PRNGKey(seed + 1), flow, jnp.asarray(Y),
                          max_epochs=epochs, batch_size=min(FLOW_BATCH, max(32, n // 8)),
                          learning_rate=FLOW_LR, max_patience=8, show_progress=False)
    return FlowMap(flow, mean, L)


def latent_log_prob(log_prob, fmap: FlowMap):
    """``Z -> log p(T(Z)) + log|det ∂x/∂z|`` for emcee (vectorised); non-finite → −∞."""

    def f(Z):
        X, ld = fmap.forward(Z)
        ok = np.all(np.isfinite(X), axis=1) & np.isfinite(ld)
        out = np.full(len(Z), -np.inf)
        if ok.any():
            v = np.asarray(log_prob(np.where(ok[:, None], X, fmap.mean[None])), dtype=float)
            out = np.where(ok & np.isfinite(v), v + ld, -np.inf)
        return out

    return f


class LatentT:
    """Independence proposal in the latent space: a multivariate t at 0 with unit scale
    (an independence move from the flow itself, made heavy-tailed)."""

    def __init__(self, D: int, nu: float = 8.0, scale: float = 1.0):
        self.D, self.nu, self.scale = D, float(nu), float(scale)

    def logpdf(self, Z):
        m = np.sum((Z / self.scale) ** 2, axis=1)
        return -0.5 * (self.nu + self.D) * np.log1p(m / self.nu)

    def __call__(self, coords, random):
        n = coords.shape[0]
        z = random.standard_normal((n, self.D))
        g = random.chisquare(self.nu, size=n) / self.nu
        new = self.scale * z / np.sqrt(g)[:, None]
        return new, self.logpdf(coords) - self.logpdf(new)


def latent_moves(D: int):
    """Differential evolution (+ mode jumps) and a latent t independence move."""
    import emcee

    return [
        (emcee.moves.DEMove(), 0.55),
        (emcee.moves.DEMove(gamma0=1.0), 0.1),
        (emcee.moves.DESnookerMove(), 0.1),
        (emcee.moves.MHMove(LatentT(D)), 0.25),
    ]
