"""Uncertainty and identifiability at the optimum: covariance, flags, derived quantities."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .._covariance import null_in_u, scaled_covariance, undetermined_scaled
from .._problems._evaluate import dense as _dense
from .._problems._evaluate import jacobian as _jacobian
from .._simulation._prepare import Prepared
from .._problems._problem import Problem
from .._results._result import FitResult
from .._results._summaries import ParameterEstimate, RunSummary, StartSummary
from .._models._transforms import derivative
from .._problems._derived import BracketTooCostly, _derived, band_bracket
from ._trust import (AT_BOUND, HIGH_CORRELATION, _carried,  # noqa: F401
                     _shape_warnings, _trust_warnings)
from ._plausibility import (RESIDUAL_FLOOR_FACTOR, integrator_warning,  # noqa: F401
                            motion_warning, plausibility_warnings)


#: A direction in the optimiser's space whose data-only standard deviation exceeds this
#: (0.5 ≈ ±50 % in a log-parameter) is reported as not determined by the data.
ILL_DETERMINED_STD = 0.5
#: Posterior std above this fraction of the prior sd: the prior, not the data, decides.
PRIOR_DOMINATED = 0.7
#: Correlations above HIGH_CORRELATION (from ._trust) are reported.
#: Stribeck shape is only visible when the motion goes well past the Stribeck velocity.
STRIBECK_VISIBLE = 5.0
#: A run whose rest reading differs from its hold reading by more than this many encoder
#: counts moved (one count of flicker is not motion).
MOVED_COUNTS = 1.5


def unknown_labels(problem: Problem, prep: Prepared) -> list[str]:
    labels = list(problem.free)
    if problem.release_free:
        labels += [f"release_time[{n}]" for n in prep.run_names]
    labels += [f"theta0[{n}]" for n in prep.run_names]
    labels += [f"offset[{s}]" for s in prep.setup_names]
    if problem.n_moving:
        labels += [f"omega0[{prep.run_names[i]}]" for i in np.asarray(problem.moving_index)]
    return labels


def analyse(
    problem: Problem, prep: Prepared, u, starts: StartSummary, fixed: set[str], *,
    bracket: bool = True, precomputed: dict | None = None,
) -> FitResult:
    """Covariance, identifiability flags, derived quantities and per-run summaries at ``u``.

    ``bracket=False`` skips the band bracket (the event-driven reference simulation of
    every run, the slowest part); ``precomputed`` holds the JAX parts evaluated elsewhere
    (:func:`hdid.fit` and the batch, :mod:`hdid._fitting._vfit`, from stored programs):
    ``"jacobian"`` ``(J, r)``, ``"dense"`` ``(theta, omega, stuck)`` and ``"derived"``
    ``(values, jacobian)``.

    The steps, in order (each a function below, each adding its warnings in this order):
    the noise scale (:func:`_noise`), the covariance with and without the priors
    (:func:`_uncertainty`), which parameters the data determine (:func:`_identifiability`)
    and which pairs they confuse (:func:`_correlations`), the parameter estimates
    (:func:`_parameters`) and derived quantities, the per-run summaries
    (:func:`_run_summaries`) and what the runs show about the fit (:func:`_run_warnings`:
    Stribeck visibility, the stick band's data bracket, runs held, still moving or cut),
    then the trust and plausibility checks; :class:`~hdid.FitResult` assembles them.
    """
    pre = precomputed or {}
    u = jnp.asarray(u) if not pre else np.asarray(u)
    J, r = map(np.asarray, pre["jacobian"] if "jacobian" in pre else _jacobian(problem, u))
    P = problem.n_physical
    labels = unknown_labels(problem, prep)
    warnings: list[str] = list(getattr(prep, "log_notes", ()))  # split / still runs
    s2, s2_used, dof = _noise(problem, prep, r, warnings)
    with np.errstate(over="ignore", invalid="ignore"):  # |J| ~ 1e164 overflows JᵀJ
        finite = np.isfinite(r).all() and np.isfinite(J).all() and np.isfinite(J.T @ J).all()
    if not finite:
        from .._errors import FitError
        raise FitError(
            f"{prep.source}: the fit diverged (non-finite or overflowing residuals or "
            "sensitivities at its optimum); check the units (time in s, angles in rad or "
            "--resolution), the ratio and the inertia, or fix parameters the log cannot determine")
    fisher_data, cov, null, std_u, std_u_data = _uncertainty(problem, J, s2_used)
    flags = _identifiability(problem, labels, J, fisher_data, cov, std_u, std_u_data, warnings)
    corr = _correlations(labels, P, cov, std_u, warnings)
    values, model, params = _parameters(problem, u, std_u, flags)
    derived = _derived(problem, u, cov, null, pre.get("derived"))
    runs, rms_all, offset, moving = _run_summaries(problem, prep, u, std_u, pre)
    bracket = _run_warnings(prep, runs, values, model, derived, bracket, warnings)
    warnings += _trust_warnings(problem, u, params, std_u, values)
    warnings += motion_warning(problem, prep, moving)
    warnings += integrator_warning(problem, prep, values,
                                   derived.get("natural_frequency_hz", (math.nan, math.nan)))
    warnings += plausibility_warnings(prep, model, values, rms_all,
                                      derived.get("natural_frequency_hz", (math.nan,))[0],
                                      problem.n_unknowns)

    return FitResult(
        source=prep.source,
        model=model,
        parameters=params,
        derived=derived,
        runs=runs,
        setups={s: float(offset[k]) for k, s in enumerate(prep.setup_names)},
        rms_residual_rad=rms_all,
        resolution_rad=prep.resolution,
        resolution_known=prep.resolution_known,
        resolution_source=prep.resolution_source,
        print_unit=getattr(prep, "print_unit", None),
        resolution_note=getattr(prep, "resolution_note", None),
        time_print_unit=getattr(prep, "time_print_unit", None),
        timing_floor_rad=prep.floor if getattr(prep, "time_scale", None) is not None else None,
        print_rounding_rad=getattr(prep, "print_rms", 0.0) or None,
        sample_period=prep.sample_period,
        n_effective=prep.n_effective,
        n_unknowns=problem.n_unknowns,
        noise_scale=math.sqrt(s2) if dof > 0 else float("nan"),
        correlation={(labels[i], labels[j]): float(corr[i, j]) for i in range(P) for j in range(i + 1, P)},
        band_bracket=bracket,
        warnings=warnings,
        starts=starts,
        problem=problem,
        u=np.asarray(u),
        covariance=cov,
        labels=labels,
    )


def analyse_first_finite(problem: Problem, prep: Prepared, U, order, summary, stored, fixed,
                         **options) -> tuple[FitResult, int]:
    """:func:`analyse` of the first row of ``U`` in ``order`` (best first) with finite
    residuals and sensitivities, and its index: an optimum at the end of a parameter's range
    (world log08: v_s 7e-4 rad/s under δ = 3.2 overflows ∂/∂v_s) is passed over, with a
    warning; none finite: the best one's error. ``summary(i)``, ``stored(u)``: its start
    summary, its precomputed analysis (the caller's ``precomputed`` for the best)."""
    from .._errors import FitError

    for k, i in enumerate(int(j) for j in order):
        pre = options.pop("precomputed", None) if k == 0 else None
        try:
            res = analyse(problem, prep, U[i], summary(i), fixed=fixed,
                          precomputed=pre if pre is not None else stored(U[i]), **options)
        except FitError as e:
            first = e if k == 0 else first
            continue
        res.warnings += [f"the {k} best optimum(s) have overflowing sensitivities (a "
                         "parameter at the end of its range): the best with finite ones is "
                         "reported"] * (k > 0)
        return res, i
    raise first


def _noise(problem: Problem, prep: Prepared, r, warnings: list[str]):
    """``(s2, s2_used, dof)``: the residual variance in units of the floor's (χ²/dof), and
    the one the covariance uses — 1 where there are no degrees of freedom, else at least 1:
    never more precision than the floor (the noise estimated from the log, or the rounding
    of a known grid)."""
    n_eff = prep.n_effective
    dof = n_eff - problem.n_unknowns
    rss = float(np.sum(r**2))
    s2 = rss / dof if dof > 0 else float("nan")
    if not dof > 0:
        warnings.append(
            f"only {n_eff:.1f} effective observations for {problem.n_unknowns} unknowns: "
            "standard errors are not available; add runs or fix parameters"
        )
        s2_used = 1.0
    elif prep.resolution_source == "noise":
        # readings on no grid: never claim more precision than the noise floor estimated
        # from the log, itself at least the simulator's accuracy (1e-4 of the swing)
        s2_used = max(s2, 1.0)
        if s2 < 0.01:
            warnings.append(
                f"the residual ({math.sqrt(s2):.2g}× the estimated noise floor) is far below what "
                "a real sensor gives: the readings look noiseless (simulated, or smoothed); the "
                "standard errors then rest on the floor of the simulator's accuracy and are "
                "lower bounds"
            )
    else:
        # readings on a known grid carry at least the rounding's variance (step²/12, exact
        # for readings spread over the steps); a residual below it is the χ²_ν/ν scatter of
        # a fit with few degrees of freedom, not more precise readings (a world log, 18
        # effective readings for 10 unknowns: χ²/ν 0.53 shrank every error 0.72×, tau_c 3.8
        # of them from its truth)
        s2_used = max(s2, 1.0)
    return s2, s2_used, dof


def _uncertainty(problem: Problem, J, s2_used: float):
    """The Fisher information of the data ``JᵀJ/s²``, the covariance of the unknowns with
    the prior rows and its null space, and the standard deviations of the unknowns with
    and without the priors (∞ along an undetermined direction). The null space is decided
    after Jacobi scaling (:func:`hdid._covariance.scaled_covariance`): a log-parameter run
    towards 0 has a column ~its value, and an unscaled cut would hold it fixed and give the
    parameters it trades with their conditional variance."""
    P = problem.n_physical
    fisher_data = J.T @ J / s2_used
    prior_prec = np.zeros(problem.n_unknowns)
    prior_on = np.asarray(problem.prior_on)
    prior_sd = np.asarray(problem.prior_sd)
    prior_prec[:P] = np.where(prior_on, 1.0 / prior_sd**2, 0.0)
    cov, null_s, d = scaled_covariance(fisher_data + np.diag(prior_prec))
    (cov_data, null_data, d_data), eye = scaled_covariance(fisher_data), np.eye(len(prior_prec))

    def std(c, null, scale):  # ∞ along an undetermined direction
        return np.array([math.inf if undetermined_scaled(eye[i], null, scale)
                         else math.sqrt(max(c[i, i], 0.0)) for i in range(len(eye))])

    return fisher_data, cov, null_in_u(null_s, d), std(cov, null_s, d), std(
        cov_data, null_data, d_data)


def _identifiability(problem: Problem, labels, J, fisher_data, cov, std_u, std_u_data,
                     warnings: list[str]) -> dict[str, str]:
    """What the data determine: a flag per physical parameter that they do not (no effect,
    only a combination, set by the prior, poorly determined), and warnings for the
    combinations (eigen-directions of the data's Fisher information wider than
    ``ILL_DETERMINED_STD``), the flags and the friction shape."""
    P = problem.n_physical
    prior_on = np.asarray(problem.prior_on)
    prior_sd = np.asarray(problem.prior_sd)
    flags: dict[str, str] = {}
    col_norm = np.linalg.norm(J, axis=0)
    for i, name in enumerate(labels[:P]):
        if col_norm[i] == 0:
            flags[name] = "has no effect on these data"
        elif not np.isfinite(std_u[i]):
            flags[name] = "not determined: only a combination with other parameters is"
        elif std_u_data[i] > ILL_DETERMINED_STD:
            if prior_on[i] and std_u[i] > PRIOR_DOMINATED * prior_sd[i]:
                flags[name] = "not determined by the data: the weak prior sets it"
            else:
                flags[name] = (
                    f"poorly determined by the data alone (±{_pct(std_u_data[i])} from data)"
                )
    evals, evecs = np.linalg.eigh(fisher_data)
    combos = []
    for lam, vec in zip(evals, evecs.T):
        std_dir = 1.0 / math.sqrt(lam) if lam > 1e-10 * max(evals.max(), 0.0) else math.inf
        if std_dir <= ILL_DETERMINED_STD:
            continue
        members = [labels[i] for i in np.argsort(-np.abs(vec)) if abs(vec[i]) > 0.3]
        if len(members) >= 2:
            combos.append(members)
    for members in combos[:3]:
        warnings.append(
            "only a combination of " + ", ".join(members) + " is determined by the data"
            + (
                " (free motion fixes torques relative to the inertia: fix the inertia, give "
                "a prior, or add runs with known added inertia)"
                if "inertia" in members
                else ""
            )
        )
    for name, why in flags.items():
        warnings.append(f"{name}: {why}")
    warnings += _shape_warnings(problem, flags, cov, std_u)
    return flags


def _correlations(labels, P: int, cov, std_u, warnings: list[str]) -> np.ndarray:
    """The physical parameters' correlation matrix (0 where undetermined); pairs above
    ``HIGH_CORRELATION`` are named in a warning."""
    with np.errstate(invalid="ignore"):
        corr = cov[:P, :P] / np.outer(std_u[:P], std_u[:P]).clip(1e-300)
    corr = np.where(np.isfinite(corr), corr, 0.0)
    pairs = sorted(
        ((abs(corr[i, j]), labels[i], labels[j], corr[i, j]) for i in range(P) for j in range(i + 1, P)
         if abs(corr[i, j]) > HIGH_CORRELATION),
        reverse=True,
    )
    if pairs:
        shown = ", ".join(f"{a}~{b} ({c:+.3f})" for _, a, b, c in pairs[:6])
        more = f" and {len(pairs) - 6} more" if len(pairs) > 6 else ""
        warnings.append(
            f"strongly correlated (|r| > {HIGH_CORRELATION}): {shown}{more}; the data fix "
            "mainly combinations of these"
        )
    return corr


def _parameters(problem: Problem, u, std_u, flags: dict[str, str]):
    """``(values, model, estimates)`` at ``u`` (fixed ones included); each standard error by
    the delta method through the parameter's transform."""
    values = problem.values_np(u)
    model = problem.base.replace(**values)
    specs = model.parameter_specs()
    params: dict[str, ParameterEstimate] = {}
    for name, spec in specs.items():
        if name in problem.free:
            i = problem.free.index(name)
            # undetermined stays ∞ (not 0·∞ = NaN where a log-parameter's value underflowed)
            std = (math.inf if not math.isfinite(std_u[i])
                   else float(abs(derivative(spec, u[i])) * std_u[i]))
        else:
            std = 0.0
        params[name] = ParameterEstimate(
            name=name, value=values[name], std=std, unit=spec.unit, fixed=name not in problem.free,
            doc=spec.doc, note=flags.get(name, ""),
        )
    return values, model, params


def _run_summaries(problem: Problem, prep: Prepared, u, std_u, pre: dict):
    """``(runs, rms, offsets, moving)``: a :class:`RunSummary` per run, the weighted RMS
    residual of the whole log [log units], each set-up's offset and each run's readings
    at which the model moves (speed ≠ 0)."""
    _, t_release, theta0_enc, offset = problem.unpack_np(u)
    theta_pred, omega_pred, stuck = map(
        np.asarray, pre["dense"] if "dense" in pre else _dense(problem, u, problem.times)
    )
    off_run = offset[prep.setup_index]
    pred_enc = theta_pred + off_run[:, None]
    w2 = prep.weight**2
    err = pred_enc - prep.theta
    runs = []
    for i, name in enumerate(prep.run_names):
        n = prep.lengths[i]
        rms = math.sqrt(np.sum(w2[i, :n] * err[i, :n] ** 2) / np.sum(w2[i, :n]))
        runs.append(
            RunSummary(
                name=name,
                setup=prep.setup_names[prep.setup_index[i]],
                n_samples=int(n),
                release_time=float(t_release[i]),
                release_time_std=_release_std(problem, u, std_u, i),
                theta0=float(theta0_enc[i] - off_run[i]),
                offset=float(off_run[i]),
                rms_rad=rms,
                rest_logged=float(prep.rest[i] - off_run[i]),
                rest_model=float(theta_pred[i, n - 1]),
                stuck_at_end=bool(stuck[i, n - 1]),
                peak_speed=float(np.max(np.abs(omega_pred[i, :n]))),
            )
        )
    rms_all = math.sqrt(np.sum(w2 * err**2) / np.sum(w2))
    moving = np.array([int(np.count_nonzero(omega_pred[i, :n])) for i, n in
                       enumerate(prep.lengths)])
    return runs, rms_all, offset, moving


def _run_warnings(prep: Prepared, runs, values, model, derived, bracket: bool,
                  warnings: list[str]):
    """What the runs show about the fit: the Stribeck shape out of the swings' reach, the
    stick band against its data bracket (the event-driven reference at the fitted values,
    :func:`band_bracket`; ``bracket`` False skips it), runs the model never releases, runs
    it leaves moving, runs the log cuts before they stop. Returns the bracket (or None)."""
    if "v_s" in values and runs:
        peak = max(r.peak_speed for r in runs)
        if peak < STRIBECK_VISIBLE * values["v_s"]:
            warnings.append(
                f"peak speed {peak:.3g} rad/s is not far above the Stribeck velocity "
                f"{values['v_s']:.3g} rad/s: tau_c, tau_s, v_s and delta blur together"
            )
    moving_start = (np.zeros(prep.n_runs, bool) if prep.moving_start is None
                    else np.asarray(prep.moving_start))
    ends_moving = (np.zeros(prep.n_runs, bool) if prep.ends_moving is None
                   else np.asarray(prep.ends_moving))
    stopped = [r for i, r in enumerate(runs) if not ends_moving[i] and not moving_start[i]]
    duration = float(np.max(prep.lengths)) * prep.sample_period
    try:
        bracket = band_bracket(model, stopped, duration) if bracket else None
    except BracketTooCostly as exc:
        bracket = None
        warnings.append(
            "stick band: no data bracket — the event-driven reference simulation at the "
            f"fitted parameters was stopped ({exc}: a stiff friction law, tau_s "
            f"{values.get('tau_s', math.nan):.3g}, tau_c {values.get('tau_c', math.nan):.3g}, "
            f"v_s {values.get('v_s', math.nan):.3g} rad/s)")
    if bracket is not None and bracket[0] > bracket[1]:
        warnings.append(
            f"stick band: the largest logged |rest point| {bracket[0]:.4g} exceeds the smallest "
            f"|angle| {bracket[1]:.4g} from which the fitted model slides on: the fitted "
            "friction cannot reproduce the logged rest points (no data bracket)"
        )
        bracket = None
    if bracket is not None:
        lo, hi = bracket
        hw, hw_std = derived["stick_band_halfwidth_rad"]
        if hi > lo and 2 * hw_std < 0.5 * (hi - lo):
            warnings.append(
                f"stick band: the half-width {hw:.4f} ± {hw_std:.4f} rad of the smooth fit (and "
                "tau_s, the torque that sets it) rests on the fitted Stribeck shape; the data "
                f"alone bracket it to [{lo:.4f}, "
                f"{hi:.4f}] rad (largest |rest point|, smallest |angle it slid on from|)"
            )
    # A run the model never releases (exact stick: its speed is 0 at every sample) although
    # the log shows it moving has a zero gradient in its release and start angle: the fit
    # cannot pull it out, and the others' parameters bend around it.
    held = [r.name for i, r in enumerate(runs) if r.peak_speed == 0.0 and not moving_start[i]
            and abs(prep.rest[i] - prep.hold[i]) > MOVED_COUNTS * prep.resolution]
    if held:
        warnings.append(
            "the model never releases run(s) " + ", ".join(held) + " although the log shows "
            "them moving: the fit is caught in a basin where their release cannot be moved "
            "(the stick band it tried once exceeded their start angle) and its parameters "
            "are not trustworthy; check those runs or fit without them"
        )
    not_stuck = [r.name for i, r in enumerate(runs) if not r.stuck_at_end and not ends_moving[i]]
    if not_stuck:
        warnings.append(
            "the model is still moving at the end of run(s) " + ", ".join(not_stuck)
            + ": the fitted friction cannot hold the logged rest point"
        )
    open_end = [r.name for i, r in enumerate(runs) if ends_moving[i]]
    if open_end:
        warnings.append(
            "the log ends before the motion stops in run(s) " + ", ".join(open_end)
            + ": their rest points are not in the data, so they say nothing about the "
            "stick band; log until the gear is at rest to see it"
        )
    return bracket


def _release_std(problem: Problem, u, std_u, i: int) -> float:
    """Standard error of a run's release instant [s] (delta method through the map)."""
    if not problem.release_free:
        return 0.0
    j = problem.n_physical + i
    lo, hi = float(np.asarray(problem.release_lo)[i]), float(np.asarray(problem.release_hi)[i])
    if hi == lo:  # a run released at its first sample (moving, or never moving): known
        return 0.0
    if not math.isfinite(std_u[j]):  # undetermined (not 0·∞ = NaN at a bracket end)
        return math.inf
    s = 1.0 / (1.0 + math.exp(-float(u[j])))
    return float((hi - lo) * s * (1 - s) * std_u[j])


def _pct(x: float) -> str:
    return f"{100 * (math.exp(x) - 1):.0f} %" if x < 3 else "orders of magnitude"
