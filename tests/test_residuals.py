"""Residual views (:mod:`hdid._results._residuals`): the frame, the whiteness test, features, plots.

Two fits of the committed ``csf8_paper.csv`` (reference simulator, CSF-8 truth, 250 Hz,
4 releases, rounded to a 4000-count encoder, no other noise), shared module-wide:

* ``paper`` — the default model, i.e. the model that generated the log;
* ``no_stribeck`` — ``Model.default().without("stribeck")``: no Coulomb/Stribeck friction,
  only viscous damping, so the model cannot stick at ±0.035 rad as the log does.

Statistical facts used below (``step = 2π/4000``, ``σ_q = step/√12`` the floor):

* The gear stops ~4–5 samples after release at 250 Hz, so there are only ~17 moving
  samples: the whiteness test has little power there, and the fitted residual of a
  correct model is *not* white in the raw sense (mean removal per run and the fit's
  ~4 unknowns per run give a lag-1 ACF ≈ −0.4); ``whiteness`` centres the ACF on what
  the linearised fit predicts for a correct model (``acf_null``).
* For ideal rounding the moving RMS is ≤ σ_q (the fit absorbs part of it).
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import hdid
from hdid._results import _residuals as R

ROOT = Path(__file__).resolve().parent.parent
PAPER_CSV = ROOT / "data" / "synthetic" / "csf8_paper.csv"
STEP = 2 * math.pi / 4000
FLOOR = STEP / math.sqrt(12)
COLUMNS = [
    "run", "setup", "t", "t_since_release", "t_to_stick", "measured", "model",
    "residual_rad", "residual_counts", "theta_wg", "omega", "deflection_out", "phase", "weight",
]


@pytest.fixture(scope="module")
def paper():
    return hdid.fit(PAPER_CSV)


@pytest.fixture(scope="module")
def paper_frame(paper):
    return R.residual_frame(paper)


@pytest.fixture(scope="module")
def no_stribeck():
    # Two starts suffice: the structural error (no stick) is ~20 counts, far beyond any
    # difference between local optima; it keeps the module within its time budget.
    return hdid.fit(PAPER_CSV, model=hdid.Model.default().without("stribeck"), n_starts=2)


@pytest.fixture(scope="module")
def no_stribeck_frame(no_stribeck):
    return R.residual_frame(no_stribeck)


# -- the frame -------------------------------------------------------------------------
def test_frame_has_a_row_per_logged_sample(paper, paper_frame):
    log = pd.read_csv(PAPER_CSV)
    assert list(paper_frame.columns) == COLUMNS
    assert len(paper_frame) == len(log) == sum(r.n_samples for r in paper.runs)
    for run in paper.runs:
        g = paper_frame[paper_frame["run"] == run.name]
        lg = log[log["run"].astype(str) == run.name]
        assert len(g) == run.n_samples
        assert set(g["setup"]) == {run.setup}
        np.testing.assert_array_equal(g["t"].to_numpy(), lg["time"].to_numpy())
        np.testing.assert_array_equal(g["measured"].to_numpy(), lg["theta"].to_numpy())
        assert np.all(np.isfinite(g.drop(columns=["run", "setup", "phase"]).to_numpy(float)))


def test_residual_is_measured_minus_model(paper, paper_frame):
    f = paper_frame
    np.testing.assert_array_equal(f["residual_rad"], f["measured"] - f["model"])
    np.testing.assert_allclose(f["residual_counts"] * paper.resolution_rad, f["residual_rad"],
                               rtol=1e-12, atol=0)
    # The model column is FitResult.predict() (same simulator, same samples).
    pred = paper.predict()
    for i, run in enumerate(paper.runs):
        g = paper_frame[paper_frame["run"] == run.name]
        np.testing.assert_allclose(g["model"], pred[i, : run.n_samples], rtol=0, atol=1e-12)
        # Model angle from the spring zero + the run's offset is the model reading.
        np.testing.assert_allclose(g["theta_wg"] + run.offset, g["model"], rtol=0, atol=1e-12)
        np.testing.assert_allclose(g["deflection_out"], g["theta_wg"] / paper.model.ratio)
    # The frame's weighted RMS is the fit's RMS residual (Σw²r²/Σw²).
    w2 = f["weight"] ** 2
    rms = np.sqrt(np.sum(w2 * f["residual_rad"] ** 2) / np.sum(w2))
    assert rms == pytest.approx(paper.rms_residual_rad, rel=1e-9)


def test_phases_follow_release_and_model_stick(paper, paper_frame):
    dt = paper.sample_period
    stick = R.stick_times(paper)
    for i, run in enumerate(paper.runs):
        g = paper_frame[paper_frame["run"] == run.name]
        t, ph = g["t"].to_numpy(), g["phase"].astype(str).to_numpy()
        assert np.array_equal(ph == "hold", t < run.release_time)
        assert np.array_equal(ph == "stuck", t >= stick[i])
        # Phases come in order hold → moving → stuck, each present on this log.
        order = np.array([R.PHASES.index(p) for p in ph])
        assert np.all(np.diff(order) >= 0) and set(ph) == set(R.PHASES)
        # The model is at θ0 before the release and at its rest point once stuck.
        hold, mov, st = (g[ph == p] for p in R.PHASES)
        np.testing.assert_allclose(hold["theta_wg"], run.theta0, atol=1e-12)
        np.testing.assert_allclose(st["theta_wg"], run.rest_model, rtol=0, atol=1e-12)
        assert g["omega"].abs().max() == pytest.approx(run.peak_speed, rel=1e-12)
        assert np.ptp(st["model"]) == 0.0
        assert np.all(hold["omega"] == 0) and np.all(st["omega"] == 0)
        assert np.all(mov["omega"] != 0)
        # The stick lies between the last moving and the first stuck sample.
        assert 0 <= st["t_to_stick"].iloc[0] < dt
        assert mov["t_to_stick"].iloc[-1] < 0
        np.testing.assert_allclose(g["t_since_release"], t - run.release_time)
        # The fit's weights. Moving samples have full weight except where the fitted
        # release precedes the last sample still at the logged hold reading (the model
        # has started but moved less than a count): those keep the hold's shared weight.
        fit_weight = np.asarray(paper.problem.weight)[i, : run.n_samples]
        np.testing.assert_allclose(g["weight"], fit_weight)
        at_hold = mov["measured"] == g["measured"].iloc[0]
        assert np.all(mov["weight"][~at_hold] == 1.0)


def test_velocity_is_the_model_derivative(paper, paper_frame):
    """ω from the simulator's full output equals a central difference of the model angle."""
    h = 2e-5
    times = np.asarray(paper.problem.times)
    # Interleaved t−h, t+h: the simulator needs non-decreasing times.
    both = np.stack([times - h, times + h], axis=2).reshape(times.shape[0], -1)
    pred = paper.predict(both)
    for i, run in enumerate(paper.runs):
        g = paper_frame[paper_frame["run"] == run.name]
        n = run.n_samples
        fd = (pred[i, 1 : 2 * n : 2] - pred[i, 0 : 2 * n : 2]) / (2 * h)
        mov = (g["phase"] == "moving").to_numpy()
        # The two simulations cut time into different RK4 substeps (≤ 0.5 ms, but t ± h
        # splits every interval): their velocities differ by ≈ 2e-3 of the peak speed
        # near the friction reversals (0.09 of 48 rad/s), the central difference itself
        # only by h²·θ'''/6 ≈ 5e-4 rad/s. 5e-3 of the peak still catches any real
        # mistake (a sample shift or a differenced-data ω is off by tens of rad/s).
        scale = np.max(np.abs(fd[mov]))
        np.testing.assert_allclose(g["omega"].to_numpy()[mov], fd[mov], rtol=0, atol=5e-3 * scale)
    assert paper_frame["omega"].abs().max() > 1.0  # it does move fast (≈ tens of rad/s)


