"""fit.png as an engineer reads it (issue 18 item 4): the model carries a confidence band
propagated from the fit's covariance, and saving a figure leaves the caller's matplotlib
backend alone."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import hdid

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "data" / "synthetic" / "csf8_paper.csv"


@pytest.fixture(scope="module")
def result():
    return hdid.fit(EXAMPLE, n_starts=2)


def test_band_is_the_delta_method_of_the_fit(result):
    """The band's σ(t)² = g(t)ᵀ C g(t) must be the fit's own linearised covariance carried
    to the trajectory. Check it through the least-squares identity that ties the two: at
    the logged samples, Σ_i (w_i/σ_q)² σ_i² / s² = trace(F_data·C/s²) = n − Σ_prior C_jj/sd_j²
    (the unknowns minus what the weak priors carry), with C = (F_data/s² + P)⁻¹. A band
    from another covariance, without the nuisances' sensitivities, or scaled by σ instead
    of σ² breaks it; the tolerance is the eigen-decomposition's rounding (C is a
    pseudo-inverse with eigenvalues cut at 1e-10 of the largest)."""
    prob = result.problem
    sd = result.predict_std()
    assert sd.shape == np.asarray(prob.times).shape
    assert np.all(np.isfinite(sd)) and np.all(sd >= 0)
    w2 = np.asarray(prob.weight) ** 2 / float(prob.sigma) ** 2
    s2 = result.noise_scale**2  # χ²/dof: the scale the covariance was given (encoder grid)
    leverage = float(np.sum(w2 * sd**2)) / s2
    C = np.asarray(result.covariance)
    P = prob.n_physical
    prior = np.asarray(prob.prior_on)
    prior_share = float(np.sum(np.where(prior, np.diag(C)[:P] / np.asarray(prob.prior_sd) ** 2, 0.0)))
    assert leverage == pytest.approx(prob.n_unknowns - prior_share, rel=1e-6)
    assert 0 < leverage <= prob.n_unknowns


def test_fit_png_draws_the_band(result):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from matplotlib.collections import PolyCollection

    from hdid._results._plot import BAND_LABEL, BAND_SIGMAS

    fig = result.plot()[0, 0].figure
    step = result.resolution_rad
    for i, run in enumerate(result.runs):
        top, bottom = fig.axes[2 * i], fig.axes[2 * i + 1]
        for ax in (top, bottom):
            bands = [c for c in ax.collections
                     if isinstance(c, PolyCollection) and c.get_label() == BAND_LABEL]
            assert len(bands) == 1, (run.name, [c.get_label() for c in ax.collections])
            verts = bands[0].get_paths()[0].vertices
            assert np.all(np.isfinite(verts))
        # residual panel: the band about 0 is ±2σ of the prediction, in counts
        verts = [c for c in bottom.collections if c.get_label() == BAND_LABEL][0].get_paths()[0].vertices
        half = np.abs(verts[:, 1])
        # ±2σ of the prediction on the figure's time grid (the simulator's substeps follow
        # the output times, so the same grid gives the same numbers to rounding)
        t_grid = np.unique(verts[:, 0])
        sd = result.predict_std(np.tile(t_grid, (len(result.runs), 1)))[i]
        upper = {t: y for t, y in verts if y >= 0}
        assert np.allclose([upper[t] for t in t_grid], BAND_SIGMAS * sd / step, rtol=1e-9, atol=0)
        # it is widest while the gear moves (the release instant is uncertain where the
        # speed is high), narrower on the hold, which the hold's readings pin
        t = verts[:, 0]
        hold = t < run.release_time - result.sample_period
        moving = (t > run.release_time) & (t < run.release_time + 0.015)
        assert half[moving].max() > half[hold].max() > 0
    legend = [t.get_text() for t in fig.axes[0].get_legend().get_texts()]
    assert BAND_LABEL in legend
    assert BAND_LABEL in [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    plt.close("all")


def test_one_axes_overlay_has_the_band(result):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hdid._results._plot import BAND_LABEL

    fig, ax = plt.subplots()
    assert result.plot(ax=ax) is ax
    assert BAND_LABEL in [t.get_text() for t in ax.get_legend().get_texts()]
    assert len(ax.collections) >= len(result.runs)
    # the motion fills the axes: the still tail (most of each 0.5 s run) is cropped, as in
    # fit.png (the gear rests ~20 ms after release; the window ends 6 samples later)
    duration = result.runs[0].n_samples * result.sample_period
    assert ax.get_xlim()[1] < 0.25 * duration
    assert "cropped" in ax.get_xlabel()
    plt.close("all")


def test_saving_leaves_the_backend_alone(result, tmp_path):
    """plot(path) used to switch matplotlib to Agg (a notebook then showed nothing more);
    the CLI's way of saving (bare figures, ``save_figure``) touches no backend or pyplot."""
    import matplotlib

    before = matplotlib.get_backend()
    matplotlib.use("svg")
    try:
        out = tmp_path / "fit.png"
        with hdid.bare_figures():
            ax = result.plot()
        hdid.save_figure(ax, out)
        fig = ax[0, 0].figure
        assert out.stat().st_size > 0
        assert matplotlib.get_backend() == "svg"
        import matplotlib.pyplot as plt

        assert fig not in [plt.figure(n) for n in plt.get_fignums()]  # not kept by pyplot
    finally:
        matplotlib.use(before)


def test_readings_on_no_grid_get_no_counts(result):
    """A log whose readings lie on no grid has no encoder counts (issue 16: never print
    counts for an assumed encoder): fit.png's residual is then in the estimated noise σ."""
    import dataclasses

    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    analog = dataclasses.replace(result, resolution_source="noise")
    fig = analog.plot()[0, 0].figure
    texts = [fig._suptitle.get_text(), fig.axes[1].get_ylabel()]
    texts += [t.get_text() for t in fig.axes[1].get_legend().get_texts()]
    assert not any("count" in t for t in texts), texts
    assert "noise σ" in fig.axes[1].get_ylabel()
    fig = result.plot()[0, 0].figure  # on a grid: counts, as before
    assert "counts" in fig.axes[1].get_ylabel() and "counts" in fig._suptitle.get_text()
    plt.close("all")
