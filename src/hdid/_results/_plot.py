"""Figures of a fit and of its posterior, and the one convention every hdid figure follows.

Every figure is ``f(result, *, ax=None) -> Axes`` (lmfit's ``plot(ax=None)``): it draws
into the axes it is given (one Axes, or an array of them for a multi-panel figure) and
returns them; without ``ax`` it makes a new figure through pyplot, so a notebook or a
window shows it. It never saves and never chooses a backend. To save,
``save_figure(ax, path)``; inside ``with bare_figures():`` new figures are made without
pyplot (the CLI: figures that are only written to a file touch no backend at all).
"""

from __future__ import annotations

import contextlib
import contextvars

import numpy as np
from .._problems._evaluate import predict_rows as _predict_batch

_BARE = contextvars.ContextVar("hdid_bare_figures", default=False)


@contextlib.contextmanager
def bare_figures():
    """New figures inside this block are bare :class:`~matplotlib.figure.Figure` objects,
    made without pyplot: nothing is shown, no backend is chosen or touched (for figures
    that are only saved)."""
    token = _BARE.set(True)
    try:
        yield
    finally:
        _BARE.reset(token)


def new_figure(**kw):
    """A new figure: through pyplot (shown in a notebook or a window), or a bare one
    inside :func:`bare_figures`."""
    if _BARE.get():
        from matplotlib.figure import Figure

        return Figure(**kw)
    import matplotlib.pyplot as plt

    return plt.figure(**kw)


def figure_of(ax):
    """The figure an Axes, or an array of Axes, belongs to."""
    first = ax if hasattr(ax, "figure") else np.asarray(ax, dtype=object).flat[0]
    return first.figure


def save_figure(ax, path, dpi: int = 110) -> None:
    """Save the figure ``ax`` (an Axes or an array of them, as a plot function returned
    them) belongs to; the format follows the file's suffix."""
    figure_of(ax).savefig(path, dpi=dpi)


#: Runs per row of the fit figure; more runs wrap into further rows.
RUNS_PER_ROW = 4


