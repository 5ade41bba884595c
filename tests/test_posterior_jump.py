"""The affine mode-jump move (``_posterior/jump.py``) leaves its target invariant.

Target: a 3-component mixture of correlated Gaussians in 3-D (weights 0.55/0.30/0.15,
modes ~8–10 sd apart). The move's mixture is deliberately wrong: means shifted by ~0.5,
covariances scaled ×2, ×0.5, ×1.5, equal weights, and a fourth component overlapping the
first mode (so the assignment's territories are not the modes': the ``a(x') = j`` check
then matters, as it does between the fit's optimum and the limit fits). The move runs beside a local isotropic
random-walk move (``GaussianMove`` with a *scalar* scale: it draws an independent step per
walker; with a full covariance emcee adds one common step to every walker, which couples
them). Every walker starts in the first mode: the random walk alone cannot cross between
modes in the run, so the mode shares are the jump move's doing.

Tolerance. Both moves update each walker on its own, so the 64 walkers are independent
chains and the per-walker time averages of a statistic are iid: the Monte Carlo standard
error of their mean is ``sd(walker means)/√64`` whatever the autocorrelation inside a
walker (measured: over 30 seeds the z-scores ``(estimate − exact)/MCSE`` had sd 0.84–1.10
from the one-mode start, 0.94–0.96 from the exact start, max |z| 2.6 and 2.9 of 180 each). We require |z| ≤ 5 for six statistics (the mean and
three half-space probabilities, exact from the normal CDF): a false failure has
probability ≈ 6 × P(|t₆₃| > 5) ≈ 3e-5 (the seed is fixed, so the test is deterministic
anyway). Power, checked here (``test_the_check_has_power``) and by editing ``jump.py``
itself (benchmarks/README.md, ``post11``): without the Jacobian term the z-scores reach
~85, without the ``a(x') = j`` check 11–13 (seeds 1–4); without the jump move the walkers
stay in the start's mode (z ~100, or ∞: MCSE 0).
"""

from __future__ import annotations

import hdid

hdid.configure()

import emcee  # noqa: E402
import numpy as np  # noqa: E402
import pytest  # noqa: E402
from scipy.stats import norm  # noqa: E402

from hdid._posterior.jump import ModeJumpMove, mode_jump_moves  # noqa: E402
from hdid._posterior.moves import MixtureProposal  # noqa: E402

D = 3
MU = 2.0 * np.array([[0.0, 0.0, 0.0], [4.0, 1.0, -1.0], [-1.0, 4.5, 2.0]])
W = np.array([0.55, 0.30, 0.15])


def _cov(a, s):
    A = np.array(a, float).reshape(D, D)
    return s * (A @ A.T + 0.3 * np.eye(D))


COV = np.array([_cov([1, .5, 0, 0, 1, .3, .2, 0, 1], 0.5),
                _cov([1, 0, 0, .8, .6, 0, 0, .4, .7], 0.3),
                _cov([.6, 0, 0, 0, 1.2, 0, .5, .5, .5], 0.4)])
_CH = np.linalg.cholesky(COV)
_LI = np.linalg.inv(_CH)
_LD = np.sum(np.log(np.diagonal(_CH, axis1=1, axis2=2)), axis=1)
#: half-spaces a·x > b whose exact probabilities are checked
A = np.array([[1.0, 0, 0], [0, 1, 0], [1, -1, 0.5]])
B = np.array([4.0, 4.4, 0.0])
#: the move's mixture: shifted, rescaled, equal weights, and a fourth component that
#: overlaps the first mode (as the limit fits' components overlap the fit's optimum)
MIX_MEANS = np.vstack([MU + np.array([[0.4, -0.3, 0.2], [-0.5, 0.3, 0.4], [0.3, 0.5, -0.4]]),
                       MU[:1] + np.array([[1.2, 0.6, 0.0]])])
MIX_COVS = np.concatenate([COV * np.array([2.0, 0.5, 1.5])[:, None, None],
                           0.6 * COV[:1]])
Z_MAX = 5.0


def log_target(X):
    Z = np.einsum("kij,nkj->nki", _LI, X[:, None] - MU[None])
    c = np.log(W) - _LD - 0.5 * np.sum(Z * Z, axis=2)
    t = c.max(axis=1)
    return t + np.log(np.exp(c - t[:, None]).sum(axis=1))


def exact_stats():
    p = [sum(W[k] * norm.sf((B[a] - A[a] @ MU[k]) / np.sqrt(A[a] @ COV[k] @ A[a]))
             for k in range(len(W))) for a in range(len(A))]
    return np.concatenate([W @ MU, p])


