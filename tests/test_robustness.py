"""Logs a real test station produces: flickering counts, noise, no hold."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hdid
from hdid._log import read_log
from hdid._simulation._prepare import prepare
from hdid.reference import logs, stick_band_halfwidth

ROOT = Path(__file__).resolve().parents[1]
TRUTH = logs.TRUTH_CSF8
PAPER = dict(amplitudes=[0.157, -0.157, 0.157, -0.157], fs=250.0, duration=0.5, hold=0.04)


@pytest.fixture(scope="module")
def noisy():
    # 0.3 counts of noise before quantization: the last digit flickers in hold and tail.
    df, info = logs.make_log(TRUTH, PAPER["amplitudes"], PAPER["fs"], PAPER["duration"], PAPER["hold"],
                             {"A": 0.01}, seed=4, noise_std=5e-4, return_truth=True)
    return df, info


def test_release_bracket_survives_flickering_counts(noisy):
    df, info = noisy
    prep = prepare(read_log(df))
    for i, run in enumerate(info["runs"]):
        assert prep.release_lo[i] <= run["t_release"] <= prep.release_hi[i]


def test_noisy_quantized_log_fits_and_bracket_holds_truth(noisy):
    df, _ = noisy
    res = hdid.fit(df)
    k, s = res.derived["k1/inertia"]
    true = TRUTH["k1"] / TRUTH["inertia"]
    # k1/I is fixed by the oscillation frequency: 3 of its own std (≈ 3 %) at most.
    assert abs(k - true) < 3 * s
    # RMS at the noise level: quantization σ_q and 5e-4 rad of noise add in quadrature.
    expected = np.hypot(res.quantization_floor_rad, 5e-4)
    assert 0.5 * expected < res.rms_residual_rad < 1.5 * expected
    # The data bracket of the stick band is physics, not statistics: every rest point is
    # inside the band, every angle it slid on from is outside. It must hold the truth.
    lo, hi = res.band_bracket
    band = stick_band_halfwidth(TRUTH["k1"], TRUTH["k2"], TRUTH["tau_s"], 100.0)
    assert lo <= band <= hi


def test_overflowing_sensitivities_are_a_one_line_fit_error(monkeypatch):
    # A noisy paper log (posterior_sbc seed 40000, sensor noise 1.4 steps) ended its fit
    # with sensitivities of 9e163 in a stuck stretch: finite, but JᵀJ overflows and numpy's
    # eigh raised "Eigenvalues did not converge" (a traceback). The same J planted here
    # (one column ×1e160 at the optimum) must give hdid's one-line FitError instead.
    from hdid._fitting import _fit

    real = _fit._stored_analysis

    def huge(problem, u):
        pre = dict(real(problem, u))
        J, r = map(np.asarray, pre["jacobian"])
        pre["jacobian"] = (J * np.where(np.arange(J.shape[1]) == 0, 1e160, 1.0), r)
        return pre

    monkeypatch.setattr(_fit, "_stored_analysis", huge)
    with pytest.raises(hdid.FitError, match="diverged .*overflowing"):
        hdid.fit(ROOT / "data" / "synthetic" / "csf8_paper.csv", nested=False)
