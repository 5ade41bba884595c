"""emcee after a tempered-SMC pilot — the default of ``sample_posterior`` (issue 17: emcee
stays the engine, preconditioned). On an exact target the pilot's particles and mixture
must leave emcee's stationary distribution alone (the independence move is exact for any
mixture); on the shipped log the default must be that engine and say so. Calibration over
many logs is a benchmark (benchmarks/posterior_sbc.py), not a unit test."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import hdid
from hdid._posterior import sample_posterior
from hdid._posterior.moves import MixtureProposal, pilot_moves
from hdid._posterior.smc import pilot

EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"

#: Exact target: two Gaussians in 3-D, weights 0.2 / 0.8, normalised, modes 12 sd apart
#: (differential evolution alone never crosses between them).
MU = np.array([[0.0, 0.0, 0.0], [12.0, 3.0, -2.0]])
SD = np.array([[1.0, 0.5, 2.0], [0.7, 1.5, 1.0]])
W_TRUE = np.array([0.2, 0.8])


class _Target:
    def batch(self, X):
        X = np.asarray(X)
        comp = [math.log(w) - np.sum(np.log(s)) - 1.5 * math.log(2 * math.pi)
                - 0.5 * np.sum(((X - m) / s) ** 2, axis=1) for w, m, s in zip(W_TRUE, MU, SD)]
        return np.logaddexp(*comp)


def test_emcee_from_the_smc_pilot_keeps_the_exact_target():
    """Pilot from a reference with the wrong weights (0.5 / 0.5, 1.5× too wide); emcee's
    walkers start from its particles and move by the pilot's mixture (independence MH) and
    DE. The heavier mode's share and its mean and sd must be the target's.

    Tolerances: 32 walkers × 1500 kept steps; the independence move accepts ≳ 30 % here
    (measured), so τ ≲ 10 steps and the ESS ≳ 32·1500/10 = 4800: the share's sd
    ≤ √(0.16/4800) ≈ 0.006, 0.03 is ≥ 5 sd; the mode's mean to 4·sd/√(0.8·4800)
    ≈ 0.065 sd, its sd to 10 % (relative se ≈ 1/√(2·3800) ≈ 1.2 %, with margin for τ)."""
    import emcee

    covs = np.array([np.diag((1.5 * s) ** 2) for s in SD])
    ref = MixtureProposal(MU, covs, [0.5, 0.5], nu=5.0)
    tgt = _Target()
    P, mix, info = pilot(tgt, ref, seed=4, n_particles=200, n_runs=2, n_components=4)
    assert P.shape == (400, 3) and info["reached_beta_1"] and info["n_components"] <= 4
    rng = np.random.default_rng(0)
    W = 32
    X0 = P[rng.choice(len(P), W, replace=False)]
    sampler = emcee.EnsembleSampler(W, 3, tgt.batch, vectorize=True, moves=pilot_moves(mix))
    state = emcee.State(X0, log_prob=tgt.batch(X0),
                        random_state=np.random.RandomState(0).get_state())
    state = sampler.run_mcmc(state, 200)  # burn-in
    sampler.reset()
    sampler.run_mcmc(state, 1500)
    X = sampler.get_chain(flat=True)
    assert np.mean(X[:, 0] > 6.0) == pytest.approx(W_TRUE[1], abs=0.03)
    Y = X[X[:, 0] > 6.0]
    np.testing.assert_allclose(Y.mean(axis=0), MU[1], atol=4 * SD[1].max() / math.sqrt(0.8 * 4800))
    np.testing.assert_allclose(Y.std(axis=0), SD[1], rtol=0.10)


@pytest.fixture(scope="module")
def fit():
    return hdid.fit(EXAMPLE)


def test_default_is_emcee_after_an_smc_pilot_and_says_so(fit):
    """The default ``sample_posterior`` is emcee (the user's engine) whose walkers start from
    the SMC pilot's particles, and whose report
    names the engine and the criterion; the same seed gives the same chain. Plumbing only:
    40 particles per run and 30 steps cannot converge, and it must say so."""
    kw = dict(n_steps=30, burn_in=20, n_particles=40, seed=5, modes="fit")
    a = sample_posterior(fit, **kw)
    b = sample_posterior(fit, **kw)
    np.testing.assert_array_equal(a.chain, b.chain)
    d = a.to_dict()["posterior_diagnostics"]
    assert d["method"] == "emcee" and d["smc"]["pilot"] == "smc"
    assert d["smc"]["n_runs"] == 2 and d["smc"]["n_particles"] == 40
    assert "emcee" in d["engine"] and "SMC" in d["engine"]
    assert a.chain.shape[0] == 30 and a.burn_in == 20
    assert "engine: emcee" in a.report() and "R-hat <= 1.01" in a.report()
    assert d["converged"] is False and any("NOT CONVERGED" in w for w in d["warnings"])
    # pilot="modes" is the walkers-from-the-optima start (no SMC pilot)
    c = sample_posterior(fit, n_steps=10, burn_in=0, seed=5, modes="fit", pilot="modes")
    assert c.to_dict()["posterior_diagnostics"]["smc"] == {"pilot": "modes"}
    with pytest.raises(ValueError, match="pilot"):
        sample_posterior(fit, n_steps=10, modes="fit", pilot="flow")
