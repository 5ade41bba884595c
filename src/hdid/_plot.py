"""Measured-vs-model figure for a fit."""

from __future__ import annotations

import numpy as np


def plot_fit(result, path=None, *, axes=None, fine_rate: float = 20000.0):
    import matplotlib

    if path is not None and axes is None:
        matplotlib.use("Agg", force=False)
    import matplotlib.pyplot as plt

    prob = result.problem
    times = np.asarray(prob.times)
    meas = np.asarray(prob.theta)
    R = times.shape[0]
    n_fine = int(np.ceil((times.max() - times.min()) * fine_rate)) + 1
    fine = np.stack([np.linspace(t[0], t[-1], n_fine) for t in times])
    model_fine = result.predict(fine)
    model_s = result.predict()
    if axes is None:
        fig, axes = plt.subplots(
            2, R, figsize=(3.2 * R + 1, 5.2), sharex="col", squeeze=False,
            gridspec_kw={"height_ratios": [3, 1.3]},
        )
    else:
        axes = np.asarray(axes).reshape(2, R)
        fig = axes[0, 0].figure
    step = result.resolution_rad
    lo = result.derived["stick_band_lower_rad"][0]
    hi = result.derived["stick_band_upper_rad"][0]
    for i, run in enumerate(result.runs):
        n = run.n_samples
        ax, axr = axes[0, i], axes[1, i]
        t0 = run.release_time
        # Show the motion: from a few samples before release to a little after rest.
        moving = np.flatnonzero(np.abs(np.diff(model_s[i, :n])) > 0)
        t_end = times[i, min(moving[-1] + 6, n - 1)] if moving.size else times[i, n - 1]
        t_end = max(t_end, t0 + 0.05)
        sel = (times[i, :n] >= t0 - 5 * result.sample_period) & (times[i, :n] <= t_end)
        fsel = (fine[i] >= t0 - 5 * result.sample_period) & (fine[i] <= t_end)
        ax.axhspan(run.offset + lo, run.offset + hi, color="0.9", label="stick band (fit)")
        ax.plot(fine[i, fsel], model_fine[i, fsel], "-", color="C0", lw=1.2, label="model")
        ax.plot(times[i, :n][sel], meas[i, :n][sel], "o", ms=3.5, color="k", mfc="none",
                label="encoder")
        ax.axvline(t0, color="C3", lw=0.8, ls=":", label="release (fit)")
        ax.set_title(f"run {run.name} (set-up {run.setup})", fontsize=9)
        res = (meas[i, :n] - model_s[i, :n]) / step
        axr.axhspan(-0.5, 0.5, color="0.9")
        axr.plot(times[i, :n][sel], res[sel], "o-", ms=3, lw=0.8, color="C1")
        axr.set_xlabel("time [s]")
        if i == 0:
            ax.set_ylabel("WG angle [rad]")
            axr.set_ylabel("measured − model\n[counts]")
            ax.legend(fontsize=7, loc="best")
    fig.suptitle(
        f"{result.source}: RMS {result.rms_residual_rad / step:.2f} counts "
        f"(floor 0.29), band half-width {result.stick_band_halfwidth_rad:.4f} rad",
        fontsize=10,
    )
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
