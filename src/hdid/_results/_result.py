"""Fit results: a readable report, a JSON-able summary and a plot (lmfit style)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from .._config import float64_methods
from ._summaries import ParameterEstimate, RunSummary, StartSummary
from .._problems._evaluate import dense as _dense, prediction_and_jacobian
from ._plot import plot_fit
from ._residuals import plot_residuals, residual_frame, whiteness
from ._saved import covariance_matrix, extras, finite, load, save


@float64_methods
@dataclass
class FitResult:
    """Outcome of :func:`hdid.fit`.

    Use :meth:`report` for text, :meth:`to_dict` for JSON and :meth:`plot` for a
    measured-vs-model figure. ``model`` is the fitted :class:`~hdid.Model`.
    """

    source: str
    model: Any
    parameters: dict[str, ParameterEstimate]
    derived: dict[str, tuple[float, float]]
    runs: list[RunSummary]
    setups: dict[str, float]
    rms_residual_rad: float
    resolution_rad: float
    resolution_known: bool
    sample_period: float
    n_effective: float
    n_unknowns: int
    noise_scale: float
    correlation: dict[tuple[str, str], float]
    warnings: list[str]
    starts: StartSummary
    problem: Any = field(repr=False)
    u: np.ndarray = field(repr=False)
    covariance: np.ndarray = field(repr=False)
    labels: list[str] = field(repr=False)
    band_bracket: tuple[float, float] | None = None
    wall_time_s: float = float("nan")
    #: SHA-256 of the input log file (set by the CLI; else computed from ``source``)
    input_sha256: str | None = None
    #: options of the fit (the CLI's, as given), written to the JSON
    options: dict | None = None
    #: hdid version that made the fit (None: this one; set for a loaded result)
    hdid_version: str | None = None
    #: "given", "estimated" (an encoder grid found in the readings) or "noise" (readings
    #: on no grid: ``resolution_rad`` is ``σ·√12`` of the noise estimated from the log)
    resolution_source: str = "estimated"
    #: printing precision of the readings [rad] (``None``: numbers never printed) and why
    #: no encoder step was found in them (:attr:`hdid.Log.print_unit`, ``resolution_note``)
    print_unit: float | None = None
    resolution_note: str | None = None
    #: runs whose first reading was taken as the hold, the release in the first interval
    #: (:attr:`hdid.Log.first_reading_held`, :mod:`hdid._fitting._first_reading`)
    first_reading_held: tuple[str, ...] = ()
    #: the time column's print unit [s] where the stamps are instants rounded to it, and
    #: the floor with that rounding in it [rad] (:mod:`hdid._simulation._timing`)
    time_print_unit: float | None = None
    timing_floor_rad: float | None = None
    #: RMS print error of the encoder's levels [rad] where the readings are printed to a
    #: unit within a few steps, in the floor then (:mod:`hdid._simulation._print_rounding`)
    print_rounding_rad: float | None = None

    # -- accessors --------------------------------------------------------------------
    @property
    def values(self) -> dict[str, float]:
        return {n: p.value for n, p in self.parameters.items()}

    @property
    def stick_band_halfwidth_rad(self) -> float:
        return self.derived["stick_band_halfwidth_rad"][0]

    @property
    def units_problem(self) -> str | None:
        """One line when the log's numbers are implausible for their declared units (time
        in s, angles in rad), with the fix (``time [ms]``, ``theta [deg]``,
        ``--counts-per-rev``); ``None`` when they are plausible
        (:func:`hdid._units.implausible_units`)."""
        from .._units import implausible_units

        swing = max((abs(r.theta0 - r.rest_logged) for r in self.runs), default=0.0)
        band = self.derived.get("stick_band_halfwidth_rad", (0.0, 0.0))[0]
        effects = {e.name for e in self.model.effects}
        return implausible_units(
            sample_period=self.sample_period, swing=swing, ratio=float(self.model.ratio),
            band_halfwidth=band if math.isfinite(band) else 0.0,
            step=self.resolution_rad if self.resolution_source != "noise" else None,
            geared_spring="k1" in self.parameters and "gravity" not in effects,
        )

    @property
    def quantization_floor_rad(self) -> float:
        """RMS error of rounding to the encoder step, ``step/√12`` — with the rounding of
        the time stamps where they are rounded instants (the weighted RMS a correct model
        reaches then: :attr:`hdid._simulation._prepare.Prepared.floor`)."""
        if self.timing_floor_rad:
            return self.timing_floor_rad
        return math.sqrt(self.resolution_rad**2 / 12 + (self.print_rounding_rad or 0.0) ** 2)

    def predict(self, times=None) -> np.ndarray:
        """Model encoder readings per run at the logged times, or at ``times`` ``(R, T')``."""
        import jax.numpy as jnp

        self._need_log("predict()")
        t = self.problem.times if times is None else jnp.asarray(times)
        theta, _, _ = _dense(self.problem, jnp.asarray(self.u), t)
        off = np.array([r.offset for r in self.runs])
        return np.asarray(theta) + off[:, None]

    def predict_std(self, times=None) -> np.ndarray:
        """Standard error of :meth:`predict` ``(R, T)`` from the fit's uncertainty: a
        confidence band on the model, not on a new reading (add the noise for that).

        Delta method: ``σ(t)² = g(t)ᵀ C g(t)``, with ``g`` the sensitivity of the predicted
        reading to every unknown of the fit (physical parameters and per-run nuisances:
        release instant, start angle, offset), forward-mode through the simulator, and ``C``
        their covariance (the one behind the report's std). It is widest where the data
        pin the model least: at the release (its instant is uncertain while the gear moves
        fastest) and around the stop.
        """
        return self._predict_with_std(times)[1]

    def _predict_with_std(self, times=None) -> tuple[np.ndarray, np.ndarray]:
        import jax.numpy as jnp

        self._need_log("predict_std()")
        t = self.problem.times if times is None else jnp.asarray(times)
        pred, J = map(np.asarray, prediction_and_jacobian(self.problem, jnp.asarray(self.u), t))
        C = np.asarray(self.covariance)
        var = np.einsum("rtk,kl,rtl->rt", J, C, J)
        return pred, np.sqrt(np.clip(var, 0.0, None))

    # -- output -----------------------------------------------------------------------
    def to_dict(self) -> dict[str, Any]:
        """Strict-JSON summary (the ``hdid fit --json`` schema): plain Python numbers, a
        NaN or infinite value (an undetermined std) as ``None``."""
        return finite({
            "units_problem": self.units_problem,
            "source": self.source,
            "parameters": {n: p.to_dict() for n, p in self.parameters.items()},
            "nuisance": {
                r.name: {
                    "release_time": r.release_time,
                    "release_time_std": r.release_time_std,
                    "offset": r.offset,
                    "theta0": r.theta0,
                    "setup": r.setup,
                }
                for r in self.runs
            },
            "limits": list(getattr(self, "limits", None) or []),
            "restarted_from": getattr(self, "restarted_from", None),
            "rms_residual_rad": self.rms_residual_rad,
            "rms_residual_counts": (self.rms_residual_rad / self.resolution_rad
                                    if self.resolution_source != "noise" else None),
            "resolution": self.resolution_rad,
            "resolution_source": self.resolution_source,
            "print_unit": self.print_unit,
            "resolution_note": self.resolution_note,
            "first_reading_held": list(self.first_reading_held),
            # (only where the stamps' rounding is in the floor: hdid._simulation._timing)
            **({"time_print_unit": self.time_print_unit,
                "timing_floor_rad": self.timing_floor_rad} if self.timing_floor_rad else {}),
            **({"print_rounding_rad": self.print_rounding_rad} if self.print_rounding_rad else {}),
            "quantization_floor_rad": self.quantization_floor_rad,
            "stick_band_halfwidth_rad": self.stick_band_halfwidth_rad,
            "stick_band_halfwidth_std_rad": self.derived["stick_band_halfwidth_rad"][1],
            "stick_band_bracket_rad": list(self.band_bracket) if self.band_bracket else None,
            "derived": {k: {"value": v, "std": s} for k, (v, s) in self.derived.items()},
            "runs": [r.to_dict() for r in self.runs],
            "setups": {s: {"offset": o} for s, o in self.setups.items()},
            "warnings": list(self.warnings),
            "starts": self.starts.to_dict(),
            "effective_observations": self.n_effective,
            "unknowns": self.n_unknowns,
            "noise_scale_vs_quantization": self.noise_scale,
            "wall_time_s": self.wall_time_s,
            **self._reuse_dict(),
        })

    def report(self) -> str:
        """A readable text report."""
        problem = self.units_problem
        lines = ([problem.upper()[:6] + problem[6:]] if problem else []) + [
            f"hdid fit: {self.source}", ""]
        lines.append(f"{'parameter':<10} {'value':>12} {'std':>11} {'rel':>7}  unit")
        for p in self.parameters.values():
            if p.fixed:
                std, rel = "(fixed)", ""
            else:
                std = f"{p.std:11.3g}"
                rel = f"{100 * p.std / abs(p.value):6.1f}%" if p.value else ""
            flag = "  *" if p.note else ""
            lines.append(f"{p.name:<10} {p.value:12.5g} {std:>11} {rel:>7}  {p.unit}{flag}")
        if any(p.note for p in self.parameters.values()):
            lines.append("  * see warnings")
        lines.append("")
        lines.append("derived (torques relative to the inertia are what free motion fixes):")
        order = ["stick_band_halfwidth_rad", "natural_frequency_hz", "damping_ratio",
                 "k1/inertia", "k2/inertia", "tau_c/inertia", "tau_s/inertia", "c_v/inertia"]
        keys = [k for k in order if k in self.derived] + [
            k for k in self.derived if k not in order and not k.startswith("stick_band_")
        ]
        for k in keys:
            v, s = self.derived[k]
            rel = f" ({100 * s / abs(v):.1f}%)" if v else ""
            lines.append(f"  {k:<26} {v:12.5g} ± {s:.3g}{rel}")
        lines.append("")
        floor = self.quantization_floor_rad
        if self.resolution_source == "noise":
            fit_sigma = floor * self.noise_scale if math.isfinite(self.noise_scale) else floor
            why = f" ({self.resolution_note})" if self.resolution_note else ""
            lines.append(
                f"RMS residual {self.rms_residual_rad:.3e} rad; the readings lie on no encoder "
                f"grid{why}, so the noise is estimated: σ ≈ {fit_sigma:.3e} rad from the fit's "
                f"residuals ({floor:.3e} rad from the log alone); pass --resolution STEP if "
                "you know the sensor's"
            )
        else:
            how = "given" if self.resolution_source == "given" else "found in the readings"
            if self.print_unit and self.resolution_source == "estimated":
                how += f" (printed to {self.print_unit:.3g} rad)"
            lines.append(
                f"encoder step {self.resolution_rad:.4g} rad {how}"
            )
            lines.append(
                f"RMS residual {self.rms_residual_rad:.3e} rad = "
                f"{self.rms_residual_rad / self.resolution_rad:.3f} counts "
                + (f"(floor {floor:.3e} rad = {floor / self.resolution_rad:.3g} counts: the "
                   "step's rounding"
                   + (" and the readings' print rounding" if self.print_rounding_rad else "")
                   + (f" and the time stamps' to {self.time_print_unit:.3g} s"
                      if self.timing_floor_rad else "") + ")"
                   if self.timing_floor_rad or self.print_rounding_rad else
                   f"(quantization floor {floor:.3e} rad = 0.289 counts)")
            )
        lo = self.derived["stick_band_lower_rad"][0]
        hi = self.derived["stick_band_upper_rad"][0]
        hw, hws = self.derived["stick_band_halfwidth_rad"]
        scale = max((abs(r.theta0) for r in self.runs), default=1.0)
        if max(abs(lo), abs(hi)) <= 1e-9 * scale:
            lines.append("stick band: none (the model holds no torque at rest)")
        else:
            lines.append(
                f"stick band (WG, from spring zero): [{lo:+.4f}, {hi:+.4f}] rad, "
                f"half-width {hw:.4f} ± {hws:.4f} rad"
            )
        if self.band_bracket and self.band_bracket[0] <= self.band_bracket[1]:
            b0, b1 = self.band_bracket
            lines.append(
                f"  the data bracket the half-width to [{b0:.4f}, {b1:.4f}] rad "
                "(largest |rest point| logged, smallest |slide-on reversal|)"
            )
        lines.append("")
        lines.append(
            f"{'run':<6} {'setup':<6} {'n':>4} {'release [s]':>12} {'theta0':>9} "
            f"{'rest logged':>12} {'rest model':>11} "
            f"{'RMS [counts]' if self.resolution_source != 'noise' else 'RMS [noise σ]':>12}"
        )
        for r in self.runs:
            lines.append(
                f"{r.name:<6} {r.setup:<6} {r.n_samples:>4} {r.release_time:12.5f} "
                f"{r.theta0:+9.4f} {r.rest_logged:+12.4f} {r.rest_model:+11.4f} "
                f"{r.rms_rad / (self.resolution_rad if self.resolution_source != 'noise' else floor):12.3f}"
            )
        for s, o in self.setups.items():
            lines.append(f"set-up {s}: encoder reading at spring zero {o:+.5f} rad")
        st = self.starts
        dchi = ", ".join(f"{c - st.costs[st.best]:.3g}" for c in np.sort(st.costs))
        lines.append("")
        lines.append(
            f"starts: Δχ² to the best = {dchi}; {int(st.same_minimum().sum())} of "
            f"{len(st.costs)} within Δχ² < 1, largest relative parameter spread among them "
            f"{max(st.spread().values(), default=0):.2g}; {self.wall_time_s:.2f} s"
        )
        if self.warnings:
            lines.append("")
            lines.append("warnings:")
            lines += [f"  - {w}" for w in self.warnings]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.report()

    def _reuse_dict(self) -> dict[str, Any]:
        """Model structure, correlation/covariance, version, input checksum, options."""
        return extras(self)

    def parameter_covariance(self):
        """``(names, matrix)``: the free parameters' covariance in physical units."""
        return covariance_matrix(self)

    def save(self, path) -> None:
        """Write the result as JSON (what ``hdid fit --json`` writes; schema in
        ``hdid/schema/fit.schema.json``). :meth:`load` reads it back."""
        save(self, path)

    @classmethod
    def load(cls, path, *, effects: dict | None = None) -> FitResult:
        """Read a result written by :meth:`save` or ``hdid fit --json``.

        The report, parameters, derived values, runs and the fitted ``model`` come back
        (``hdid.simulate(result.model, …)``, or a warm start with
        ``hdid.fit(log, model=result.model, start_from_model=True)``); the log does not,
        so :meth:`predict` needs a refit and :meth:`plot` draws the runs' RMS only.
        ``effects`` maps class names to your own effect classes (those not in hdid).
        """
        return load(path, effects, cls)

    def _need_log(self, what: str) -> None:
        if self.problem is None:
            from .._errors import HdidError

            raise HdidError(
                f"{what} needs the log, and this result was loaded from a file: refit with "
                "hdid.fit(log, model=result.model, start_from_model=True)"
            )

    def plot(self, *, ax=None, fine_rate: float = 20000.0):
        """Measured vs model for every run (top) with residuals in counts (bottom); the
        model carries its ±2σ confidence band (:meth:`predict_std`). Returns the axes drawn
        into; never saves (``hdid.save_figure(ax, "fit.png")``) or chooses a backend. A
        result read by :meth:`load` has no log: it draws its runs' RMS residual against
        the quantization floor (one Axes).

        Parameters
        ----------
        ax:
            ``(2, R)`` array of matplotlib axes to draw into (angle above, residual below,
            one column per run), or one Axes (every run's release-to-rest stretch overlaid,
            no residuals); a new figure otherwise.
        """
        return plot_fit(self, ax=ax, fine_rate=fine_rate)

    # -- residual views (see hdid._results._residuals) -------------------------------------------
    def residuals(self):
        """Per-sample frame: measured, model, residual, model state and phase."""
        return residual_frame(self)

    def whiteness(self, max_lag: int | None = None):
        """Ljung–Box and quantization-floor test of the moving residual."""
        return whiteness(self, max_lag)

    def plot_residuals(self, *, ax=None):
        """Residual vs time, WG angle, velocity, deflection; ACF; spectrum (2×3 axes,
        returned)."""
        return plot_residuals(self, ax=ax)
