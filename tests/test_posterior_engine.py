"""The default engine of ``sample_posterior`` is emcee (issue 17: the engine the user asked
for); tempered SMC alone is ``method="smc"``. Which one is calibrated over many logs is a
benchmark (benchmarks/posterior_sbc.py), not a unit test."""

from __future__ import annotations

from pathlib import Path

import pytest

import hdid
from hdid._posterior import sample_posterior

EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"


@pytest.fixture(scope="module")
def fit():
    return hdid.fit(EXAMPLE)


def test_default_is_emcee_and_says_which_engine_and_criterion(fit):
    """Without ``method`` the draws are emcee's walkers (a chain of ``n_steps`` × walkers),
    and the report and JSON name the engine and the convergence criterion. Plumbing only:
    30 steps cannot converge, and it must say so."""
    post = sample_posterior(fit, n_steps=30, burn_in=0, seed=5, modes="fit")
    d = post.to_dict()["posterior_diagnostics"]
    assert d["method"] == "emcee" and "emcee" in d["engine"]
    assert post.chain.shape[0] == 30 and post.chain.shape[1] >= 2 * post.chain.shape[2]
    assert "engine: emcee" in post.report() and "R-hat <= 1.01" in post.report()
    assert d["converged"] is False and any("NOT CONVERGED" in w for w in d["warnings"])
    # emcee's options with the SMC are refused, naming the default
    with pytest.raises(ValueError, match="method='emcee'"):
        sample_posterior(fit, method="smc", n_steps=30, modes="fit")


def test_emcee_leaves_out_the_ridge_starts_and_smc_keeps_them(fit):
    """Starts down the Coulomb ridge (``modes.seek_ridges``) stall emcee's walkers, which
    keep their starts (shipped paper log: R-hat 1.116 with them, 1.053 without, after
    20 000 steps; benchmarks/results/posterior_sbc.md); SMC reweights them away. Given a
    ridge start, emcee's modes leave it out and the SMC's mode list keeps it."""
    from dataclasses import replace

    import numpy as np

    from hdid._posterior.modes import _fit_mode, sampled_modes

    m = _fit_mode(fit)
    i = list(fit.problem.free).index("tau_c")
    u = m.u.copy()
    u[i] -= 0.5  # down the ridge: tau_c × 0.6
    ridge = replace(m, u=u, kind="ridge:tau_c")
    post = sample_posterior(fit, n_steps=30, burn_in=0, seed=5, modes=[m, ridge])
    assert [x.kind for x in post.modes] == ["optimum"]
    kept = sampled_modes(fit, [m, ridge], 0, np.asarray(fit.u),
                         np.zeros(fit.problem.n_physical), ridges=True)
    assert [x.kind for x in kept] == ["optimum", "ridge:tau_c"]
