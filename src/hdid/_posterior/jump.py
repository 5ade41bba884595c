"""Affine mode jumps between the independence mixture's components (an emcee move).

Tjelmeland & Hegstad (2001, "Mode jumping proposals in MCMC") with a deterministic
*assignment*: the walker at ``x`` belongs to the component ``i = a(x)`` of the
independence mixture (:class:`~hdid._posterior.moves.MixtureProposal`) whose own
density — its multivariate t, *without* its mixture weight (``use_weights=False``,
default) — is largest at ``x``; ``j`` is drawn uniformly from the other ``K − 1``
components and the walker is proposed at

    x' = T_ij(x) = μ_j + A_ij (x − μ_i),   A_ij = L_j L_i⁻¹

(``L`` the components' Cholesky factors), i.e. at the same whitened offset from ``μ_j``
as ``x`` has from ``μ_i``. The log factor handed to emcee's Metropolis–Hastings step is
``log|det A_ij| = log|det L_j| − log|det L_i|``, and the jump is rejected outright
(factor −∞) unless ``a(x') = j``.

Why it is exact (for any mixture, however badly it matches the posterior ``π``): consider
the extended state ``(x, j)``. The map ``(x, j) ↦ (T_ij(x), i)`` with ``i = a(x)``,
restricted to the pairs with ``a(T_ij(x)) = j``, is an involution: ``T_ji(T_ij(x)) = x``
and ``a(x) = i``, so the reverse jump from ``x'`` draws ``i`` with the same probability
``1/(K−1)`` and lands exactly on ``x``. Detailed balance of the accepted jumps is then

    π(x) · 1/(K−1) · min(1, π(x') |det A_ij| / π(x)) dx
        = π(x') · 1/(K−1) · min(1, π(x) |det A_ji| / π(x')) dx'

which holds because ``dx' = |det A_ij| dx`` and ``det A_ji = 1/det A_ij``. A proposal
with ``a(x') ≠ j`` has no reverse move (from ``x'`` the walker would be assigned
elsewhere and jumped by another map), so it must be rejected: dropping that check, or the
Jacobian, biases the chain (``tests/test_posterior_jump.py`` verifies both fail). The
assignment must be a function of ``x`` alone — deterministic, no random tie-breaking — and
the mixture must not change while the chain is kept: the driver refits it only between
burn-in stages (discarded), and this move reads it at call time (through the driver's
``_Adaptive`` holder) so it follows those refits. emcee's :class:`~emcee.moves.MHMove`
moves every walker independently of the others, so the product kernel leaves the
ensemble's product target invariant. The move alone is not irreducible (from ``x`` it
reaches finitely many points): it is a complement to the local moves, never the only one.

With one component (or one allowed by ``components``) there is nowhere to jump: the move
proposes no change (factor −∞, counted as rejected); :func:`mode_jump_moves` does not add it
at all then.

Which covariances: the mixture's (refitted to the burn-in draws for the optima, the
Laplace ones × ``START_SCALE²`` for the frozen limit fits, log σ_n included), so the
map follows each component's fitted shape. Which components: all, by default — in the
driver every component is a mode (an optimum or a limit fit, ``sampled_modes``);
``components`` restricts the jumps (and the assignment) to a subset.

Measured on the shipped paper log (benchmarks/README.md, issue 17, ``post11``): at 10–20 %
of the steps it is accepted 1.3–2.5 % of the time and adds crossings into the k2 → 0 and
tau_c < 1 mN m regions, but R-hat and τ stay within the seeds' spread (12 seeds), and
restricted to the optima and the limit fits' ends it is almost never accepted (the
regions are far from Gaussian: an affine map between Gaussians fitted to their own draws
is accepted ~1e-9 of the time). Not used by :func:`~hdid._posterior.moves.default_moves`.
"""

from __future__ import annotations

import numpy as np

try:  # emcee is a dependency of the posterior, imported lazily by the driver
    from emcee.moves import MHMove
except ImportError:  # pragma: no cover
    MHMove = object


