"""Predicted outcome of each candidate experiment from the linearised Fisher information.

For a candidate at the current fit: its noise-free readings (the exact simulator, rounded
to its encoder step: the observation weights the fit would give them — a stretch of
identical readings counts once, :func:`hdid._simulation._prepare.prepare`), the Jacobian
of every run in its local unknowns, and the Fisher information

    F = Σ_runs J_runᵀ W J_run / σ²  +  prior precision,    σ² = step²/12 + σ_x²,

over the physical parameters *and the nuisances* (each run's release instant and start
angle, each set-up's offset), as the fit estimates them. ``σ_x`` is noise beyond the
quantization that the current fit's residual shows (``√(rms² − step²/12)``, 0 at the
floor). The physical parameters' covariance is the corresponding block of ``F⁻¹``
(nuisances marginalised); standard errors in physical units by the delta method, derived
quantities (stick band, natural frequency, torques per inertia) through their Jacobian.
A direction of ``F``'s null space (free motion's joint scale of torques and inertia when
the inertia is free without added inertia) gives an infinite std, not a small one.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._covariance import _covariance, _undetermined
from .._errors import HdidError
from .._log import Log, Run
from .._models._transforms import derivative, from_unconstrained
from .._simulation._prepare import prepare
from . import _stack
from ._candidates import Experiment


@dataclass
class Prediction:
    """What one candidate would determine (physical units; ``inf``: not determined)."""

    experiment: Experiment
    std: dict[str, float] = field(default_factory=dict)
    std_data: dict[str, float] = field(default_factory=dict)
    prior_ratio: dict[str, float] = field(default_factory=dict)
    derived_std: dict[str, float] = field(default_factory=dict)
    names: tuple[str, ...] = ()
    cov_u: np.ndarray | None = None      # physical block of F⁻¹ (transformed space)
    full_cov: np.ndarray | None = None   # every unknown (for the linearity check)
    n_effective: float = math.nan
    sigma: float = math.nan
    logdet: float = math.nan             # log det of the physical covariance (common names)
    error: str | None = None
    honesty: list[str] = field(default_factory=list)
    weights: list[np.ndarray] = field(default_factory=list)
    null: np.ndarray | None = None       # null space of F (undetermined directions)
    scale: np.ndarray | None = None      # the unknowns' scales the null space is in
    stack_rows: tuple | None = None      # (Stacked, rows) where its runs were simulated
    #: expected 2 ln LR of the separated pair ``(A true, B true)`` (``separate=``)
    separation: tuple[float, float] | None = None
    #: how ``separation`` was computed: "rival fitted globally" (a value), "upper bound"
    #: (the rival refitted locally) or "linearised"
    separation_kind: str | None = None


def parameter_names(fit) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``(free, all)``: the fit's free physical parameters, and those plus the inertia
    (freed by candidates with added inertia), in the model's order."""
    specs = fit.model.parameter_specs()
    free = tuple(n for n in specs if n in fit.parameters and not fit.parameters[n].fixed)
    extra = tuple(n for n in specs if n == "inertia" and n not in free)
    every = tuple(n for n in specs if n in free or n in extra)
    return free, every


def prior_sd(fit, names) -> dict[str, float]:
    """The fit's weak prior rows (transformed space): its problem's, else the model's."""
    problem = getattr(fit, "problem", None)
    out = {}
    if problem is not None and hasattr(problem, "prior_on"):
        on, sd = np.asarray(problem.prior_on), np.asarray(problem.prior_sd)
        for i, n in enumerate(problem.free):
            if on[i] and n in names:
                out[n] = float(sd[i])
        return out
    specs = fit.model.parameter_specs()
    for n in names:
        if specs[n].prior is not None and not fit.parameters[n].fixed:
            out[n] = float(specs[n].prior[1])
    return out