# -- whiteness --------------------------------------------------------------------------
def test_whiteness_correct_model_is_adequate(paper, paper_frame):
    w = paper.whiteness()
    assert w.n == int((paper_frame["phase"] == "moving").sum())
    assert w.max_lag == 1  # min(10, 4 // 4): the shortest run has 4 moving samples
    assert w.band == pytest.approx(1.96 / math.sqrt(w.n), rel=1e-4)
    assert w.floor_rad == pytest.approx(FLOOR)
    assert w.white and w.at_floor and w.adequate, w.to_dict()
    # Under ideal rounding the fitted moving residual is below the floor (rms_null_rad)
    # and the ACF of a correct model is negative at lag 1 (mean removal + fitted
    # release/θ0 per run); both are properties of the fit, not of this log.
    assert w.rms_null_rad < FLOOR
    assert w.acf_null[0] < 0
    json.dumps(w.to_dict())


def test_whiteness_wrong_model_is_not_adequate(no_stribeck):
    w = no_stribeck.whiteness()
    # Without Coulomb friction the model never sticks: every sample after the release is
    # "moving", and the residual is a slow ±20-count drift (the logged rest point).
    assert w.n > 400
    assert not w.adequate and not w.white and not w.at_floor
    assert w.rms_ratio > 10          # ≈ 76: the logged rest is ±0.035 rad ≈ 22 counts
    assert w.p_value < 1e-6          # lag-1 ACF ≈ 0.8 against a band of ±0.09
    assert w.max_lag == 10