class ModeJumpMove(MHMove):
    """emcee move: affine jumps between a :class:`MixtureProposal`'s components.

    ``source``: the mixture, or an object with a ``.mix`` attribute holding it (the
    driver's ``_Adaptive``), read at every call. ``components``: indices of the components
    to jump among (default all). Counts per pair ``(from, to)`` of proposals that pass
    the assignment check (``valid``) and of accepted jumps (``accepted_pairs``); reset by
    :meth:`burn_in_update` (so after the burn-in they describe the kept chain).
    """

    def __init__(self, source, components=None, use_weights: bool = False):
        self.source = source
        self.components = (None if components is None
                           else np.unique(np.asarray(components, dtype=int)))
        self.use_weights = bool(use_weights)
        super().__init__(self._jump)
        K = len(self.mix.weights)
        self.valid = np.zeros((K, K), dtype=np.int64)
        self.accepted_pairs = np.zeros((K, K), dtype=np.int64)
        self.proposed = 0
        self._last = None

    @property
    def mix(self):
        return getattr(self.source, "mix", self.source)

    def assign(self, X) -> np.ndarray:
        """The component each row of ``X`` belongs to (index into the mixture)."""
        mix = self.mix
        lg = mix.component_logpdf(np.atleast_2d(X))
        if not self.use_weights:
            lg = lg - np.log(mix.weights)[None]
        if self.components is not None:
            return self.components[np.argmax(lg[:, self.components], axis=1)]
        return np.argmax(lg, axis=1)

    def _jump(self, coords, random):
        mix = self.mix
        X = np.asarray(coords, dtype=float)
        n = X.shape[0]
        allowed = np.arange(len(mix.weights)) if self.components is None else self.components
        m = allowed.size
        if m < 2:
            self._last = None
            return X.copy(), np.full(n, -np.inf)
        i = self.assign(X)
        pos = np.searchsorted(allowed, i)  # i's place among the allowed (sorted below)
        j = allowed[(pos + 1 + random.randint(0, m - 1, size=n)) % m]
        z = np.einsum("nab,nb->na", mix._linv[i], X - mix.means[i])
        Xn = mix.means[j] + np.einsum("nab,nb->na", mix.chols[j], z)
        logdet = np.sum(np.log(np.diagonal(mix.chols, axis1=1, axis2=2)), axis=1)
        factor = logdet[j] - logdet[i]
        ok = self.assign(Xn) == j
        Xn[~ok] = X[~ok]  # harmless to evaluate; rejected by the factor
        factor = np.where(ok, factor, -np.inf)
        self._last = (i, j, ok)
        return Xn, factor

    def propose(self, model, state):
        state, accepted = super().propose(model, state)
        if self._last is not None:
            i, j, ok = self._last
            np.add.at(self.valid, (i[ok], j[ok]), 1)
            acc = np.asarray(accepted, dtype=bool) & ok
            np.add.at(self.accepted_pairs, (i[acc], j[acc]), 1)
        self.proposed += int(np.size(accepted))
        return state, accepted

    def burn_in_update(self, acceptance, draws) -> None:
        """Called by the driver after each burn-in stage: reset the counters."""
        K = len(self.mix.weights)
        self.valid = np.zeros((K, K), dtype=np.int64)
        self.accepted_pairs = np.zeros((K, K), dtype=np.int64)
        self.proposed = 0


def mode_jump_moves(base_moves, source, weight: float, **kw):
    """``base_moves`` (a list of ``(move, weight)``) with a :class:`ModeJumpMove` taking
    ``weight`` of the steps (the others scaled to ``1 − weight``); unchanged when the
    mixture has fewer than two components (nothing to jump between)."""
    move = ModeJumpMove(source, **kw)
    allowed = len(move.mix.weights) if move.components is None else move.components.size
    if allowed < 2 or weight <= 0:
        return list(base_moves)
    total = sum(w for _, w in base_moves)
    return [(m, w * (1.0 - weight) / total) for m, w in base_moves] + [(move, weight)]