def extra_noise(fit) -> float:
    """Noise [rad] beyond the encoder's rounding that the fit's residual shows."""
    floor = fit.resolution_rad / math.sqrt(12.0)
    rms = fit.rms_residual_rad
    if not (math.isfinite(rms) and rms > floor):
        return 0.0
    return math.sqrt(rms**2 - floor**2)


def max_substep(fit) -> float:
    problem = getattr(fit, "problem", None)
    if problem is not None and hasattr(problem, "max_substep"):
        return float(problem.max_substep)
    from .._fitting._fit import substep_for

    f = fit.derived.get("natural_frequency_hz", (math.nan, 0.0))[0]
    return substep_for(f)


def readings(e: Experiment, theta: np.ndarray, quantized: bool, offsets=None) -> np.ndarray:
    """Encoder readings of the runs of ``e`` from spring-frame trajectories ``(R, n)``."""
    off = np.array([e.offsets[s] for s in e.setups]) if offsets is None else offsets
    x = theta + off[:, None]
    return np.round(x / e.resolution) * e.resolution if quantized else x


def as_log(e: Experiment, theta_enc: np.ndarray, source: str, quantized: bool) -> Log:
    n = e.n_samples
    t = np.arange(n) / e.rate
    runs = [Run(name=str(k + 1), time=t, theta=theta_enc[k, :n], setup=e.setups[k],
                added_inertia=e.added_inertia[k]) for k in range(e.n_runs)]
    return Log(source=source, runs=tuple(runs), sample_period=1.0 / e.rate,
               resolution=e.resolution if quantized else None,
               resolution_source="given" if quantized else None)


def predict(fit, experiments: list[Experiment]) -> tuple[list[Prediction], dict]:
    """Predictions for every experiment, and the derived quantities' values."""
    free, every = parameter_names(fit)
    quantized = bool(fit.resolution_known)
    sigma_x = extra_noise(fit)
    priors = prior_sd(fit, every)
    sub = max_substep(fit)
    groups: dict[float, list[tuple[int, Experiment]]] = {}
    for i, e in enumerate(experiments):
        groups.setdefault(float(e.rate), []).append((i, e))
    out: list[Prediction | None] = [None] * len(experiments)
    stacks = []
    for cands in groups.values():
        st = _stack.stack(cands, fit, every, sub)
        theta, J = _stack.evaluate(st)
        stacks.append(st)
        for pos, e in cands:
            rows = st.index[pos]
            out[pos] = _one(fit, e, theta[rows, :e.n_samples], J[rows, :e.n_samples],
                            free, every, priors, sigma_x, quantized)
            out[pos].stack_rows = (st, rows)
    amp = max(abs(a) for e in experiments for a in e.amplitudes)
    values, jac = _derived(fit, every, 2.0 * amp)
    for p in out:
        if p.error is None:
            p.derived_std = _derived_std(p, values, jac, every)
    return out, values


