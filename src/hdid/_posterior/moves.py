"""Moves and preconditioning: emcee moves, the independence proposals and the start.

The ensemble moves are differential evolution (local, undo linear correlations) plus
independence Metropolis–Hastings from a proposal fitted to the posterior: at first a
t-mixture over the optima (:class:`MixtureProposal`), refitted during the burn-in. An
independence proposal keeps the chain exact for any proposal (the Hastings factor
``log q(x) − log q(x')``): a poor one costs acceptance, never correctness.
"""

from __future__ import annotations

import math

import numpy as np

#: Walkers start from each mode's Laplace approximation at this multiple of its width.
START_SCALE = 1.0


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

    def __init__(self, means, covs, weights, nu: float = 8.0, frozen=None):
        self.means = np.atleast_2d(np.asarray(means, dtype=float))
        #: components :meth:`refit` leaves as they are (mean, covariance, weight)
        self.frozen = (np.zeros(len(self.means), dtype=bool) if frozen is None
                       else np.asarray(frozen, dtype=bool))
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
        no draws). Frozen components (:attr:`frozen`: the limit fits' regions, which the
        draws may not have reached yet) keep their mean, covariance and weight."""
        X = np.asarray(X, dtype=float)
        means, covs, weights = self.means.copy(), self.covs.copy(), self.weights.copy()
        cur = self
        for _ in range(iterations):
            lg = cur.component_logpdf(X)
            r = np.exp(lg - lg.max(axis=1, keepdims=True))
            r /= r.sum(axis=1, keepdims=True)
            nk = r.sum(axis=0)
            for k in range(len(weights)):
                if nk[k] < 2.0 or self.frozen[k]:
                    continue
                mu = (r[:, k] @ X) / nk[k]
                d = X - mu
                S = (r[:, k, None] * d).T @ d / nk[k]
                covs[k] = (nk[k] * S + shrink * self.covs[k]) / (nk[k] + shrink)
                means[k] = mu
            total = nk.sum()
            if total > 0:
                weights = np.where(nk >= 2.0, nk / total, self.weights * 0.5)
                f = self.frozen
                if f.any():
                    free_w = weights[~f].sum()
                    weights = np.where(f, self.weights, weights * (1.0 - self.weights[f].sum())
                                       / (free_w if free_w > 0 else 1.0))
            cur = MixtureProposal(means, covs, weights, self.nu, self.frozen)
        return cur


def default_moves(proposal=None):
    """emcee moves used by default: differential evolution (+ snooker, mode jumps) and,
    given a :class:`MixtureProposal`, independence Metropolis–Hastings from it.

    Measured on an 18-D Gaussian with the shipped log's least-squares covariance (36
    walkers, 20000 steps): emcee's default stretch move has τ ≈ 250–290 steps, the
    differential-evolution mixture ≈ 65 — the stretch move's efficiency falls with the
    dimension. DE only undoes *linear* correlations and moves walkers locally; the
    paper design's posterior has several modes and curved ridges, which the
    independence proposal crosses in one step (docs/decisions/posterior-moves.md).
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