def test_whiteness_of_a_frame_has_no_null_correction(paper, paper_frame):
    a, b = paper.whiteness(), R.whiteness(paper_frame)
    np.testing.assert_allclose(a.acf, b.acf)
    assert np.all(b.acf_null == 0) and math.isnan(b.rms_null_rad)
    assert a.rms_ratio == b.rms_ratio


def _fake_frame(residuals: list[np.ndarray], step: float = STEP) -> pd.DataFrame:
    parts = []
    for k, r in enumerate(residuals):
        n = r.size
        parts.append(pd.DataFrame({
            "run": str(k), "t": np.arange(n) * 1e-3, "t_since_release": np.arange(n) * 1e-3,
            "t_to_stick": np.arange(n) * 1e-3 - n * 1e-3, "residual_rad": r,
            "residual_counts": r / step, "theta_wg": np.zeros(n), "omega": np.ones(n),
            "measured": r, "phase": "moving",
        }))
    f = pd.concat(parts, ignore_index=True)
    f.attrs.update(resolution_rad=step, sample_period=1e-3)
    return f


def test_ljung_box_is_calibrated_for_rounding_noise():
    """Uniform rounding errors (the null): the false-alarm rate at α = 0.01 is near 1 %."""
    rng = np.random.default_rng(1)
    reps = 200
    rejected = 0
    ratios = []
    for _ in range(reps):
        f = _fake_frame([rng.uniform(-STEP / 2, STEP / 2, 60) for _ in range(4)])
        w = R.whiteness(f)
        rejected += not w.white
        ratios.append(w.rms_ratio)
    # Binomial(200, 0.01): mean 2, P(X > 8) ≈ 2e-4. The −1/n_i mean-removal bias at
    # n_i = 60 (≈ −0.017 per lag, vs sd 0.065) inflates the rate only slightly.
    assert rejected <= 8
    # RMS ratio of 240 uniform errors: sd ≈ √(0.2/240) = 0.029 → all within 1 ± 0.15,
    # and the at_floor threshold 1.3 is > 10 sd away.
    assert np.all(np.abs(np.array(ratios) - 1) < 0.15)


def test_ljung_box_detects_correlated_residuals():
    rng = np.random.default_rng(2)
    runs = []
    for _ in range(4):
        e = rng.normal(0, FLOOR, 60)
        r = np.zeros(60)
        for t in range(60):  # AR(1), φ = 0.6: lag-1 ACF 0.6 vs band ±0.13
            r[t] = 0.6 * r[t - 1] + e[t] if t else e[t]
        runs.append(r)
    w = R.whiteness(_fake_frame(runs))
    assert not w.white and w.p_value < 1e-6


# -- spectrum ---------------------------------------------------------------------------
def test_spectrum(paper_frame, no_stribeck_frame):
    sp = R.spectrum(paper_frame)
    f, p, lo, hi = sp
    assert f.size == p.size == lo.size == hi.size >= 1
    assert np.all(f > 0) and f.max() <= 125.0 + 1e-9  # up to Nyquist at 250 Hz
    assert np.all(lo < sp.level) and np.all(sp.level < hi)
    # The no-friction residual is a slow drift: the lowest bins (< 10 Hz) all lie above
    # the white-noise band (≈ 5× the white level against a 97.5 % point of 2.2×).
    sw = R.spectrum(no_stribeck_frame)
    low = sw.frequency < 10
    assert low.sum() >= 4 and np.all(sw.power[low] > sw.upper[low])
    # The periodogram integrates to the variance (Parseval, one-sided, zero mean):
    # Σ P·Δf ≈ σ² within the leakage of the N/2 grid (all runs have 114–113 samples).
    df = sw.frequency[1] - sw.frequency[0]
    assert np.sum(sw.power) * df == pytest.approx(sw.level * 125.0, rel=0.05)


# -- features ---------------------------------------------------------------------------
def test_features_of_the_correct_model(paper_frame):
    ft = R.residual_features(paper_frame)
    assert set(ft) >= {
        "corr_sign_omega", "corr_theta", "corr_abs_theta", "corr_omega",
        "near_rest_energy_share", "stuck_mean_counts", "stuck_signed_counts",
        "stuck_sign_agreement", "theta_peak_order", "theta_peak_share", "n_moving",
    }
    # A correct model's rest point is the logged one up to rounding (≤ ½ count).
    assert abs(ft["stuck_mean_counts"]) <= 0.5 and abs(ft["stuck_signed_counts"]) <= 0.5
    for k in ("corr_sign_omega", "corr_theta", "corr_abs_theta", "corr_omega"):
        assert -1 <= ft[k] <= 1
    assert 0 <= ft["near_rest_energy_share"] <= 1
    assert 2 <= ft["theta_peak_order"] <= 300