def chain_z(move_cls, seed=1, n_walkers=64, n_steps=3500, burn=500, w_jump=0.3,
            exact_start=False, **kw):
    """z-scores of the six statistics and the move (None: random walk only); walkers
    start in the first mode, or drawn from the target (``exact_start``)."""
    rng = np.random.default_rng(seed)
    moves = [(emcee.moves.GaussianMove(0.15), 1.0 - w_jump)]
    move = None
    if move_cls is not None:
        move = move_cls(MixtureProposal(MIX_MEANS, MIX_COVS, np.ones(4) / 4), **kw)
        moves.append((move, w_jump))
    k = rng.choice(len(W), n_walkers, p=W) if exact_start else np.zeros(n_walkers, int)
    start = MU[k] + np.einsum("nij,nj->ni", _CH[k], rng.standard_normal((n_walkers, D)))
    s = emcee.EnsembleSampler(n_walkers, D, log_target, vectorize=True, moves=moves)
    s.run_mcmc(emcee.State(start, random_state=np.random.RandomState(seed).get_state()),
               n_steps)
    X = s.get_chain(discard=burn)
    per = np.concatenate([X, (X @ A.T > B).astype(float)], axis=-1).mean(axis=0)
    est = per.mean(axis=0)
    mcse = per.std(axis=0, ddof=1) / np.sqrt(n_walkers)
    return (est - exact_stats()) / mcse, move


def test_mode_jumps_leave_a_mismatched_mixture_target_invariant():
    z, move = chain_z(ModeJumpMove)
    assert np.all(np.abs(z) <= Z_MAX), z
    # it did the work: jumps between the three modes' components, every pair both ways
    assert np.all(move.accepted_pairs[:3, :3] + np.eye(3, dtype=int) > 0), move.accepted_pairs
    # …and the random walk alone, from the same start, is far off (the shares are the jump's)
    with np.errstate(divide="ignore"):  # no walker ever in a half-space: MCSE 0
        z0, _ = chain_z(None, n_steps=1500)
    assert np.max(np.abs(z0)) > 10 * Z_MAX


def test_restricted_to_two_components_still_exact():
    # jumps only between components 0 and 1 (the assignment too): walkers in mode 2 are
    # assigned to 0 or 1 and jump from there. Mode 2 cannot be entered by an accepted jump
    # often, so start from the target itself: invariance is what is checked.
    z, move = chain_z(ModeJumpMove, seed=3, components=[0, 1], exact_start=True)
    assert np.all(np.abs(z) <= Z_MAX), z
    assert move.valid[:, 2].sum() == 0 and move.valid[2].sum() == 0
    assert move.accepted_pairs[0, 1] > 0 and move.accepted_pairs[1, 0] > 0


class _NoJacobian(ModeJumpMove):
    """The move with log factor 0 instead of log|det A_ij|."""

    def _jump(self, coords, random):
        X, f = super()._jump(coords, random)
        return X, np.where(np.isfinite(f), 0.0, f)


class _NoCheck(ModeJumpMove):
    """The move without the ``a(x') = j`` check (otherwise the same code)."""

    def _jump(self, coords, random):
        mix = self.mix
        X = np.asarray(coords, dtype=float)
        i = self.assign(X)
        K = len(mix.weights)
        j = (i + 1 + random.randint(0, K - 1, size=len(X))) % K
        z = np.einsum("nab,nb->na", mix._linv[i], X - mix.means[i])
        Xn = mix.means[j] + np.einsum("nab,nb->na", mix.chols[j], z)
        ld = np.sum(np.log(np.diagonal(mix.chols, axis1=1, axis2=2)), axis=1)
        self._last = (i, j, np.ones(len(X), dtype=bool))
        return Xn, ld[j] - ld[i]


@pytest.mark.parametrize("broken", [_NoJacobian, _NoCheck])
def test_the_check_has_power(broken):
    z, _ = chain_z(broken)
    assert np.max(np.abs(z)) > Z_MAX, z  # measured (seeds 1–4): ~85 and ~12


def test_the_jump_is_an_involution_and_one_component_is_a_no_op():
    mix = MixtureProposal(MIX_MEANS, MIX_COVS, np.ones(4) / 4)
    move = ModeJumpMove(mix)
    rng = np.random.RandomState(0)
    X = MU[rng.randint(0, 3, 200)] + 0.5 * rng.standard_normal((200, D))
    Xn, f = move._jump(X, rng)
    i, j, ok = move._last
    assert ok.mean() > 0.5
    assert np.all(move.assign(Xn[ok]) == j[ok]) and np.all(np.isneginf(f[~ok]))
    # the reverse map from x' to component i lands on x, with the opposite log factor
    z = np.einsum("nab,nb->na", mix._linv[j[ok]], Xn[ok] - mix.means[j[ok]])
    back = mix.means[i[ok]] + np.einsum("nab,nb->na", mix.chols[i[ok]], z)
    np.testing.assert_allclose(back, X[ok], rtol=0, atol=1e-10)
    one = ModeJumpMove(MixtureProposal(MIX_MEANS[:1], MIX_COVS[:1], [1.0]))
    Y, g = one._jump(X, rng)
    assert np.array_equal(Y, X) and np.all(np.isneginf(g))
    base = [(emcee.moves.DEMove(), 1.0)]
    assert mode_jump_moves(base, MixtureProposal(MIX_MEANS[:1], MIX_COVS[:1], [1.0]), 0.1) == base
    out = mode_jump_moves(base, mix, 0.1)
    assert len(out) == 2 and abs(sum(w for _, w in out) - 1.0) < 1e-12
    assert isinstance(out[1][0], ModeJumpMove) and out[1][1] == 0.1
