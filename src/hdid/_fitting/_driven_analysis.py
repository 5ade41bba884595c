"""The analysis of a driven or joint fit at its optimum: covariance (scaled where the
residual is correlated in time), correlations, undetermined directions, parameter flags,
RMS per part; it builds the :class:`~hdid._results._driven_result.DrivenFitResult`."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .._covariance import scaled_covariance, undetermined_scaled
from .._results._summaries import ParameterEstimate
from .._models._transforms import derivative
from .._problems._driven_evaluate import _predict, _res_jac, _simulate
from .._results._driven_result import DrivenFitResult


#: Correlations above this are listed in the report.
HIGH_CORRELATION = 0.95

#: How the note on time-correlated residuals begins (a joint fit replaces the one of its
#: driven-alone start, whose correlation time is stale).
_CORRELATED_NOTE = "the WG residual is correlated in time"


def analyse_driven(
    problem, u, *, data, notes, order_bic=None, free_preps=(), extra_names=(),
) -> DrivenFitResult:
    """Covariance (Gauss–Newton, null directions undetermined), estimates, RMS, flags."""
    u = np.asarray(u, dtype=float)
    joint_problem = hasattr(problem, "parts")
    dproblem = problem.parts[0] if joint_problem else problem
    du = u[np.asarray(problem.index[0])] if joint_problem else u
    joint = dproblem.joint(jnp.asarray(du))
    r, J = map(np.asarray, _res_jac(problem, jnp.asarray(u)))
    n_rows = int(np.sum(np.abs(r) > 0))
    dof = max(n_rows - u.size, 1)
    chi2_red = float(r @ r) / dof
    cov, null_s, scale = scaled_covariance(J.T @ J)
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
        stds[n] = (math.inf if undetermined_scaled(g, null_s, scale)
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
    warnings = list(getattr(data, "log_notes", ()))  # runs split at breaks in the time column
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
