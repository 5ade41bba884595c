"""Results of driven and joint fits: report, JSON summary, plots (lmfit style)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from ._config import float64_methods
from ._summaries import ParameterEstimate
from ._transforms import derivative

#: Correlations above this are listed in the report.
HIGH_CORRELATION = 0.95

#: How the note on time-correlated residuals begins (a joint fit replaces the one of its
#: driven-alone start, whose correlation time is stale).
_CORRELATED_NOTE = "the WG residual is correlated in time"


@float64_methods
@dataclass
class DrivenFitResult:
    """Outcome of :func:`hdid.fit_driven` / :func:`hdid.fit_joint`.

    ``joint`` is the fitted :class:`~hdid.DrivenJoint` (its ``model`` the WG-side
    :class:`~hdid.Model`). :meth:`report` gives text, :meth:`to_dict` JSON,
    :meth:`plot` measured-vs-model WG angles and :meth:`plot_kinematic_error` the
    paper's Fig. 3 (output kinematic error split into positional and flexibility parts).
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

    @property
    def values(self) -> dict[str, float]:
        return {n: p.value for n, p in self.parameters.items()}

    @property
    def model(self):
        return self.joint.model

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
        lines = [f"hdid {self.kind} fit: {self.source}", ""]
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
        from ._saved import finite

        return finite({
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
        """The fields the fit JSON has for reuse (``hdid._saved.provenance``): version, the
        input files and their SHA-256, the options, the model's structure, and the full
        correlation and covariance of the parameters and positional coefficients."""
        from ._saved import SCHEMA_VERSION, hdid_version, model_structure, sha256

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
            "hdid_version": hdid_version(),
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
        problem, _ = self._driven_problem()
        return str(getattr(problem, "input_hold", "zoh"))

    # -- plots ----------------------------------------------------------------------
    def plot(self, ax=None, residual_ax=None):
        """Measured (dots) and simulated (line, drawn above them) WG angle of every driven
        run, and below it the residual ``logged − model`` (the sign of the free-motion
        figure) with the quantization floor ±σ shaded. Without ``ax`` a two-panel figure
        is made; with ``ax`` alone only the top panel is drawn there. Returns ``ax``."""
        import matplotlib.pyplot as plt

        if ax is None:
            _, (ax, residual_ax) = plt.subplots(
                2, 1, figsize=(8, 6), sharex=True, gridspec_kw={"height_ratios": [2, 1]})
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
        return ax

    def plot_kinematic_error(self, ax=None, run: int = 0):
        """Paper Fig. 3: the output kinematic error ``θ_out + θ/N`` of one run, split into
        the positional error ``θ̃_p(θ)`` and the flexibility-induced error
        ``T_k⁻¹(τ_l + τ_fout)``."""
        import matplotlib.pyplot as plt

        if not self.data.has_output:
            raise ValueError(f"{self.source}: the log has no output angle, so no kinematic error")
        c = self.curves_by_run()[run]
        if ax is None:
            _, ax = plt.subplots(figsize=(8, 4))
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


@eqx.filter_jit
def _simulate(problem, u):
    return problem.simulate(u)


@eqx.filter_jit
def _residuals(problem, u):
    return problem.residuals(u)


@eqx.filter_jit
def _predict(problem, u):
    return problem.predict(u)


@eqx.filter_jit
def _res_jac(problem, u):
    return problem.residuals_and_jacobian(u)


def analyse_driven(
    problem, u, *, data, notes, order_bic=None, free_preps=(), extra_names=(),
) -> DrivenFitResult:
    """Covariance (Gauss–Newton, null directions undetermined), estimates, RMS, flags."""
    from ._covariance import _covariance

    u = np.asarray(u, dtype=float)
    joint_problem = hasattr(problem, "parts")
    dproblem = problem.parts[0] if joint_problem else problem
    du = u[np.asarray(problem.index[0])] if joint_problem else u
    joint = dproblem.joint(jnp.asarray(du))
    r, J = map(np.asarray, _res_jac(problem, jnp.asarray(u)))
    n_rows = int(np.sum(np.abs(r) > 0))
    dof = max(n_rows - u.size, 1)
    chi2_red = float(r @ r) / dof
    cov, null_s, scale = _scaled_covariance(J.T @ J, _covariance)
    inflate = max(1.0, chi2_red)
    tau_int = _residual_correlation_time(dproblem, r)
    inflate *= tau_int
    specs = joint.parameter_specs()
    values = joint.float_values()
    where = {n: i for i, n in enumerate(dproblem.free)}
    if joint_problem:
        for j, n in enumerate(extra_names):
            where[n] = dproblem.n_unknowns + j
        values.update(_extra_values(problem, u, extra_names))
    stds, grads = {}, {}
    for n, k in where.items():
        g = np.zeros(u.size)
        g[k] = float(derivative(specs[n], u[k]))
        grads[n] = g
        stds[n] = (math.inf if _undetermined_scaled(g, null_s, scale)
                   else math.sqrt(max(g @ cov @ g, 0.0) * inflate))
    params = {}
    for n, spec in specs.items():
        if n.startswith("pos_"):
            continue
        fixed = n not in where
        params[n] = ParameterEstimate(
            name=n, value=values[n], std=0.0 if fixed else stds[n], unit=spec.unit,
            fixed=fixed, doc=spec.doc,
            note="not determined by the data" if not fixed and math.isinf(stds[n]) else "",
        )
    positional = {}
    if dproblem.has_output:
        coeffs = {
            n: {"value": values[n], "std": stds.get(n) if n in where else None}
            for n in joint.positional.names()
        }
        positional = {
            "order": joint.positional.order,
            "coefficients": coeffs,
            "peak_to_peak_rad": float(joint.positional.peak_to_peak()),
            "bic": {int(k): float(v) for k, v in (order_bic or {}).items()},
        }
    corr = {}
    names = list(where)
    for a_i, a in enumerate(names):
        for b in names[a_i + 1:]:
            va, vb = grads[a] @ cov @ grads[a], grads[b] @ cov @ grads[b]
            if math.isinf(stds[a]) or math.isinf(stds[b]) or va <= 0 or vb <= 0:
                continue
            c = float(grads[a] @ cov @ grads[b] / math.sqrt(va * vb))
            if abs(c) > HIGH_CORRELATION:
                corr[(a, b)] = c
    rms = _rms(problem, u, data, dproblem, du)
    # physical covariance of every free parameter and positional coefficient, the delta
    # method through each one's transform (the same as the stds above); inf along the
    # null directions, where the std is undetermined
    cov_names = list(where)
    G = np.array([grads[n] for n in cov_names]).reshape(len(cov_names), u.size)
    phys_cov = G @ (cov * inflate) @ G.T
    phys_cov = 0.5 * (phys_cov + phys_cov.T)  # the pseudo-inverse is symmetric to rounding
    bad = np.array([math.isinf(stds[n]) for n in cov_names], dtype=bool)
    phys_cov[bad, :] = math.inf
    phys_cov[:, bad] = math.inf
    warnings = []
    if rms["wg_rad"] > 3 * rms["wg_floor_rad"]:
        warnings.append(
            f"the WG residual RMS is {rms['wg_rad'] / rms['wg_floor_rad']:.1f}× the "
            "quantization floor: the model misses part of the driven motion (see plot())"
        )
    if "kinematic_rad" in rms and rms["kinematic_rad"] > 3 * rms["kinematic_floor_rad"]:
        warnings.append(
            f"the kinematic-error RMS is {rms['kinematic_rad'] / rms['kinematic_floor_rad']:.1f}× "
            "its floor: see plot_kinematic_error()"
        )
    # a joint fit passes on the driven-alone fit's notes: its correlation time is stale
    notes = [n for n in notes if not n.startswith(_CORRELATED_NOTE)]
    if tau_int > 1.0:
        notes = list(notes) + [
            f"{_CORRELATED_NOTE} (integrated correlation time {tau_int:.3g} "
            "samples, model error rather than encoder noise): the stds are scaled up by "
            f"√{tau_int:.3g}, the effective number of independent residuals"]
    warnings += _parameter_flags(params, specs, du, where, dproblem)
    spring = [p.name for p in joint.spring.parameters]
    if dproblem.has_output and any(n in where and math.isinf(stds[n]) for n in spring):
        notes = list(notes) + [
            "the spring is not determined: the twist T_k⁻¹(τ_l + τ_fout) only flips with the "
            "output friction unless the load torque varies, which fixes tau_fout/k1 and "
            "tau_c + tau_fout/N but not each; log a varying load_torque, or fit jointly with "
            "a free-motion log (hdid fit FREE.csv DRIVEN.csv --joint)"
        ]
    labels = dproblem.labels(data.window_names) + list(extra_names)
    return DrivenFitResult(
        source=data.source if not joint_problem else " + ".join(
            [data.source] + [p.source for p in free_preps]),
        kind="joint" if joint_problem else "driven",
        joint=joint.replace(**{n: values[n] for n in extra_names}) if extra_names else joint,
        parameters=params, positional=positional, rms=rms, correlation=corr,
        warnings=warnings, notes=list(notes), data=data, problem=problem, u=u,
        covariance=cov * inflate, labels=labels, order_bic=order_bic, chi2_reduced=chi2_red,
        sources=[data.source] + [p.source for p in free_preps],
        covariance_names=cov_names, parameter_covariance=phys_cov,
    )


#: Residual scatter (in units of the floor) above which the residuals are taken as
#: model error and their correlation in time widens the stds.
CORRELATED_ABOVE_FLOOR = 3.0


def _residual_correlation_time(dproblem, r) -> float:
    """Integrated autocorrelation time [samples] of the WG residuals within windows,
    ``1 + 2 Σ ρ_k`` summed until ρ first drops below 0 (Geyer's initial positive
    sequence), when the residual is model error (RMS > ``CORRELATED_ABOVE_FLOOR`` of its
    σ); 1 otherwise. Least squares treats residuals as independent; a smooth model error
    shared by neighbouring samples carries ``n/τ`` samples' worth of information."""
    W, T = dproblem.times.shape
    w = np.asarray(dproblem.weight) > 0
    rw = np.asarray(r[: W * T]).reshape(W, T) * w
    n = w.sum()
    scatter = math.sqrt(float((rw**2).sum()) / max(n, 1)) * float(getattr(dproblem, "noise_scale", 1.0))
    if scatter <= CORRELATED_ABOVE_FLOOR or T < 4:
        return 1.0
    rw = rw - (rw.sum(axis=1, keepdims=True) / np.maximum(w.sum(axis=1, keepdims=True), 1)) * w
    var = float((rw**2).sum())
    if var <= 0:
        return 1.0
    tau = 1.0
    for k in range(1, T // 2):
        rho = float((rw[:, k:] * rw[:, :-k]).sum()) / var
        if rho <= 0:
            break
        tau += 2.0 * rho
    return tau


def _parameter_flags(params, specs, u, where, dproblem) -> list[str]:
    """Warnings for fitted parameters the data do not fix: an undetermined or ``nan``
    std, a value at a bound of its interval, a positive parameter driven to 0 (its std
    larger than its value) — as the free-motion report does."""
    out = []
    for n, p in params.items():
        if p.fixed:
            continue
        spec = specs[n]
        if math.isnan(p.std):
            out.append(f"{n}: the std is nan (the fit's curvature there is not positive); "
                       "the value is not determined by the data")
        elif math.isinf(p.std):
            out.append(f"{n}: not determined by the data")
        elif spec.transform == "log" and p.std > p.value:
            out.append(f"{n} = {p.value:.4g} ± {p.std:.3g}: consistent with 0; the data do "
                       "not show this effect")
        if isinstance(spec.transform, tuple):
            _, lo, hi = spec.transform
            if min(p.value - lo, hi - p.value) < 0.01 * (hi - lo):
                out.append(f"{n} = {p.value:.4g} is at a bound of its range [{lo}, {hi}]")
    return out


def _scaled_covariance(fisher: np.ndarray, covariance):
    """:func:`hdid._covariance._covariance` after Jacobi scaling.

    The unknowns of a driven or joint fit differ in sensitivity by ~10 orders (the
    inertia of a driven log against an output-friction sign flip), so an eigenvalue cut
    relative to the largest would call well-measured directions null. Scaling by the
    diagonal first makes the cut about correlation, not units; unknowns the data do not
    touch at all (the velocity of a window that starts at rest) stay exactly null.
    """
    d = np.sqrt(np.clip(np.diag(fisher), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    cov_s, null_s = covariance(fisher / np.outer(d, d))
    return cov_s / np.outer(d, d), null_s, d


def _undetermined_scaled(g: np.ndarray, null_s: np.ndarray, d: np.ndarray) -> bool:
    """Whether a quantity with gradient ``g`` (optimiser space) has a component along a
    null direction — tested in the scaled space, where the null basis is orthonormal
    (in the original space a null direction's physical components can be 1e-5 of its
    nuisance components and would slip under any threshold)."""
    from ._covariance import _undetermined

    return _undetermined(g / d, null_s)


def _extra_values(problem, u, extra_names):
    out = {}
    for part, idx in zip(problem.parts[1:], problem.index[1:]):
        vals = part.values_np(u[np.asarray(idx)])
        out.update({n: vals[n] for n in extra_names if n in vals})
    return out


def _rms(problem, u, data, dproblem, du) -> dict[str, float]:
    joint, sim = _simulate(dproblem, jnp.asarray(du))
    w = np.asarray(dproblem.weight) > 0
    N = joint.ratio
    err = (np.asarray(sim["theta"]) - np.asarray(dproblem.theta))[w]
    out = {"wg_rad": float(np.sqrt(np.mean(err**2))), "wg_floor_rad": data.sigma}
    if dproblem.has_output:
        theta = np.asarray(dproblem.theta)
        kin = np.asarray(dproblem.theta_out) + theta / N - np.asarray(
            joint.kinematic_error(dproblem.theta, dproblem.load_torque, sim["output_direction"]))
        out["kinematic_rad"] = float(np.sqrt(np.mean(kin[w] ** 2)))
        out["kinematic_floor_rad"] = float(dproblem.sigma_kin)
    if hasattr(problem, "parts"):
        for i, (part, idx) in enumerate(zip(problem.parts[1:], problem.index[1:])):
            pu = jnp.asarray(np.asarray(u)[np.asarray(idx)])
            pred = np.asarray(_predict(part, pu))
            m = np.asarray(part.weight) > 0
            out[f"free_motion[{i}]_rad"] = float(
                np.sqrt(np.mean((pred - np.asarray(part.theta))[m] ** 2)))
            out[f"free_motion[{i}]_floor_rad"] = float(part.step) / math.sqrt(12)
    return out
