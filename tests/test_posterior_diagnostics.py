"""Posterior diagnostics and reporting: arviz convergence, posterior / prior widths,
progress bars only on a terminal, the public name.

Statistical calibration of the sampler (coverage over many logs) is a benchmark
(benchmarks/posterior_calibration.py), not a unit test.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hdid
from hdid._posterior import PRIOR_HALF_WIDTH, convergence, sample_posterior
from hdid._posterior.diagnostics import prior_sd, width_ratios

EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"


def _ar1(rng, S, W, rho):
    x = np.empty((S, W))
    x[0] = rng.standard_normal(W)
    e = rng.standard_normal((S, W)) * np.sqrt(1 - rho**2)
    for t in range(1, S):
        x[t] = rho * x[t - 1] + e[t]
    return x


def test_convergence_passes_independent_walkers_and_fails_stuck_or_slow_ones():
    """36 walkers × 300 independent draws: ESS ≈ 10 800 ≫ 400 and R-hat ≈ 1 (its sampling
    spread at this size is ~0.002, so 1.01 is 5 spreads away). Walkers that sit in two
    modes 6 sd apart and never swap: R-hat ≫ 1.01. AR(1) walkers with ρ = 0.995 (τ ≈ 400)
    over 300 steps: ESS ≈ 36·300/400 ≈ 27 < 400. Each failure names its quantity."""
    rng = np.random.default_rng(0)
    S, W = 300, 36
    good = rng.standard_normal((S, W, 2))
    c = convergence(good, ["a", "b"])
    assert c.converged and c.rhat.max() < 1.01 and c.ess_bulk.min() > 5000
    stuck = good.copy()
    stuck[:, ::2, 1] += 6.0
    c = convergence(stuck, ["a", "b"])
    assert not c.converged and c.rhat[1] > 1.5 and c.worst[0] == "b"
    slow = np.stack([good[:, :, 0], _ar1(rng, S, W, 0.995)], axis=2)
    c = convergence(slow, ["a", "b"])
    assert not c.converged and c.ess_bulk[1] < 400 and c.worst[0] == "b"
    # a constant quantity (a walker set that never moved) cannot pass
    const = good.copy()
    const[:, :, 0] = 1.0
    assert not convergence(const, ["a", "b"]).converged


@pytest.fixture(scope="module")
def fit():
    return hdid.fit(EXAMPLE)


def test_prior_width_is_the_box_the_linear_prior_or_the_gaussian(fit):
    """Prior sd in the fit's coordinates: flat box ±7 → 14/√12 = 4.04; flat in the value
    (density ∝ eᵘ on the box) → a truncated exponential, sd ≈ 1 (exactly 1 untruncated;
    truncation at 14 changes it by < 1e-4); a weak Gaussian prior inside the box → its own
    sd (the box cuts it only if sd is comparable to 7). Grid of 4001 points: 1e-3 relative."""
    prob = fit.problem
    P = prob.n_physical
    centre = np.asarray(prob.prior_mean, dtype=float).copy()
    on = np.asarray(prob.prior_on, dtype=bool)
    centre[~on] = np.asarray(fit.u)[:P][~on]
    lin = np.zeros(P)
    lin[0] = 1.0 if not on[0] else 0.0
    sd = prior_sd(prob, centre, PRIOR_HALF_WIDTH, lin)
    for i in range(P):
        if on[i]:
            want = float(np.asarray(prob.prior_sd)[i])
            if want < 2.0:
                assert sd[i] == pytest.approx(want, rel=1e-2)
        elif lin[i]:
            assert sd[i] == pytest.approx(1.0, rel=1e-3)
        else:
            assert sd[i] == pytest.approx(14 / np.sqrt(12), rel=1e-3)


def test_width_ratio_tells_measured_from_assumed(fit):
    """Draws 100× narrower than every prior read "measured"; draws as wide as the prior
    of a parameter read "assumed" for it."""
    prob = fit.problem
    P = prob.n_physical
    u = np.asarray(fit.u, dtype=float)
    lin = np.zeros(P)
    psd = prior_sd(prob, u, PRIOR_HALF_WIDTH, lin)
    rng = np.random.default_rng(0)
    draws = u + 0.01 * psd[np.r_[np.arange(P), np.zeros(u.size - P, int)]] * rng.standard_normal((4000, u.size))
    w = width_ratios(prob, draws, u, PRIOR_HALF_WIDTH, lin)
    assert all(v["verdict"] == "measured" for v in w.values())
    draws[:, 0] = u[0] + psd[0] * rng.standard_normal(4000)
    w = width_ratios(prob, draws, u, PRIOR_HALF_WIDTH, lin)
    assert w[prob.free[0]]["verdict"] == "assumed"
    assert w[prob.free[0]]["posterior_over_prior_width"] == pytest.approx(1.0, abs=0.05)


def test_no_progress_bar_unless_stderr_is_a_terminal(fit, capfd):
    """tqdm's carriage-return updates must not reach a redirected stderr (a log file),
    even when progress is asked for (the CLI asks unless -q)."""
    sample_posterior(fit, n_steps=20, burn_in=0, seed=0, modes="fit", progress=True)
    err = capfd.readouterr().err
    assert "\r" not in err and "it/s" not in err


def test_public_api():
    assert hdid.sample_posterior is sample_posterior
    from hdid._posterior import _predict_batch  # noqa: F401  (used by _plot)
