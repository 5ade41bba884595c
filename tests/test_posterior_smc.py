"""Tempered SMC (``hdid._posterior.smc``) on a target whose answer is known exactly, and its
plumbing on the shipped log. Its calibration over many logs is a benchmark
(benchmarks/posterior_sbc.py --method smc), not a unit test."""

from __future__ import annotations

import math

import numpy as np
import pytest

from hdid._posterior import MixtureProposal
from hdid._posterior.smc import run_smc_np

#: Exact target: two Gaussians in 3-D, weights 0.2 / 0.8, normalised (log Z = 0), modes 12
#: sd apart (a random walk never crosses: the weights must come from the importance weights).
MU = np.array([[0.0, 0.0, 0.0], [12.0, 3.0, -2.0]])
SD = np.array([[1.0, 0.5, 2.0], [0.7, 1.5, 1.0]])
W_TRUE = np.array([0.2, 0.8])


class _Target:
    """Stands in for a LogPosterior: ``batch(X)`` is the exact log-density."""

    def batch(self, X):
        X = np.asarray(X)
        comp = [math.log(w) - np.sum(np.log(s)) - 1.5 * math.log(2 * math.pi)
                - 0.5 * np.sum(((X - m) / s) ** 2, axis=1) for w, m, s in zip(W_TRUE, MU, SD)]
        return np.logaddexp(*comp)


def _wrong_weights_reference():
    """The modes' places, the wrong weights (0.5 / 0.5) and 1.5× their widths."""
    covs = np.array([np.diag((1.5 * s) ** 2) for s in SD])
    return MixtureProposal(MU, covs, [0.5, 0.5], nu=5.0)


def _check_weights_evidence_and_moments(X, log_z):
    """The heavier mode's share, log Z = 0, and that mode's mean and sd (tolerances in the
    first test's docstring; within the mode 400·4·0.8 ≈ 1280 particles, ESS ≥ ~300: the
    mean's se ≤ sd/√300 ≈ 0.06 sd, the sd's relative se ≤ 0.04; 4 se)."""
    share = np.mean(X[..., 0] > 6.0)
    assert share == pytest.approx(W_TRUE[1], abs=0.06)
    se = max(np.std(log_z, ddof=1) / 2.0, 0.005)
    assert abs(np.mean(log_z)) <= 4 * se + 0.02
    Y = X[X[..., 0] > 6.0]
    np.testing.assert_allclose(Y.mean(axis=0), MU[1], atol=4 * 0.06 * SD[1].max())
    np.testing.assert_allclose(Y.std(axis=0), SD[1], rtol=0.16)


def test_smc_weighs_modes_and_estimates_the_evidence():
    """The reference mixture has the right places but the wrong weights (0.5 / 0.5) and is
    1.5× too wide; the random walk cannot cross between modes, so the 0.2 / 0.8 split can
    only come from the tempering weights, and log Z = 0 from their running product.

    Tolerances: 4 runs × 400 particles; the share of a mode in one run has a binomial sd
    √(0.16/400) = 0.02, inflated by resampling (measured over 8 seeds: between-run sd 0.012–0.037), so the
    pooled share's sd is ≤ 0.04/√4 = 0.02: 0.06 is 3 sd or more. log Z: tolerance 4 × the runs'
    own standard error (sd/√4), floored at 0.02 (four runs' sd can come out tiny)."""
    ref = _wrong_weights_reference()
    X, anc, log_z, steps = run_smc_np(_Target(), ref, n_particles=400, n_runs=4, seed=1)
    assert X.shape == (4, 400, 3) and anc.shape == (4, 400)
    assert all(st["beta"] == [1.0] * 4 for st in steps[-1:])
    _check_weights_evidence_and_moments(X, log_z)


def test_independence_moves_with_kmeans_mixture_keep_the_target():
    """The same exact target with the run's mixture started from k-means (4 components, not
    the two modes) and independence moves: weights and per-mode moments as above (same
    tolerances); the IMH proposal is exact whatever the mixture, so only efficiency may
    change. With ``check`` always true the rounds at β = 1 stop after two passes."""
    ref = _wrong_weights_reference()
    calls = []

    def check(X, anc):
        calls.append(X.shape)
        return True

    X, anc, log_z, steps = run_smc_np(_Target(), ref, n_particles=400, n_runs=4, seed=3,
                                      n_mcmc=6, k_min=4, check=check, final_rounds=1,
                                      max_final=10)
    assert len(calls) == 2 and [st.get("check") for st in steps[-2:]] == [True, True]
    assert all("acceptance_imh" in st for st in steps)
    _check_weights_evidence_and_moments(X, log_z)
