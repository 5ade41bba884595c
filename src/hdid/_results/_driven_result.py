"""Results of driven and joint fits: report, JSON summary, plots (lmfit style)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import jax.numpy as jnp
import numpy as np

from .._config import float64_methods
from ._summaries import ParameterEstimate
from .._problems._driven_evaluate import _simulate
from ._plot import new_figure
from ._saved import SCHEMA_VERSION, finite, hdid_version, model_structure, save, sha256


@float64_methods
@dataclass
class DrivenFitResult:
    """Outcome of :func:`hdid.fit_driven` / :func:`hdid.fit_joint`.

    ``joint`` is the fitted :class:`~hdid.DrivenJoint` (its ``model`` the WG-side
    :class:`~hdid.Model`). :meth:`report` gives text, :meth:`to_dict` JSON,
    :meth:`plot` measured-vs-model WG angles and :meth:`plot_kinematic_error` the
    paper's Fig. 3 (output kinematic error split into positional and flexibility parts);
    :meth:`save` writes the JSON and :meth:`load` reads it back.
    """

    source: str
    kind: str
    joint: Any
    parameters: dict[str, ParameterEstimate]
    positional: dict[str, Any]
    rms: dict[str, float]
    correlation: dict[tuple[str, str], float]
    warnings: list[str]
    notes: list[str]
    data: Any = field(repr=False)
    problem: Any = field(repr=False)
    u: np.ndarray = field(repr=False)
    covariance: np.ndarray = field(repr=False)
    labels: list[str] = field(repr=False)
    order_bic: dict[int, float] | None = None
    chi2_reduced: float = float("nan")
    wall_time_s: float = float("nan")
    #: the logs fitted (the driven one first), as given
    sources: list[str] = field(default_factory=list)
    #: free unknowns with a physical meaning (parameters and positional coefficients) and
    #: their covariance in physical units (inf where undetermined)
    covariance_names: list[str] = field(default_factory=list)
    parameter_covariance: np.ndarray = field(default=None, repr=False)
    #: SHA-256 of each input file by path (set by the CLI; else computed from ``sources``)
    input_sha256: dict[str, str | None] | None = None
    #: options of the fit (the CLI's, as given), written to the JSON
    options: dict | None = None
    #: hdid version that made the fit (None: this one; set for a loaded result)
    hdid_version: str | None = None
    #: a loaded result's values that were computed from the log (``units_problem``,
    #: ``kinematic_split``, ``input_hold``), as its file gives them; None for a fit
    saved: dict[str, Any] | None = field(default=None, repr=False)

    @property
    def values(self) -> dict[str, float]:
        return {n: p.value for n, p in self.parameters.items()}

    @property
    def model(self):
        return self.joint.model

    @property
    def units_problem(self) -> str | None:
        """One line when the driven log's numbers are implausible for their declared units
        (time in s, angles in rad), with the fix (``time [ms]``, ``theta [deg]``,
        ``--counts-per-rev``); ``None`` when they are plausible
        (:func:`hdid._units.implausible_units`: its sample rate, and its largest motor
        speed — a driven motor turns freely, so its angle range tells nothing)."""
        from .._units import implausible_units

        if self.data is None and self.saved is not None:
            return self.saved["units_problem"]
        data = self.data
        return implausible_units(
            sample_period=float(data.sample_period), swing=0.0,
            ratio=float(self.joint.ratio), band_halfwidth=0.0,
            step=float(data.step), geared_spring=False, speed=_top_speed(data))

    # -- curves ---------------------------------------------------------------------
    def _driven_problem(self):
        p = self.problem
        return (p.parts[0], np.asarray(self.u)[np.asarray(p.index[0])]) if hasattr(p, "parts") else (p, self.u)

    def curves_by_run(self) -> list[dict[str, np.ndarray]]:
        """:meth:`curves` with each run's windows joined back, padding dropped: one dict
        of 1-D arrays per run, in log order."""
        c = self.curves()
        runs = np.asarray(self.data.run_of_window)
        out = []
        for i in range(len(self.data.run_names)):
            rows = np.nonzero(runs == i)[0]
            joined = {}
            for k, v in c.items():
                if k == "weight":
                    continue
                joined[k] = np.concatenate([v[w][c["weight"][w] > 0] for w in rows])
            out.append(joined)
        return out

    def curves(self) -> dict[str, np.ndarray]:
        """Per-window arrays ``(W, T)``: measured and simulated WG angle, measured kinematic
        error and its modelled positional and flexibility parts, and the weight mask."""
        self._need_log("curves()")
        problem, u = self._driven_problem()
        joint, sim = _simulate(problem, jnp.asarray(u))
        N = joint.ratio
        theta = np.asarray(problem.theta)
        out = {
            "time": np.asarray(problem.times),
            "theta": theta,
            "theta_model": np.asarray(sim["theta"]),
            "weight": np.asarray(problem.weight),
        }
        if problem.has_output:
            out["kinematic_error"] = np.asarray(problem.theta_out) + theta / N
            out["positional"] = np.asarray(joint.positional(theta))
            out["flexibility"] = np.asarray(
                joint.flexibility_error(problem.load_torque, sim["output_direction"])
            )
        return out

    # -- text -----------------------------------------------------------------------
    def report(self) -> str:
        problem = self.units_problem  # a wrong unit is the first thing a user reads
        lines = ([problem.upper()[:6] + problem[6:]] if problem else []) + [
            f"hdid {self.kind} fit: {self.source}", ""]
        lines.append(f"{'parameter':<11} {'value':>12} {'std':>10}  unit")
        for p in self.parameters.values():
            if p.fixed:
                std = "fixed"
            elif math.isinf(p.std):
                std = "undetermined"
            else:
                std = f"{p.std:.3g}"
            lines.append(f"{p.name:<11} {p.value:>12.5g} {std:>10}  {p.unit}")
        pe = self.positional
        if pe:
            lines += ["", f"positional error (eq. 3): order {pe['order']}"
                      + (" (chosen by BIC)" if self.order_bic else "")
                      + f", peak-to-peak {pe['peak_to_peak_rad']:.3g} rad (output)"]
            for name, c in pe["coefficients"].items():
                std = "fixed" if c["std"] is None else f"{c['std']:.2g}"
                lines.append(f"  {name:<8} {c['value']:>12.4g} ± {std}")
            ks = self.kinematic_split
            if ks:
                lines.append(
                    f"kinematic error split (Fig. 3): positional RMS {ks['positional_rms_rad']:.3g} rad, "
                    f"flexibility-induced {ks['flexibility_min_rad']:.3g} … "
                    f"{ks['flexibility_max_rad']:.3g} rad (RMS {ks['flexibility_rms_rad']:.3g}), "
                    f"left over {ks['residual_rms_rad']:.3g} rad")
            if self.order_bic:
                best = min(self.order_bic.values())
                lines.append("  ΔBIC by order: " + ", ".join(
                    f"{k}: {v - best:+.1f}" for k, v in self.order_bic.items()))
        lines += ["", "residual RMS:"]
        for k, v in self.rms.items():
            lines.append(f"  {k:<28} {v:.3g}")
        if self.correlation:
            lines += ["", "high correlations: " + ", ".join(
                f"{a}~{b} {c:+.3f}" for (a, b), c in self.correlation.items())]
        for w in self.warnings:
            lines.append(f"WARNING: {w}")
        for n in self.notes:
            lines.append(f"note: {n}")
        return "\n".join(lines)

    @property
    def kinematic_split(self) -> dict[str, float]:
        """Sizes of the two parts of the output kinematic error over the log (paper Fig. 3):
        the positional error ``θ̃_p(θ)`` and the flexibility-induced ``T_k⁻¹(τ_l+τ_fout)``."""
        if not self.positional:
            return {}
        if self.data is None and self.saved is not None:
            return dict(self.saved["kinematic_split"])
        c = self.curves()
        w = c["weight"] > 0
        pos = c["positional"][w] - np.mean(c["positional"][w])
        flex = c["flexibility"][w]
        left = (c["kinematic_error"] - c["positional"] - c["flexibility"])[w]
        return {
            "positional_rms_rad": float(np.sqrt(np.mean(pos**2))),
            "flexibility_min_rad": float(flex.min()),
            "flexibility_max_rad": float(flex.max()),
            "flexibility_rms_rad": float(np.sqrt(np.mean(flex**2))),
            "residual_rms_rad": float(np.sqrt(np.mean(left**2))),
        }

    def to_dict(self) -> dict[str, Any]:
        """Strict-JSON summary (the ``--json`` schema of a driven or joint fit): a NaN or
        infinite value as ``None``."""
        return finite({
            "units_problem": self.units_problem,
            "source": self.source,
            "kind": self.kind,
            "parameters": {n: p.to_dict() for n, p in self.parameters.items()},
            "positional_error": self.positional or None,
            "kinematic_error_split": self.kinematic_split or None,
            "rms": dict(self.rms),
            "chi2_reduced": self.chi2_reduced,
            "correlations": {f"{a}~{b}": c for (a, b), c in self.correlation.items()},
            "warnings": list(self.warnings),
            "notes": list(self.notes),
            "wall_time_s": self.wall_time_s,
            **self._provenance(),
        })

    def _provenance(self) -> dict[str, Any]:
        """The fields the fit JSON has for reuse (``hdid._results._saved.provenance``): version, the
        input files and their SHA-256, the options, the model's structure, and the full
        correlation and covariance of the parameters and positional coefficients."""
        digests = self.input_sha256 or {}
        inputs = [{"path": p, "sha256": digests.get(p) or sha256(p)}
                  for p in (self.sources or [self.source])]
        names = list(self.covariance_names)
        cov = (np.asarray(self.parameter_covariance, dtype=float) if names
               else np.zeros((0, 0)))
        with np.errstate(invalid="ignore", divide="ignore"):
            sd = np.sqrt(np.diag(cov))
            corr = cov / np.outer(sd, sd)
        corr[~np.isfinite(corr)] = np.nan  # undetermined: null in the JSON
        np.fill_diagonal(corr, np.where(np.isfinite(sd), 1.0, np.nan))
        specs = self.joint.parameter_specs()
        units = [specs[n].unit if n in specs else "" for n in names]
        model = model_structure(self.joint.model)
        model["output_friction_tau_fout"] = float(self.joint.tau_fout)
        model["positional_error_order"] = int(self.joint.positional.order)
        model["input_hold"] = self.input_hold
        return {
            "schema_version": SCHEMA_VERSION,
            "hdid_version": self.hdid_version or hdid_version(),
            "input": inputs[0],
            "inputs": inputs,
            "options": dict(self.options or {}),
            "model": model,
            "correlation": {"parameters": names, "matrix": corr.tolist()},
            "covariance": {"parameters": names, "units": units, "matrix": cov.tolist()},
        }

    @property
    def input_hold(self) -> str:
        """How the motor torque was taken between samples: "zoh" (held) or "foh" (linear)."""
        if self.data is None and self.saved is not None:
            return str(self.saved["input_hold"])
        problem, _ = self._driven_problem()
        return str(getattr(problem, "input_hold", "zoh"))

    # -- file -----------------------------------------------------------------------
    def save(self, path) -> None:
        """Write the result as JSON (what ``hdid fit DRIVEN.csv --json`` writes; schema in
        ``hdid/schema/driven.schema.json``). :meth:`load` reads it back."""
        save(self, path)

    @classmethod
    def load(cls, path, *, effects: dict | None = None) -> DrivenFitResult:
        """Read a result written by :meth:`save` or ``hdid fit DRIVEN.csv --json``: the
        same :meth:`report` and :meth:`to_dict`, and the fitted ``joint`` (its WG model,
        output friction and positional error). The log does not come back: :meth:`plot`
        draws the positional error only, and :meth:`curves` needs a refit. ``effects``
        maps class names to your own effect classes (those not in hdid)."""
        from ._driven_saved import load

        return load(path, effects, cls)

    def _need_log(self, what: str) -> None:
        if self.data is None:
            from .._errors import HdidError

            raise HdidError(f"{what} needs the log, and this result was loaded from a file: "
                            "refit with hdid.fit_driven(log, model=result.model)")

    # -- plots ----------------------------------------------------------------------
    def plot(self, *, ax=None):
        """Measured (dots) and simulated (line, drawn above them) WG angle of every driven
        run, and below it the residual ``logged − model`` (the sign of the free-motion
        figure) with the quantization floor ±σ shaded. ``ax``: one Axes (the top panel
        only) or two (top, residual); without it a two-panel figure is made. Returns the
        axes drawn into. A result read by :meth:`load` has no log: it draws the fitted
        positional error over one WG turn (one Axes)."""
        if self.data is None:
            return self._plot_positional(ax)
        given = ax
        if ax is None:
            given = new_figure(figsize=(8, 6)).subplots(
                2, 1, sharex=True, gridspec_kw={"height_ratios": [2, 1]})
        if hasattr(given, "plot"):
            ax, residual_ax = given, None
        else:
            ax, residual_ax = np.asarray(given, dtype=object).ravel()
        runs = self.curves_by_run()
        for name, c in zip(self.data.run_names, runs):
            line, = ax.plot(c["time"], c["theta_model"], "-", lw=1.2, zorder=3,
                            label=f"run {name} model")
            ax.plot(c["time"], c["theta"], ".", ms=2, alpha=0.5, zorder=2,
                    color=line.get_color(), label=f"run {name} logged")
            if residual_ax is not None:
                residual_ax.plot(c["time"], c["theta"] - c["theta_model"], "-", lw=0.6,
                                 color=line.get_color())
        ax.set_ylabel("WG angle (log units)")
        ax.set_title("driven runs: logged (dots) and simulated from the motor torque (line)")
        ax.legend(fontsize=7)
        if residual_ax is not None:
            sigma = self.data.sigma
            residual_ax.axhspan(-sigma, sigma, color="0.85", zorder=0,
                                label=f"±σ floor ({self.data.step_source})")
            residual_ax.axhline(0.0, color="k", lw=0.5)
            residual_ax.set_ylabel("logged − model")
            residual_ax.set_xlabel("time [s]")
            residual_ax.legend(fontsize=7)
        else:
            ax.set_xlabel("time [s]")
        return given

    def _plot_positional(self, ax):
        """The fitted positional error ``θ̃_p(θ)`` (paper eq. 3) over one WG turn."""
        if ax is None:
            ax = new_figure(figsize=(6, 3.5), constrained_layout=True).subplots()
        elif not hasattr(ax, "plot"):
            ax = np.asarray(ax, dtype=object).ravel()[0]
        theta = np.linspace(0.0, 2 * np.pi, 721)
        ax.plot(theta, np.asarray(self.joint.positional(theta)), "-", lw=1.2,
                label=f"positional error θ̃_p, order {self.joint.positional.order}")
        ax.set_xlabel("WG angle θ [rad, motor encoder frame]")
        ax.set_ylabel("output error [rad]")
        ax.set_title(f"{self.source} (loaded: refit with the log to see the runs)", fontsize=9)
        ax.legend(fontsize=7)
        return ax

    def plot_kinematic_error(self, *, ax=None, run: int = 0):
        """Paper Fig. 3: the output kinematic error ``θ_out + θ/N`` of one run, split into
        the positional error ``θ̃_p(θ)`` and the flexibility-induced error
        ``T_k⁻¹(τ_l + τ_fout)``. Returns the Axes."""
        self._need_log("plot_kinematic_error()")
        if not self.data.has_output:
            raise ValueError(f"{self.source}: the log has no output angle, so no kinematic error")
        c = self.curves_by_run()[run]
        if ax is None:
            ax = new_figure(figsize=(8, 4)).subplots()
        t = c["time"]
        ax.plot(t, c["kinematic_error"], ".", ms=3, color="0.5", label="logged θ_out + θ/N")
        ax.plot(t, c["positional"], "-", lw=1, label="positional error θ̃_p")
        ax.plot(t, c["flexibility"], "-", lw=1, label="flexibility T_k⁻¹(τ_l+τ_fout)")
        ax.plot(t, c["positional"] + c["flexibility"], "k-", lw=0.8, label="model total")
        ax.set_xlabel("time [s]")
        ax.set_ylabel("output kinematic error [rad]")
        ax.set_title(f"run {self.data.run_names[run]}: kinematic error = positional + flexibility")
        ax.legend(fontsize=7)
        return ax


def _top_speed(data) -> float:
    """The 99th percentile of the driven log's motor speed [rad/s as declared], from a
    local cubic at the logged times (a percentile, so that one reading's glitch does not
    decide the log's units)."""
    from .._problems._driven_problem import _smooth_speed

    weight = np.asarray(data.weight)
    speeds = [np.abs(_smooth_speed(np.asarray(data.theta)[i, : int(weight[i].sum())],
                                   np.asarray(data.times)[i, : int(weight[i].sum())]))
              for i in range(weight.shape[0])]
    speeds = np.concatenate(speeds) if speeds else np.zeros(0)
    return float(np.percentile(speeds, 99)) if speeds.size else 0.0
