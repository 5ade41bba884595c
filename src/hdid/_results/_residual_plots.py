"""Figures of the residual views: residual against time, angle, velocity and deflection, the
ACF or what a short log supports instead, the spectrum; the approach to rest."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from ._plot import new_figure
from ._residual_frame import PHASES, residual_frame
from ._whiteness import spectrum, whiteness


#: Window around the model's stick instant shown by :func:`plot_rest_approach` [s].
REST_WINDOW = (-0.1, 0.05)
#: The residual figure shows the ACF only when the shortest moving stretch gives at least
#: this many lags (``whiteness``'s ``max_lag = n_min // 4``, i.e. ≥ 12 moving samples per
#: run): a one- or two-lag ACF of a 250 Hz log (4–5 moving samples per run) is dominated
#: by the fit's own projection (expected lag-1 value ≈ −0.5) and says nothing by eye.
MIN_ACF_LAGS = 3
#: ... and the spectrum only when the longest moving stretch gives at least this many
#: frequency bins (``N // 2``): two or three points are no spectrum.
MIN_SPECTRUM_BINS = 8


# ---------------------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------------------
def plot_residuals(result, *, ax=None):
    """Residual [counts] against time, WG angle, velocity and output deflection; ACF; spectrum.

    The ACF is drawn only with at least ``MIN_ACF_LAGS`` lags and the spectrum with at
    least ``MIN_SPECTRUM_BINS`` frequency bins. A log with fewer moving samples per run
    (250 Hz: 4–5) gets what it can support instead: the distribution of the pooled
    moving residual against ideal rounding, and each run's moving RMS against the
    floor with the range ideal rounding gives for that run's sample count.

    Parameters
    ----------
    result:
        A :class:`~hdid.FitResult`.
    ax:
        Six matplotlib axes (any shape, read row-major) to draw into; a new 2×3 figure
        otherwise.

    Returns
    -------
    The axes drawn into (as given, or the new figure's 2×3 array).
    """
    frame = residual_frame(result)
    wt = whiteness(result, frame=frame)
    sp = spectrum(frame)
    if ax is None:
        ax = new_figure(figsize=(13, 7)).subplots(2, 3)
    given = ax
    axes = np.asarray(ax).ravel()
    if axes.size != 6:
        raise ValueError(f"ax: need 6 axes, got {axes.size}")
    fig = axes[0].figure
    ax_t, ax_th, ax_om, ax_def, ax_acf, ax_sp = axes
    colors = {"hold": "0.6", "moving": "C0", "stuck": "C3"}
    for name, g in frame.groupby("run", sort=False, observed=True):
        ax_t.plot(g["t_since_release"], g["residual_counts"], ".-", ms=3, lw=0.6,
                  label=f"run {name}")
    mov = frame[frame["phase"] == "moving"]
    for ax, col, lab in ((ax_th, "theta_wg", "WG angle from spring zero (model) [rad]"),
                         (ax_om, "omega", "WG velocity (model) [rad/s]"),
                         (ax_def, "deflection_out", "output deflection θ_wg/N [mrad]")):
        scale = 1e3 if col == "deflection_out" else 1.0
        for ph in PHASES:
            g = frame[frame["phase"] == ph]
            if len(g):
                ax.plot(scale * g[col], g["residual_counts"], ".", ms=3.5, color=colors[ph],
                        label=ph)
        ax.set_xlabel(lab)
    for ax in (ax_t, ax_th, ax_om, ax_def):
        for y in (-0.5, 0.5):
            ax.axhline(y, color="k", lw=0.6, ls="--")
        ax.axhline(0.0, color="k", lw=0.4)
        ax.set_ylabel("measured − model [counts]")
    ax_t.set_xlabel("time since release [s]")
    ax_t.set_title("residual vs time (±½ count dashed)", fontsize=9)
    ax_t.legend(fontsize=7)
    ax_th.legend(fontsize=7)
    ax_th.set_title("vs WG angle", fontsize=9)
    ax_om.set_title("vs velocity", fontsize=9)
    ax_def.set_title(f"vs output deflection ({len(mov)} moving samples)", fontsize=9)
    if wt.n and wt.max_lag >= MIN_ACF_LAGS:
        null = np.zeros(wt.max_lag) if wt.acf_null is None else wt.acf_null
        ax_acf.bar(wt.lags, 2 * wt.band, bottom=null - wt.band, width=0.8, color="0.85",
                   label="95 % white band")
        ax_acf.bar(wt.lags, wt.acf, width=0.35, color="C0", label="ACF")
        ax_acf.plot(wt.lags, null, "_", ms=18, mew=2, color="k", label="expected, correct model")
        ax_acf.set_xticks(wt.lags)
        ax_acf.legend(fontsize=7)
        ax_acf.axhline(0, color="k", lw=0.5)
        ax_acf.set_xlabel("lag [samples]")
        ax_acf.set_ylabel("ACF of moving residual")
        ax_acf.set_title(
            f"Ljung–Box Q={wt.q:.2f}, p={wt.p_value:.3g}; RMS/floor {wt.rms_ratio:.2f}",
            fontsize=9,
        )
    else:
        _plot_rounding_histogram(ax_acf, frame, wt)
    if sp.frequency.size >= MIN_SPECTRUM_BINS:
        ax_sp.fill_between(sp.frequency, sp.lower, sp.upper, color="0.85", label="white 95 %")
        ax_sp.plot(sp.frequency, sp.power, "o-", ms=3, color="C0", label="periodogram")
        ax_sp.set_yscale("log")
        ax_sp.legend(fontsize=7)
        ax_sp.set_xlabel("frequency [Hz]")
        ax_sp.set_ylabel("power [rad²/Hz]")
        ax_sp.set_title("spectrum of moving residual", fontsize=9)
    else:
        _plot_run_rms(ax_sp, frame, sp.frequency.size)
    verdict = "adequate" if wt.adequate else "NOT adequate"
    fig.suptitle(
        f"{result.source}: residuals — {verdict} (white={wt.white}, at floor={wt.at_floor})",
        fontsize=10,
    )
    fig.tight_layout()
    return given


def _plot_rounding_histogram(ax, frame: pd.DataFrame, wt) -> None:
    """What a log too short per run for an ACF still supports: the distribution of the
    pooled moving residual [counts] against ideal rounding (uniform on ±½ count)."""
    mov = frame.loc[frame["phase"] == "moving", "residual_counts"].to_numpy(dtype=float)
    if mov.size:
        lim = max(1.0, float(np.ceil(np.max(np.abs(mov)) * 2) / 2))
        ax.hist(mov, bins=np.arange(-lim, lim + 1e-9, 0.25), density=True, color="C0",
                alpha=0.7, label=f"moving residual ({mov.size} samples)")
    ax.plot([-0.5, -0.5, 0.5, 0.5], [0, 1, 1, 0], color="k", lw=1.2,
            label="ideal rounding (uniform ±½ count)")
    ax.set_xlabel("measured − model [counts]")
    ax.set_ylabel("density")
    ax.legend(fontsize=7)
    lags = wt.max_lag if wt.n else 0
    ax.set_title(
        f"no ACF: {lags} lag(s) per run carry no evidence; RMS/floor {wt.rms_ratio:.2f}",
        fontsize=9,
    )


def _plot_run_rms(ax, frame: pd.DataFrame, n_bins: int) -> None:
    """Per-run RMS of the moving residual against the floor ``1/√12`` count, with the
    95 % range of ``n`` ideal rounding errors (RMS² ~ σ²·χ²ₙ/n as a normal proxy:
    ``σ²(1 ± 1.96·√(0.8/n))``, the uniform's fourth moment) — in place of a spectrum that
    would have ``n_bins`` points."""
    from scipy.stats import norm

    z = norm.ppf(0.975)
    floor = 1.0 / math.sqrt(12.0)
    names, rms, lo, hi = [], [], [], []
    mov = frame[frame["phase"] == "moving"]
    for name, g in mov.groupby("run", sort=False, observed=True):
        r = g["residual_counts"].to_numpy(dtype=float)
        if r.size == 0:
            continue
        names.append(str(name))
        rms.append(math.sqrt(float(np.mean(r**2))))
        half = z * math.sqrt(0.8 / r.size)
        lo.append(floor * math.sqrt(max(1.0 - half, 0.0)))
        hi.append(floor * math.sqrt(1.0 + half))
    x = np.arange(len(names))
    if names:
        ax.bar(x, np.array(hi) - np.array(lo), bottom=lo, width=0.8, color="0.85",
               label="95 % range, ideal rounding")
        ax.plot(x, rms, "o", color="C0", label="moving RMS")
        ax.set_xticks(x, names, rotation=30, ha="right", fontsize=7)
    ax.axhline(floor, color="k", lw=0.8, ls="--", label="floor 1/√12 count")
    ax.set_ylim(bottom=0.0)
    ax.set_ylabel("RMS [counts]")
    ax.legend(fontsize=7)
    ax.set_title(f"no spectrum ({n_bins} frequency bin(s)): RMS per run", fontsize=9)


def plot_rest_approach(result, *, ax=None, window: tuple[float, float] = REST_WINDOW):
    """Residual [counts] vs time to the model's stick instant, per run, around rest.

    Parameters
    ----------
    result:
        A :class:`~hdid.FitResult`.
    ax:
        Axes to draw into; a new figure otherwise.
    window:
        ``(before, after)`` the stick instant [s].

    Returns
    -------
    matplotlib.axes.Axes
    """
    frame = residual_frame(result)
    if ax is None:
        fig = new_figure(figsize=(6.5, 3.6))
        ax = fig.subplots()
    else:
        fig = ax.figure
    drawn = 0
    for name, g in frame.groupby("run", sort=False, observed=True):
        s = g[(g["t_to_stick"] >= window[0]) & (g["t_to_stick"] <= window[1])]
        if len(s):
            ax.plot(s["t_to_stick"], s["residual_counts"], "o-", ms=3, lw=0.7, label=f"run {name}")
            drawn += 1
    ax.axvline(0.0, color="k", lw=0.8, ls=":")
    for y in (-0.5, 0.5):
        ax.axhline(y, color="k", lw=0.6, ls="--")
    ax.set_xlim(*window)
    ax.set_xlabel("time relative to the model's stick [s]")
    ax.set_ylabel("measured − model [counts]")
    ax.set_title("approach to rest" + ("" if drawn else " (the model never sticks)"), fontsize=9)
    if drawn:
        ax.legend(fontsize=7)
    fig.tight_layout()
    return ax