def test_features_point_at_missing_friction(no_stribeck_frame):
    """Missing Coulomb friction: the model decays to the spring zero, the log stays in the
    stick band on the release side (±0.035 rad ≈ 22 counts, same sign as θ0 on this log).
    The rest-point error is the physically robust signature; the correlations with sign(ω)
    are not (the model still oscillates, with the wrong decay, long after the log rests)."""
    ft = R.residual_features(no_stribeck_frame)
    assert ft["stuck_sign_agreement"] == 1.0
    assert ft["stuck_signed_counts"] > 10  # half the logged |rest| of ~22 counts


def test_features_recover_planted_structure():
    rng = np.random.default_rng(3)
    n = 400
    t = np.arange(n) * 1e-3
    theta = 0.15 * np.cos(2 * np.pi * 20 * t) * np.exp(-5 * t)
    omega = np.gradient(theta, t)
    noise = rng.uniform(-STEP / 2, STEP / 2, n)
    base = pd.DataFrame({
        "run": "1", "t": t, "t_since_release": t, "t_to_stick": t - t[-1] - 1e-3,
        "theta_wg": theta, "omega": omega, "phase": "moving",
    })
    # Friction-like: residual = 1 count × sign(ω).
    f1 = base.assign(residual_rad=STEP * np.sign(omega) + noise)
    f1["residual_counts"] = f1["residual_rad"] / STEP
    f1["measured"] = 0.0
    ft = R.residual_features(f1)
    assert ft["corr_sign_omega"] > 0.9  # signal sd 1 count vs noise 0.29 count
    # Position-periodic (cogging-like) at order 37 per rad.
    f2 = base.assign(residual_rad=STEP * np.sin(37 * theta) + noise)
    f2["residual_counts"] = f2["residual_rad"] / STEP
    f2["measured"] = 0.0
    ft2 = R.residual_features(f2)
    # Grid spacing (300−2)/2999 ≈ 0.1; the peak's width over a 0.3 rad span is ~2π/0.3.
    assert ft2["theta_peak_order"] == pytest.approx(37, abs=1.0)
    assert ft2["theta_peak_share"] > 0.8  # variance 0.5 vs noise 1/12: share ≈ 0.86


# -- figures ----------------------------------------------------------------------------
def test_plots_build_and_save(paper, no_stribeck, tmp_path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    ax = paper.plot_residuals()
    assert ax.shape == (2, 3)
    hdid.save_figure(ax, tmp_path / "res.png")
    assert (tmp_path / "res.png").stat().st_size > 0 and len(ax[0, 0].figure.axes) == 6
    fig2, axes = plt.subplots(2, 3)
    assert R.plot_residuals(paper, ax=axes) is axes
    fig3, ax = plt.subplots()
    assert R.plot_rest_approach(paper, ax=ax) is ax
    # A model that never sticks still draws (an empty rest window, said in the title).
    ax4 = R.plot_rest_approach(no_stribeck)
    assert "never sticks" in ax4.get_title()
    with pytest.raises(ValueError, match="6 axes"):
        R.plot_residuals(paper, ax=axes[0])
    plt.close("all")


def test_residual_figure_shows_only_what_the_log_supports(paper, no_stribeck):
    """At 250 Hz the gear moves 4–5 samples per run: whiteness gets 1 lag and the
    periodogram 2 bins, which look like evidence and carry none (issue 18). Those panels
    become the residual's distribution against ideal rounding and the per-run RMS against
    the floor. A model that never sticks moves for the whole run (125 samples): there the
    ACF (10 lags) and the spectrum (≥ 8 bins) are drawn."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    wt = R.whiteness(paper)
    assert wt.max_lag < R.MIN_ACF_LAGS  # the premise: this log cannot support an ACF
    fig = R.plot_residuals(paper)[0, 0].figure
    ax_acf, ax_sp = fig.axes[4], fig.axes[5]
    assert ax_acf.get_title().startswith("no ACF")
    assert ax_sp.get_title().startswith("no spectrum")
    assert ax_sp.get_yscale() == "linear"
    # one point per run, each the run's moving RMS in counts
    runs = R.residual_frame(paper).query("phase == 'moving'").groupby("run", observed=True)
    pts = ax_sp.lines[0].get_ydata()
    assert len(pts) == runs.ngroups
    assert np.allclose(sorted(pts), sorted(np.sqrt((runs["residual_counts"]
                                                    .apply(lambda r: np.mean(r**2)))).to_numpy()))
    fig2 = R.plot_residuals(no_stribeck)[0, 0].figure
    assert R.whiteness(no_stribeck).max_lag >= R.MIN_ACF_LAGS
    assert fig2.axes[4].get_title().startswith("Ljung–Box")
    assert fig2.axes[5].get_title() == "spectrum of moving residual"
    plt.close("all")