def _one(fit, e: Experiment, theta, J, free, every, priors, sigma_x, quantized) -> Prediction:
    pred = Prediction(experiment=e)
    if not (np.all(np.isfinite(theta)) and np.all(np.isfinite(J))):
        pred.error = "the simulation diverged for this design (non-finite trajectory)"
        return pred
    try:
        prep = prepare(as_log(e, readings(e, theta, quantized), e.name, quantized))
    except HdidError as exc:
        pred.error = f"not a usable log: {exc}".replace("\n", " ")
        return pred
    w = prep.weight[:, :e.n_samples]
    pred.weights = list(w)
    sigma = math.sqrt((e.resolution**2 / 12.0 if quantized else 0.0) + sigma_x**2)
    if not quantized:
        sigma = max(sigma, e.resolution / math.sqrt(12.0))
    pred.sigma = sigma
    pred.n_effective = float(np.sum(w**2))
    keep = [i for i, n in enumerate(every) if n in free or (n == "inertia" and e.free_inertia)]
    names = tuple(every[i] for i in keep)
    P, R = len(names), e.n_runs
    setups = e.setup_names
    n_unk = P + 2 * R + len(setups)
    F = np.zeros((n_unk, n_unk))
    Pall = len(every)
    cols = keep + [Pall, Pall + 1, Pall + 2]
    for j in range(R):
        A = (w[j][:, None] / sigma) * J[j][:, cols]
        idx = list(range(P)) + [P + j, P + R + j, P + 2 * R + setups.index(e.setups[j])]
        F[np.ix_(idx, idx)] += A.T @ A
    prec = np.zeros(n_unk)
    for i, n in enumerate(names):
        if n in priors:
            prec[i] = 1.0 / priors[n] ** 2
    # unknowns in their own units (rad, log-parameters, logistic release) differ by orders
    # of magnitude: invert with the diagonal scaled to one, so that the null-space
    # tolerance (1e-10 of the largest eigenvalue) judges information, not units
    D = np.sqrt(np.where(np.diag(F) > 0, np.diag(F), 1.0))
    cov, null = _scaled(F + np.diag(prec), D)
    cov_d, null_d = _scaled(F, D)
    eye = np.eye(n_unk)
    u = _stack.physical(fit, names)
    specs = fit.model.parameter_specs()
    for i, n in enumerate(names):
        d = float(abs(derivative(specs[n], u[i])))
        s = math.inf if _undetermined(eye[i], null) else math.sqrt(max(cov[i, i], 0.0))
        sd = math.inf if _undetermined(eye[i], null_d) else math.sqrt(max(cov_d[i, i], 0.0))
        pred.std[n] = d * s
        pred.std_data[n] = d * sd
        if n in priors:
            pred.prior_ratio[n] = s / priors[n]
    pred.names = names
    pred.cov_u = cov[:P, :P]
    pred.full_cov = cov
    pred.null = null
    pred.scale = D
    common = [i for i, n in enumerate(names) if n in free]
    sub = cov[np.ix_(common, common)]
    sign, logdet = np.linalg.slogdet(sub)
    pred.logdet = float(logdet) if sign > 0 and all(
        math.isfinite(pred.std[names[i]]) for i in common) else math.inf
    return pred


def _scaled(F: np.ndarray, D: np.ndarray):
    """``F⁻¹`` (pseudo-inverse) and the null space, computed on ``F / (D Dᵀ)``; the null
    basis is in the scaled unknowns (test a gradient ``g`` as ``g / D``; a unit vector
    is tested as it is)."""
    cov_s, null = _covariance(F / np.outer(D, D))
    return cov_s / np.outer(D, D), null


def _derived(fit, names, theta_max: float):
    """Derived quantities and their Jacobian in the transformed physical parameters."""
    specs = fit.model.parameter_specs()
    base = jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=float), fit.model)
    u = jnp.asarray(_stack.physical(fit, names))
    vals, jac = _derived_program(base, tuple(names), tuple(specs[n] for n in names), u,
                                 jnp.asarray(theta_max))
    return ({k: float(v) for k, v in vals.items()},
            {k: np.asarray(v) for k, v in jac.items()})


@eqx.filter_jit
def _derived_program(base, names, specs, u, theta_max):
    def quantities(v):
        values = {n: from_unconstrained(s, v[i]) for i, (n, s) in enumerate(zip(names, specs))}
        return base.replace(**values).derived(theta_max)

    return quantities(u), jax.jacfwd(quantities)(u)


def _derived_std(p: Prediction, values: dict, jac: dict, every) -> dict[str, float]:
    out = {}
    pos = [every.index(n) for n in p.names]
    P = len(p.names)
    for k in values:
        g = np.zeros(p.full_cov.shape[0])
        g[:P] = np.asarray(jac[k])[pos]
        if not np.all(np.isfinite(g)):
            out[k] = math.nan
        elif _undetermined(g / p.scale, p.null):
            out[k] = math.inf
        else:
            out[k] = float(math.sqrt(max(g @ p.full_cov @ g, 0.0)))
    return out