def _fit_axes(R: int):
    """A new figure with a (2, R) array of axes: per run the angle above its residual,
    at most RUNS_PER_ROW runs side by side (more wrap into rows)."""
    ncol = min(R, RUNS_PER_ROW)
    nrow = -(-R // ncol)
    fig = new_figure(figsize=(3.2 * ncol + 1, 5.2 * nrow))
    gs = fig.add_gridspec(2 * nrow, ncol, height_ratios=[3, 1.3] * nrow)
    axes = np.empty((2, R), dtype=object)
    for i in range(R):
        r, c = divmod(i, ncol)
        axes[0, i] = fig.add_subplot(gs[2 * r, c])
        axes[1, i] = fig.add_subplot(gs[2 * r + 1, c], sharex=axes[0, i])
    return fig, axes


#: Width of the model's confidence band in standard errors (±2σ: ~95 % for a Gaussian).
BAND_SIGMAS = 2.0
BAND_LABEL = f"model ±{BAND_SIGMAS:g}σ (fit uncertainty)"


def _window(result, i, times, model_s):
    """Run ``i``'s shown stretch: from a few samples before the release to a little after
    the model comes to rest (at least 0.05 time units after the release)."""
    run = result.runs[i]
    n = run.n_samples
    moving = np.flatnonzero(np.abs(np.diff(model_s[i, :n])) > 0)
    t_end = times[i, min(moving[-1] + 6, n - 1)] if moving.size else times[i, n - 1]
    return run.release_time - 5 * result.sample_period, max(t_end, run.release_time + 0.05)


def _overlay(result, ax, times, meas, model_s, fine, model_fine, sd_fine):
    """All runs in one axes: angle from the spring zero against time since release (the
    release-to-rest stretch of every run), each model with its ±2σ confidence band."""
    lo = result.derived["stick_band_lower_rad"][0]
    hi = result.derived["stick_band_upper_rad"][0]
    ax.axhspan(lo, hi, color="0.9", label="stick band (fit)")
    windows = [_window(result, i, times, model_s) for i in range(len(result.runs))]
    before = max(run.release_time - w[0] for run, w in zip(result.runs, windows))
    after = max(w[1] - run.release_time for run, w in zip(result.runs, windows))
    cropped = False
    for i, run in enumerate(result.runs):
        n, t0, color = run.n_samples, run.release_time, f"C{i % 10}"
        sel = (times[i, :n] >= t0 - before) & (times[i, :n] <= t0 + after)
        fsel = (fine[i] >= t0 - before) & (fine[i] <= t0 + after)
        cropped |= not sel.all()
        m = model_fine[i, fsel] - run.offset
        band = BAND_SIGMAS * sd_fine[i, fsel]
        ax.fill_between(fine[i, fsel] - t0, m - band, m + band, color=color, alpha=0.3, lw=0,
                        label=BAND_LABEL if i == 0 else None)
        ax.plot(fine[i, fsel] - t0, m, "-", color=color, lw=1.0, label=f"run {run.name}: model")
        ax.plot(times[i, :n][sel] - t0, meas[i, :n][sel] - run.offset, "o", ms=2.5, mfc="none",
                color=color)
    ax.set_xlabel("time since release [s]" + ("  (release to rest; hold and tail cropped)"
                                              if cropped else ""))
    ax.set_ylabel("WG angle from spring zero [rad]")
    ax.set_title(f"{result.source}: measured (o) and model (–)", fontsize=9)
    ax.legend(fontsize=7)
    return ax


def plot_saved_fit(result, *, ax=None):
    """A fit read from its file, without the log: each run's RMS residual in quantization
    floors (``step/√12``; the estimated noise σ for readings on no grid), the floor as a
    line, and the rest angle logged against the model's written on each bar. ``ax``: one
    Axes (a new figure otherwise); returns it. Refit to see the runs themselves."""
    if ax is None:
        ax = new_figure(figsize=(max(4.0, 0.8 * len(result.runs) + 2), 3.5),
                        constrained_layout=True).subplots()
    elif not hasattr(ax, "plot"):
        from .._errors import HdidError

        raise HdidError("ax: a fit loaded from its file draws one Axes (its runs' RMS); "
                        "refit with the log for the (2, R) run panels")
    floor = result.quantization_floor_rad
    x = np.arange(len(result.runs))
    rms = np.array([r.rms_rad / floor for r in result.runs], dtype=float)
    bars = ax.bar(x, rms, color="C0", alpha=0.8, label="RMS residual")
    for b, r in zip(bars, result.runs):
        ax.annotate(f"rest {r.rest_logged:+.4f}\nmodel {r.rest_model:+.4f}",
                    (b.get_x() + b.get_width() / 2, b.get_height()), ha="center",
                    va="bottom", fontsize=7)
    ax.axhline(1.0, color="0.3", ls="--", lw=1, label="quantization floor")
    ax.set_xticks(x, [f"run {r.name}" for r in result.runs], fontsize=8)
    ax.set_ylabel("RMS residual / quantization floor")
    ax.set_ylim(0, 1.3 * max([1.0, *rms[np.isfinite(rms)]]))
    ax.set_title(f"{result.source} (loaded: refit with the log to see the runs)", fontsize=9)
    ax.legend(loc="upper right", fontsize=8)
    return ax


def plot_fit(result, *, ax=None, fine_rate: float = 20000.0):
    """Measured vs model per run (angle from the fitted spring zero, so the stick band is
    centred on 0) with the model's ±2σ confidence band (:meth:`FitResult.predict_std`),
    and the residual in encoder counts below it (in the estimated noise σ for readings on
    no grid), where the same band is drawn about 0.
    ``ax``: a ``(2, R)`` array of axes, or one Axes (all runs overlaid, no residuals); a
    new figure otherwise. Returns the axes drawn into (the ``(2, R)`` array, or the one Axes).
    """
    if result.problem is None:  # loaded from a file: the log is not there
        return plot_saved_fit(result, ax=ax)
    axes = ax
    prob = result.problem
    times = np.asarray(prob.times)
    meas = np.asarray(prob.theta)
    R = times.shape[0]
    one = axes is not None and hasattr(axes, "plot")  # one matplotlib Axes
    if axes is not None and not one:  # checked before any work
        grid = np.asarray(axes, dtype=object)
        if grid.size != 2 * R:
            from .._errors import HdidError

            raise HdidError(
                f"ax: this fit has {R} run(s), so give a (2, {R}) array of axes (angle above, "
                f"residual below, one column per run) or a single Axes (runs overlaid); got "
                f"{grid.size} axes of shape {grid.shape}"
            )
        grid = grid.reshape(2, R)
    n_fine = int(np.ceil((times.max() - times.min()) * fine_rate)) + 1
    fine = np.stack([np.linspace(t[0], t[-1], n_fine) for t in times])
    model_s = result.predict()  # compiled by the fit already
    model_fine, sd_fine = result._predict_with_std(fine)
    if one:
        return _overlay(result, axes, times, meas, model_s, fine, model_fine, sd_fine)
    if axes is None:
        fig, axes = _fit_axes(R)
    else:
        axes = grid
        fig = axes[0, 0].figure
    # Residuals in encoder counts; for readings on no grid (analog, interpolated) there are
    # no counts: in units of the noise σ estimated from the log (the report's "noise σ").
    on_grid = result.resolution_source != "noise"
    step = result.resolution_rad if on_grid else result.quantization_floor_rad
    unit = "counts" if on_grid else "noise σ, estimated"
    lo = result.derived["stick_band_lower_rad"][0]
    hi = result.derived["stick_band_upper_rad"][0]
    cropped = []
    for i, run in enumerate(result.runs):
        n = run.n_samples
        ax, axr = axes[0, i], axes[1, i]
        t0 = run.release_time
        # Show the motion: from a few samples before release to a little after rest.
        t_begin, t_end = _window(result, i, times, model_s)
        sel = (times[i, :n] >= t_begin) & (times[i, :n] <= t_end)
        fsel = (fine[i] >= t_begin) & (fine[i] <= t_end)
        if not sel.all():
            cropped.append(run.name)
        ax.axhspan(lo, hi, color="0.9", label="stick band (fit)")
        ax.plot(times[i, :n][sel], meas[i, :n][sel] - run.offset, "o", ms=3.5, color="k",
                mfc="none", label="encoder", zorder=2)
        m = model_fine[i, fsel] - run.offset
        band = BAND_SIGMAS * sd_fine[i, fsel]
        ax.fill_between(fine[i, fsel], m - band, m + band, color="C0", alpha=0.35, lw=0,
                        label=BAND_LABEL, zorder=2.5)
        ax.plot(fine[i, fsel], m, "-", color="C0", lw=1.4, label="model", zorder=3)
        ax.axvline(t0, color="C3", lw=0.8, ls=":", label="release (fit)")
        ax.set_title(f"run {run.name} (set-up {run.setup})", fontsize=9)
        res = (meas[i, :n] - model_s[i, :n]) / step
        axr.axhspan(-0.5 if on_grid else -1.0, 0.5 if on_grid else 1.0, color="0.9",
                    label="±½ count (rounding)" if on_grid else "±1σ noise (estimated)")
        axr.fill_between(fine[i, fsel], -band / step, band / step, color="C0", alpha=0.35,
                         lw=0, label=BAND_LABEL)
        axr.plot(times[i, :n][sel], res[sel], "o-", ms=3, lw=0.8, color="C1", label="residual")
        shown = f"{times[i, :n][sel][0]:.3g}–{times[i, :n][sel][-1]:.3g} s of {times[i, 0]:.3g}–{times[i, n - 1]:.3g}" if sel.any() else ""
        axr.set_xlabel("time [s]" + (f"\n(shows {shown})" if not sel.all() and shown else ""), fontsize=8)
        if i == 0:
            ax.set_ylabel("WG angle from spring zero [rad]")
            axr.set_ylabel(f"measured − model\n[{unit}]")
            ax.legend(fontsize=7, loc="best")
            axr.legend(fontsize=6, loc="best")
    note = ("; panels show release to rest, the still hold and tail are cropped"
            if cropped else "")
    fig.suptitle(
        f"{result.source}: RMS {result.rms_residual_rad / step:.2f} "
        + (f"counts (floor {1 / np.sqrt(12):.2f})" if on_grid else "× the estimated noise σ")
        + f", band half-width {result.stick_band_halfwidth_rad:.4f} rad{note}",
        fontsize=10,
    )
    fig.tight_layout()
    return axes


def plot_predictive(post, *, ax=None, n_draws: int = 100, seed: int = 0):
    """Posterior-predictive check of each measured run, on two scales.

    Top row: the readings and the model's 90 % / 50 % posterior band at full scale (there
    the band is thinner than a marker). Bottom row, the residual scale: everything minus the
    posterior-median model, in encoder steps — the readings (dots), the model's 90 % / 50 %
    band (the parameters' uncertainty) and the 95 % predictive interval of a *reading*
    (dashed: a draw of the model plus its noise ``σ_n`` and the rounding ``q²/12``), so a
    reading outside the dashed lines is one the posterior does not expect.

    ``ax``: ``(2, R)`` for both rows, or ``R`` axes for the residual row only; a new
    figure otherwise. Returns the axes drawn into.
    """
    import jax.numpy as jnp

    axes = ax


    fit = post.fit
    prob = fit.problem
    times = np.asarray(prob.times)
    meas = np.asarray(prob.theta)
    q = float(prob.step)
    R = times.shape[0]
    rng = np.random.default_rng(seed)
    idx = rng.choice(post.draws.shape[0], size=min(n_draws, post.draws.shape[0]), replace=False)
    draws = post.draws[idx]
    fine = np.stack([np.linspace(t[0], t[-1], int((t[-1] - t[0]) * 5000) + 1) for t in times])
    pred = np.asarray(_predict_batch(prob, jnp.asarray(draws), jnp.asarray(fine)))
    pred_s = np.asarray(_predict_batch(prob, jnp.asarray(draws), jnp.asarray(times)))
    centre_f = np.median(pred, axis=0)
    centre_s = np.median(pred_s, axis=0)
    # a reading: model draw + noise (σ_n² + q²/12, as in the likelihood)
    var = np.exp(2 * draws[:, -1])[:, None, None] + (q**2 / 12.0 if fit.resolution_known else 0.0)
    readings = pred_s + np.sqrt(var) * rng.standard_normal(pred_s.shape)
    if axes is None:
        fig = new_figure(figsize=(3.2 * R + 1, 6.2))
        axes = fig.subplots(2, R, squeeze=False, sharex="col")
        top, bottom = axes[0], axes[1]
    else:
        axes = np.asarray(axes)
        if axes.ndim == 2 and axes.shape == (2, R):
            top, bottom = axes[0], axes[1]
        elif axes.ndim == 1 and axes.size == R:
            top, bottom = [None] * R, axes
        else:
            raise ValueError(f"ax: {R} (residual row) or shape (2, {R}) (both rows), "
                             f"not {axes.shape}")
        fig = bottom[0].figure
    for i, run in enumerate(fit.runs):
        t0 = run.release_time
        sel = (fine[i] >= t0 - 0.01) & (fine[i] <= t0 + 0.05)
        n = run.n_samples
        ms = (times[i, :n] >= t0 - 0.01) & (times[i, :n] <= t0 + 0.05)
        ts = times[i, :n][ms]
        if top[i] is not None:
            ax = top[i]
            lo, q1, q3, hi = np.percentile(pred[:, i, sel], [5, 25, 75, 95], axis=0)
            ax.fill_between(fine[i, sel], lo, hi, color="C0", alpha=0.25, label="model 90 %")
            ax.fill_between(fine[i, sel], q1, q3, color="C0", alpha=0.45, label="model 50 %")
            ax.plot(ts, meas[i, :n][ms], "o", ms=3.5, mfc="none", color="k", label="encoder")
            ax.set_title(f"run {run.name}", fontsize=9)
            if i == 0:
                ax.set_ylabel("encoder reading [rad]")
                ax.legend(fontsize=7)
        ax = bottom[i]
        d = (pred[:, i, sel] - centre_f[i, sel]) / q
        lo, q1, q3, hi = np.percentile(d, [5, 25, 75, 95], axis=0)
        ax.fill_between(fine[i, sel], lo, hi, color="C0", alpha=0.25, label="model 90 %")
        ax.fill_between(fine[i, sel], q1, q3, color="C0", alpha=0.45, label="model 50 %")
        rd = (readings[:, i, :n][:, ms] - centre_s[i, :n][ms]) / q
        plo, phi = np.percentile(rd, [2.5, 97.5], axis=0)
        ax.plot(ts, plo, "--", color="C1", lw=1, label="reading 95 %")
        ax.plot(ts, phi, "--", color="C1", lw=1)
        ax.plot(ts, (meas[i, :n][ms] - centre_s[i, :n][ms]) / q, "o", ms=3.5, mfc="none",
                color="k", label="encoder − median model")
        ax.axhline(0.0, color="0.5", lw=0.6)
        ax.set_xlabel("time [s]")
        if top[i] is None:
            ax.set_title(f"run {run.name}", fontsize=9)
        if i == 0:
            ax.set_ylabel("residual [encoder steps]")
            ax.legend(fontsize=7)
    fig.suptitle(f"{fit.source}: posterior predictive ({len(idx)} draws; bottom: minus the "
                 "posterior-median model)", fontsize=10)
    fig.tight_layout()
    return axes


def plot_band(post, *, ax=None):
    """Posterior of the stick-band edges beside the rest points actually logged. Returns
    the Axes."""
    fit = post.fit
    hw = post.derived["stick_band_halfwidth_rad"]
    if ax is None:
        fig = new_figure(figsize=(6.5, 3.4))
        ax = fig.subplots()
    else:
        fig = ax.figure
    bins = np.linspace(-1.3 * np.percentile(hw, 99.5), 1.3 * np.percentile(hw, 99.5), 120)
    ax.hist(hw, bins=bins, color="C0", alpha=0.6, density=True, label="upper band edge (posterior)")
    ax.hist(-hw, bins=bins, color="C0", alpha=0.6, density=True, label="lower band edge")
    for k, r in enumerate(fit.runs):
        ax.axvline(r.rest_logged, color="C3", lw=1.2, label="logged rest points" if k == 0 else None)
    q = np.percentile(hw, [2.5, 50, 97.5])
    ax.set_title(
        f"stick band half-width {q[1]:.4f} rad (95 %: {q[0]:.4f} – {q[2]:.4f})", fontsize=10
    )
    ax.set_xlabel("WG angle from the spring zero [rad]")
    ax.set_yticks([])
    ax.legend(fontsize=7)
    fig.tight_layout()
    return ax
