"""The posterior's result: draws, summaries, diagnostics, plots and export."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._config import float64_methods

#: The stick-band half-width: sampled quantities' companion in every convergence test.
BAND = "stick_band_halfwidth_rad"


class _RunNames:
    """Adapter giving ``unknown_labels`` the run and set-up names of a FitResult."""

    def __init__(self, fit):
        self.run_names = [r.name for r in fit.runs]
        self.setup_names = list(fit.setups)


@float64_methods
@dataclass
class PosteriorResult:
    """Samples and summaries of the posterior (see :func:`sample_posterior`)."""

    samples: dict[str, np.ndarray]           # name -> (draws,) physical units
    derived: dict[str, np.ndarray]           # name -> (draws,)
    chain: np.ndarray                        # (steps, walkers, D) raw, sampled space
    labels: list[str]
    tau: np.ndarray                          # integrated autocorrelation time per dim
    acceptance: np.ndarray                   # per walker
    burn: int
    thin: int
    warnings: list[str]
    seed: int
    wall_time_s: float
    temper: float
    residual_rho1: float
    fit: Any = field(repr=False)
    draws: np.ndarray = field(repr=False)    # (draws, D) sampled space, after burn/thin
    burn_in: int = 0                         # steps run and discarded before ``chain``
    modes: list = field(default_factory=list)  # Mode: the optima the walkers started from
    mode_share: np.ndarray | None = None     # share of the kept chain nearest each mode
    tau_emcee: np.ndarray | None = None      # emcee's τ (walkers about their own means)
    mode_search_s: float = 0.0
    move_acceptance: dict = field(default_factory=dict)  # per move, kept chain only
    n_components: int = 0                    # components of the adapted mixture proposal
    convergence: Any = None                  # diagnostics.Convergence of the kept chain
    widths: dict = field(default_factory=dict)  # name -> posterior/prior width, verdict
    limits: list = field(default_factory=list)  # limit fits of value-flat parameters (dicts)
    compile_s: float = 0.0                   # first (compiling) log-posterior call
    stage_s: dict = field(default_factory=dict)  # wall time of each stage
    method: str = "emcee"                    # "smc" (tempered SMC) or "emcee"
    smc: dict = field(default_factory=dict)  # SMC: runs, particles, temperatures, evidence
    basin: dict = field(default_factory=dict)  # basin.BasinCheck.to_dict(): residual vs floor
    priors: dict = field(default_factory=dict)  # name -> priors.prior_table row (+ width)
    default_prior: str = "weak"              # "weak" (log-normal around the log's scales) or "flat"

    @property
    def converged(self) -> bool:
        """The kept chain meets the convergence criterion (``diagnostics.Convergence``:
        ESS, and R-hat or, for the ensemble, 50 τ; ``convergence.met_by`` says which)."""
        return bool(self.convergence is not None and self.convergence.converged)

    def summary(self) -> dict[str, dict[str, Any]]:
        """Median and central 68 % / 95 % intervals of every parameter and derived quantity."""
        out = {}
        for name, v in {**self.samples, **self.derived}.items():
            v = np.asarray(v)
            q = np.percentile(v, [2.5, 16, 50, 84, 97.5])
            out[name] = {
                "median": float(q[2]),
                "ci68": [float(q[1]), float(q[3])],
                "ci95": [float(q[0]), float(q[4])],
            }
        return out

    def to_dict(self) -> dict[str, Any]:
        s = self.summary()
        from .._results._saved import finite

        return finite({
            "posterior": s,
            "posterior_width": dict(self.widths),
            "posterior_prior": {"default": self.default_prior, "parameters": dict(self.priors)},
            "posterior_diagnostics": {
                "method": self.method,
                "engine": ("tempered SMC alone" if self.method == "smc" else
                           "emcee, walkers from the optima's Laplace approximations"),
                "smc": dict(self.smc) if self.smc else None,
                "n_walkers": int(self.chain.shape[1]),
                "n_steps": int(self.chain.shape[0]),
                "burn_in": self.burn_in,
                "burn": self.burn,
                "thin": self.thin,
                "chain_in_tau_max": float(self.chain.shape[0] / np.nanmax(self.tau)),
                "converged": self.converged,
                "convergence": self.convergence.to_dict() if self.convergence is not None else None,
                "n_draws": int(self.draws.shape[0]),
                "tau_max": float(np.nanmax(self.tau)),
                "tau": {l: float(t) for l, t in zip(self.labels, self.tau)},
                "move_acceptance": dict(self.move_acceptance),
                "tau_max_emcee": (float(np.nanmax(self.tau_emcee))
                                  if self.tau_emcee is not None else None),
                "modes": [
                    {**m.to_dict(), "share_of_draws": (float(self.mode_share[i])
                                                      if self.mode_share is not None else None)}
                    for i, m in enumerate(self.modes)
                ],
                "limits": list(self.limits),
                "basin": dict(self.basin) if self.basin else None,
                "acceptance_mean": float(np.mean(self.acceptance)),
                "acceptance_min": float(np.min(self.acceptance)),
                "residual_lag1_autocorrelation": self.residual_rho1,
                "likelihood_temper": self.temper,
                "seed": self.seed,
                "wall_time_s": self.wall_time_s,
                "compile_s": self.compile_s,
                "stage_s": dict(self.stage_s),
                "mode_search_s": self.mode_search_s,
                "warnings": list(self.warnings),
            },
        })

    def report(self) -> str:
        lines = []
        if self.basin and self.basin.get("statement"):
            lines.append(self.basin["statement"])
        lines.append("posterior (median, 68 % and 95 % intervals | prior median and 95 % "
                     "range | posterior/prior width):")
        for name, s in self.summary().items():
            w = self.widths.get(name)
            p = self.priors.get(name)
            tail = ""
            if p is not None:
                lo, hi = p["ci95"] if p["ci95"] else (float("nan"), float("nan"))
                mid = f"{p['centre']:.3g}" if p["centre"] is not None else "flat"
                tail += f"  | {mid} [{lo:.3g}, {hi:.3g}]"
            if w:
                tail += (f"  | {w['posterior_over_prior_width']:.2g}"
                         + ("  set by the prior" if w.get("set_by_prior") else ""))
            lines.append(
                f"  {name:<26} {s['median']:12.5g}  [{s['ci68'][0]:.4g}, {s['ci68'][1]:.4g}]"
                f"  [{s['ci95'][0]:.4g}, {s['ci95'][1]:.4g}]{tail}"
            )
        if self.priors:
            which = ("weak: log-normal around the log's own scales" if self.default_prior == "weak"
                     else "flat (default_prior='flat')")
            lines.append(f"  priors ({which}); where each scale came from:")
            for name, p in self.priors.items():
                lines.append(f"    {name:<8} {p['kind']}: {p['source']}")
        if self.method == "smc":
            z = self.smc.get("log_evidence", [])
            lines.append(
                "  engine: tempered SMC alone (method='smc'); convergence: arviz R-hat <= 1.01 "
                "between runs, bulk/tail ESS >= 400 (particles sorted by ancestor)")
            lines.append(
                f"  tempered SMC: {self.chain.shape[1]} independent runs × "
                f"{self.chain.shape[0]} particles, {self.smc.get('temperatures')} temperatures, "
                f"{self.smc.get('steps')} steps, random-walk acceptance "
                f"{np.mean(self.acceptance):.2f}; log evidence {np.mean(z):.2f} ± "
                f"{self.smc.get('log_evidence_sd', float('nan')):.2f} (sd between runs); "
                f"{self.wall_time_s:.1f} s (of which compile {self.compile_s:.1f} s, mode "
                f"search {self.mode_search_s:.1f} s)")
        else:
            lines.append(
                "  engine: emcee (ensemble MCMC: differential evolution + independence moves "
                "from a t-mixture over the optima); convergence: arviz rank-normalised R-hat "
                "<= 1.01 and bulk/tail ESS >= 400 on every sampled quantity and the band, "
                "walkers as chains")
            lines.append(
            f"  {self.chain.shape[1]} walkers × {self.chain.shape[0]} steps (after "
            f"{self.burn_in} burn-in), max τ {np.nanmax(self.tau):.0f} = chain / "
            f"{self.chain.shape[0] / np.nanmax(self.tau):.1f}, acceptance {np.mean(self.acceptance):.2f}, "
            f"{self.draws.shape[0]} draws, {self.wall_time_s:.1f} s "
            f"(of which compile {self.compile_s:.1f} s, mode search {self.mode_search_s:.1f} s)"
        )
        if self.convergence is not None:
            c = self.convergence
            name, what = c.worst
            verdict = f"converged ({c.met_by} rule)" if c.converged else "NOT CONVERGED"
            lines.append(
                f"  convergence ({c.criterion}): "
                f"{verdict}; R-hat max "
                f"{np.max(c.rhat):.3f}, ESS bulk min {np.min(c.ess_bulk):.0f}, tail min "
                f"{np.min(c.ess_tail):.0f} (worst: {name}, {what})")
        if self.move_acceptance:
            lines.append("  acceptance per move: " + ", ".join(
                f"{k} {v:.3f}" for k, v in self.move_acceptance.items()))
        lines += [f"  warning: {w}" for w in self.warnings]
        return "\n".join(lines)

    def to_inference_data(self):
        """arviz InferenceData (posterior group: physical and derived quantities, walkers
        — or SMC runs — as chains; the draws of :attr:`samples` and :attr:`derived`)."""
        import arviz as az

        walkers = self.chain.shape[1]
        data = {}
        for k, v in {**self.samples, **self.derived}.items():
            v = np.asarray(v, dtype=float)
            data[k.replace("/", "_per_")] = v.reshape(-1, walkers).T
        return az.from_dict(posterior=data, attrs={"source": self.fit.source, "seed": self.seed})

    def save(self, path) -> None:
        """Write the posterior as arviz NetCDF: ``arviz.from_netcdf`` reads its chains, and
        :meth:`load` the whole result back (:mod:`hdid._posterior.saved`)."""
        from .saved import save

        save(self, path)

    @classmethod
    def load(cls, path, *, fit=None, effects: dict | None = None) -> PosteriorResult:
        """Read a posterior written by :meth:`save` (or ``hdid fit --posterior --chains
        OUT.nc``): draws, chain, diagnostics, warnings, priors and the fit's summary come
        back; ``fit`` the live :class:`~hdid.FitResult` it was sampled from (default: the
        saved one, without its log: no ``predict``/``plot_predictive``); ``effects`` as in
        :meth:`hdid.FitResult.load`."""
        from .saved import load

        return load(path, fit, effects, cls)

    def plot_corner(self, names=None, *, ax=None):
        """Corner plot of the free parameters (and the stick-band half-width). Draws into
        ``ax`` (a K×K array of axes, K = len(names); a new figure without it) and returns
        the K×K axes.

        Each axis is in the parameter's unit with its power of ten in the label (no
        matplotlib offset text, which overlapped between panels); the least-squares optimum
        is marked (orange lines); a posterior that did not converge says so in red.
        """
        import corner
        import matplotlib.lines as mlines

        specs = self.fit.model.parameter_specs()
        names = names or ([n for n in self.samples if np.ptp(self.samples[n]) > 0]
                          + ["stick_band_halfwidth_rad"])
        values = {**self.samples, **self.derived}
        lsq = dict(self.fit.model.float_values())
        cols, labels, marks = [], [], []
        for n in names:
            v = np.asarray(values[n], dtype=float)
            unit = specs[n].unit if n in specs else ("rad" if n.endswith("_rad") else "")
            m = float(np.nanmedian(np.abs(v))) or 1.0
            e = int(np.floor(np.log10(m))) if np.isfinite(m) and m > 0 else 0
            e = e if abs(e) >= 3 else 0
            f = 10.0 ** -e
            cols.append(v * f)
            scale = f"10^{{{e}}}\\," if e else ""
            labels.append(f"{n}\n[${scale}$ {unit}]" if scale else f"{n}\n[{unit}]" if unit else n)
            ref = lsq.get(n)
            if ref is None and n in getattr(self.fit, "derived", {}):
                ref = self.fit.derived[n][0]
            marks.append(None if ref is None else float(ref) * f)
        data = np.column_stack(cols)
        from .._results._plot import figure_of, new_figure

        K = len(cols)
        if ax is None:
            fig = new_figure(figsize=(2.0 * K + 1, 2.0 * K + 1))
            fig.subplots(K, K)
        else:
            fig = figure_of(ax)
        fig = corner.corner(data, labels=labels, quantiles=[0.16, 0.5, 0.84], fig=fig,
                            show_titles=True, title_fmt=".3g", truths=marks,
                            truth_color="C1", max_n_ticks=3, label_kwargs={"fontsize": 9},
                            title_kwargs={"fontsize": 8})
        from matplotlib.ticker import ScalarFormatter

        for ax in fig.axes:  # values are scaled to ~1–1000: no offset or exponent text
            for axis in (ax.xaxis, ax.yaxis):
                if isinstance(axis.get_major_formatter(), ScalarFormatter):
                    axis.get_major_formatter().set_useOffset(False)
                    axis.get_major_formatter().set_scientific(False)
        handles = [mlines.Line2D([], [], color="C1", label="least-squares optimum")]
        fig.legend(handles=handles, loc="upper right", fontsize=9, frameon=False)
        if not self.converged:
            name, what = self.convergence.worst if self.convergence is not None else ("?", "")
            fig.text(0.5, 0.99, f"NOT CONVERGED (worst: {name}, {what}) — intervals unreliable",
                     color="C3", ha="center", va="top", fontsize=11, weight="bold")
        return np.asarray(fig.axes, dtype=object).reshape(K, K)

    def plot_predictive(self, *, ax=None, n_draws: int = 100, seed: int = 0):
        """Posterior-predictive check of each run (:func:`hdid._results._plot.plot_predictive`);
        returns the axes."""
        from .._results._plot import plot_predictive

        return plot_predictive(self, ax=ax, n_draws=n_draws, seed=seed)

    def plot(self, *, ax=None):
        """The result protocol's figure (as ``FitResult.plot``): the stick band's posterior
        beside the logged rest points (:meth:`plot_band`; a loaded result draws it too).
        Returns the Axes; never saves (``hdid.save_figure``)."""
        return self.plot_band(ax=ax)

    def plot_band(self, *, ax=None):
        """The stick band's posterior beside the logged rest points; returns the Axes."""
        from .._results._plot import plot_band

        return plot_band(self, ax=ax)


