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


def test_smc_weighs_modes_and_estimates_the_evidence():
    """The reference mixture has the right places but the wrong weights (0.5 / 0.5) and is
    1.5× too wide; the random walk cannot cross between modes, so the 0.2 / 0.8 split can
    only come from the tempering weights, and log Z = 0 from their running product.

    Tolerances: 4 runs × 400 particles; the share of a mode in one run has a binomial sd
    √(0.16/400) = 0.02, inflated by resampling (measured over 8 seeds: between-run sd 0.012–0.037), so the
    pooled share's sd is ≤ 0.04/√4 = 0.02: 0.06 is 3 sd or more. log Z: tolerance 4 × the runs'
    own standard error (sd/√4), floored at 0.02 (four runs' sd can come out tiny)."""
    covs = np.array([np.diag((1.5 * s) ** 2) for s in SD])
    ref = MixtureProposal(MU, covs, [0.5, 0.5], nu=5.0)
    X, anc, log_z, steps = run_smc_np(_Target(), ref, n_particles=400, n_runs=4, seed=1)
    assert X.shape == (4, 400, 3) and anc.shape == (4, 400)
    assert all(st["beta"] == [1.0] * 4 for st in steps[-1:])
    share = np.mean(X[..., 0] > 6.0)
    assert share == pytest.approx(W_TRUE[1], abs=0.06)
    se = max(np.std(log_z, ddof=1) / 2.0, 0.005)
    assert abs(np.mean(log_z)) <= 4 * se + 0.02
    # within the heavier mode: its mean and sd (400·4·0.8 ≈ 1280 particles, ESS ≥ ~300:
    # the mean's se ≤ sd/√300 ≈ 0.06 sd, the sd's relative se ≤ 0.04; 4 se)
    Y = X[X[..., 0] > 6.0]
    np.testing.assert_allclose(Y.mean(axis=0), MU[1], atol=4 * 0.06 * SD[1].max())
    np.testing.assert_allclose(Y.std(axis=0), SD[1], rtol=0.16)


@pytest.fixture(scope="module")
def small_smc():
    """A deliberately small SMC on the shipped log (plumbing, not convergence)."""
    from pathlib import Path

    import hdid

    log = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"
    from hdid._posterior.smc import sample_smc

    fit = hdid.fit(log)
    return sample_smc(fit, n_particles=60, modes="fit", seed=2, max_rounds=12)


def test_smc_result_reports_runs_evidence_and_convergence(small_smc):
    post = small_smc
    d = post.to_dict()["posterior_diagnostics"]
    assert d["method"] == "smc" and post.chain.shape[:2] == (60, 4)
    z = d["smc"]["log_evidence"]
    assert len(z) == 4 and np.all(np.isfinite(z))
    conv = d["convergence"]
    assert "stick_band_halfwidth_rad" in conv["per_quantity"]
    # 60 particles × 4 runs = 240 draws cannot reach ESS 400: it must say so, with the fix
    assert d["converged"] is False
    assert any("NOT CONVERGED" in w and "n_particles" in w for w in d["warnings"])
    assert "tempered SMC" in post.report()


def test_corner_has_units_no_offset_text_the_optimum_and_the_verdict(small_smc):
    """k2 is ~5e7 and the band ~0.05: matplotlib's offset text ("1e7") overlapped between
    panels; the power of ten goes into the label instead, with the unit."""
    import matplotlib

    matplotlib.use("Agg")
    fig = small_smc.plot_corner()
    fig.canvas.draw()
    offsets = [t for ax in fig.axes for t in (ax.xaxis.get_offset_text().get_text(),
                                              ax.yaxis.get_offset_text().get_text()) if t]
    assert offsets == []
    labels = [ax.get_xlabel() for ax in fig.axes if ax.get_xlabel()]
    assert any(lbl.startswith("k2") and "10^{7}" in lbl and "N" in lbl for lbl in labels)
    assert any("rad" in lbl for lbl in labels)
    texts = [t.get_text() for t in fig.texts] + [
        t.get_text() for lg in fig.legends for t in lg.get_texts()]
    assert "least-squares optimum" in texts
    assert any(t.startswith("NOT CONVERGED") for t in texts)


def test_predictive_has_a_residual_row_in_encoder_steps(small_smc):
    import matplotlib

    matplotlib.use("Agg")
    R = len(small_smc.fit.runs)
    fig = small_smc.plot_predictive(n_draws=20)
    assert len(fig.axes) == 2 * R
    assert fig.axes[R].get_ylabel() == "residual [encoder steps]"
    # the band on the residual scale is visible: wider than a tenth of a step somewhere
    coll = fig.axes[R].collections[0].get_paths()[0].vertices[:, 1]
    assert np.ptp(coll) > 0.1
    with pytest.raises(ValueError, match=r"\(2, 4\)"):
        small_smc.plot_predictive(n_draws=5, axes=np.empty(3, dtype=object))
