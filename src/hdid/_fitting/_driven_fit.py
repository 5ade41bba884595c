"""Fitting driven (input/output) logs, alone or jointly with free-motion logs."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterable, Mapping, Sequence

import jax.numpy as jnp
import numpy as np

from .._simulation._driven import DrivenJoint
from .._problems._driven_problem import DrivenData, DrivenProblem, JointProblem, build_driven_problem
from ._driven_analysis import analyse_driven
from .._results._driven_result import DrivenFitResult
from ._driven_starts import _coulomb_effects, _start_values, log_scales
from .._errors import FitError
from .._log import Log, read_log
from .._models._model import Model
from .._models._positional import PositionalError
from .._models._transforms import to_unconstrained
from ..effects import CoulombFriction, StribeckFriction
from .._problems._driven_evaluate import _residuals, _simulate
from ._fit import _setup, fit
from ._lm import solve_fresh


#: Highest positional-error order tried when the order is chosen by BIC.
DEFAULT_MAX_ORDER = 6


def fit_driven(
    log: Log | str | os.PathLike | object,
    model: Model | DrivenJoint | None = None,
    *,
    order: int | None = None,
    max_order: int = DEFAULT_MAX_ORDER,
    fix: Mapping[str, float] | Iterable[str] | None = None,
    counts_per_rev: float | None = None,
    torque_constant: float | None = None,
    output_counts_per_rev: float | None = None,
    max_substep: float | None = None,
    max_steps: int = 200,
    input_hold: str | None = None,
) -> DrivenFitResult:
    """Fit a driven (input/output) log: WG dynamics (eq. 9), output twist and positional
    error (eqs. 3, 8).

    The motor torque is known, so — unlike free motion — the inertia and every torque
    are identified on an absolute scale. The output encoder adds the kinematic error
    ``θ_out + θ/N``: its load-dependent part gives the stiffness ``T_k`` and the output
    friction, its periodic part in the motor angle the positional error.

    Parameters
    ----------
    log:
        A driven :class:`~hdid.Log` (``motor_torque`` or ``motor_current`` column), a
        CSV path or a DataFrame.
    model:
        WG-side :class:`~hdid.Model` (default :meth:`Model.default`) or a
        :class:`~hdid.DrivenJoint` (its positional-error order is then the maximum).
    order:
        Positional-error order ``K``; default: chosen by BIC among ``0 … max_order``.
    fix:
        Parameters held fixed (names, or ``{name: value}``).
    torque_constant, output_counts_per_rev, counts_per_rev:
        Unit conversions for logs of motor current and raw encoder counts.
    input_hold:
        How the motor torque runs between samples: ``"zoh"`` (held: a drive's command,
        the default for a ``motor_torque`` column) or ``"foh"`` (linear: a sampled analog
        signal, the default for a measured ``motor_current``); see :func:`input_hold_for`.
    """
    t_start = time.perf_counter()
    log = _read(log, counts_per_rev, torque_constant, output_counts_per_rev)
    hold = input_hold_for(log, input_hold)
    data = DrivenData.from_log(log)
    joint = _as_joint(model, max_order if order is None else order, data)
    free, fixed, notes = _free_names(joint, fix, data)
    joint = joint.replace(**fixed) if fixed else joint
    joint = _start_values(data, joint, free)
    joint = _with_scales(joint, data)
    warnings: list[str] = []
    u, problem = _fit_nested_first(data, joint, free, max_substep, max_steps, warnings, notes,
                                   hold)
    bic = None
    if order is None and data.has_output:
        best_k, bic = choose_order(problem, u, max_order)
        if best_k != joint.positional.order:
            joint2 = problem.joint(u).with_order(best_k)
            free2 = tuple(n for n in free if not n.startswith("pos_")) + tuple(
                n for n in joint2.positional.names() if n not in fixed
            )
            problem2 = build_driven_problem(data, joint2, free2, _priors(joint2, free2), max_substep, hold)
            u0 = _pack(problem2, joint2, nuisance=np.asarray(u[problem.n_physical:]))
            problem2 = eqx_tree_set(problem2, direction0=problem.direction0)
            u, problem = _solve(problem2, u0, data.source, max_steps, data)
    result = analyse_driven(problem, u, data=data, notes=notes, order_bic=bic)
    result.warnings[:0] = warnings
    result.wall_time_s = time.perf_counter() - t_start
    return result


def input_hold_for(log, input_hold: str | None = None) -> str:
    """The motor torque's hold between samples: ``input_hold`` when given, else
    ``"foh"`` (linear interpolation) for a log of measured motor current — a sampled
    analog signal, continuous between its samples — and ``"zoh"`` (held) for a
    ``motor_torque`` column, read as the drive's command, which its DAC or PWM holds
    until the next sample."""
    if input_hold is not None:
        if input_hold not in ("zoh", "foh"):
            raise ValueError(f"input_hold = {input_hold!r}: must be 'zoh' (held) or 'foh' (linear)")
        return input_hold
    return "foh" if getattr(log, "torque_constant", None) is not None else "zoh"


def _with_scales(joint: DrivenJoint, data: DrivenData) -> DrivenJoint:
    """The joint with its model's data-derived optimiser scales resolved on this log."""
    values = joint.float_values()
    coulomb = sum(values.get(p.name, 0.0) for e in _coulomb_effects(joint)
                  for p in e.parameters[:1])
    scales = log_scales(data, joint, values["inertia"], coulomb or None)
    return DrivenJoint(joint.model.with_scales(scales), joint.tau_fout, joint.positional)


def _data_cost(problem, u) -> float:
    """χ² of the data rows (the weak-prior rows left out), in units of the quantization σ."""
    r = np.asarray(_residuals(problem, jnp.asarray(u)))[: -problem.n_physical or None]
    return float(r @ r) * float(problem.noise_scale) ** 2


#: Relative χ² margin by which a general model may end above its nested special case
#: before it is called worse (the LM stopping tolerance on the cost).
NESTED_MARGIN = 1e-3


def _fit_nested_first(data, joint, free, max_substep, max_steps, warnings, notes, hold):
    """Fit, Coulomb first where a Stribeck law is free.

    Stribeck friction nests Coulomb friction (``tau_s = tau_c``, any ``v_s``): the
    Coulomb case is fitted first, and the Stribeck fit starts from its optimum (with
    ``tau_s`` just above ``tau_c``), so it can only improve on it. Should it still end
    worse (a stick event, the weak priors), that is a warning and the result is the
    Coulomb optimum (``tau_s = tau_c``). An end with ``tau_s < tau_c`` is excluded the
    same way (the admissible optimum is then on the boundary ``tau_s = tau_c``) and
    reported."""
    stribeck = [e for e in _coulomb_effects(joint) if type(e) is StribeckFriction]
    names = [p.name for e in stribeck for p in e.parameters]
    if len(stribeck) != 1 or not {names[0], names[1]} <= set(free):
        problem = build_driven_problem(data, joint, free, _priors(joint, free), max_substep, hold)
        return _solve(problem, _pack(problem, joint, data=data), data.source, max_steps, data)
    e = stribeck[0]
    tc, ts = names[0], names[1]
    shape = [n for n in names[2:] if n in free]
    nested = DrivenJoint(joint.model.with_effect(CoulombFriction(tau_c=e.tau_c)), joint.tau_fout,
                         joint.positional)
    free_n = tuple(n for n in free if n not in (ts, *shape))
    pn = build_driven_problem(data, nested, free_n, _priors(nested, free_n), max_substep, hold)
    un, pn = _solve(pn, _pack(pn, nested, data=data), data.source, max_steps, data)
    cost_n = _data_cost(pn, un)
    at = pn.values_np(un)
    start = {n: at[n] for n in free_n}
    start[ts] = 1.02 * at[tc]
    joint_g = joint.replace(**start)
    pg = build_driven_problem(data, joint_g, free, _priors(joint_g, free), max_substep, hold)
    pg = eqx_tree_set(pg, direction0=pn.direction0)
    ug, pg = _solve(pg, _pack(pg, joint_g, nuisance=np.asarray(un[pn.n_physical:])),
                    data.source, max_steps, data)
    cost_g = _data_cost(pg, ug)
    notes.append(
        f"Coulomb friction ({tc} = {ts}) fitted first: χ² {cost_n:.6g}; Stribeck from its "
        f"optimum: χ² {cost_g:.6g} ({'better' if cost_g < cost_n else 'not better'})")
    if cost_g > cost_n * (1 + NESTED_MARGIN):
        warnings.append(
            f"the Stribeck fit ended worse (χ² {cost_g:.4g}) than its nested Coulomb case "
            f"{tc} = {ts} (χ² {cost_n:.4g}) although it started from it: the result is the "
            f"Coulomb optimum ({ts} = {tc}; the Stribeck shape is then undetermined)")
        back = joint.replace(**{**start, ts: at[tc]})
        ug = _pack(pg, back, nuisance=np.asarray(un[pn.n_physical:]))
    vals = pg.values_np(ug)
    if vals[ts] < vals[tc] and cost_g <= cost_n * (1 + NESTED_MARGIN):
        # Excluded: a Stribeck law has tau_s ≥ tau_c; when the free optimum falls below,
        # the best admissible one is on the boundary tau_s = tau_c — the Coulomb optimum.
        warnings.append(
            f"the free Stribeck fit ends with {ts} = {vals[ts]:.4g} < {tc} = {vals[tc]:.4g} "
            f"(friction rising from rest, χ² {cost_g:.4g} against {cost_n:.4g}): excluded; "
            f"the result is the Coulomb optimum {ts} = {tc}, where the Stribeck shape is "
            "undetermined")
        back = joint.replace(**{**start, ts: at[tc]})
        ug = _pack(pg, back, nuisance=np.asarray(un[pn.n_physical:]))
    return ug, pg


def fit_joint(
    logs: Sequence[Log | str | os.PathLike | object],
    model: Model | DrivenJoint | None = None,
    *,
    order: int | None = None,
    max_order: int = DEFAULT_MAX_ORDER,
    fix: Mapping[str, float] | Iterable[str] | None = None,
    counts_per_rev: float | None = None,
    torque_constant: float | None = None,
    output_counts_per_rev: float | None = None,
    release_time: float | None = None,
    max_substep: float | None = None,
    max_steps: int = 200,
    input_hold: str | None = None,
) -> DrivenFitResult:
    """One set of physical parameters for a free-motion log and a driven log of one gear.

    ``logs`` holds exactly one driven log and one or more free-motion logs (in any
    order; each log's kind is read from its columns). The free-motion logs fix the
    stiffness and friction *relative to* the inertia with high precision; the driven
    log fixes the absolute scale (known motor torque), the output friction and the
    positional error. Starting values come from a fit of each log alone.
    """
    t_start = time.perf_counter()
    read = [_read(lg, counts_per_rev, torque_constant, output_counts_per_rev) for lg in logs]
    driven = [lg for lg in read if getattr(lg, "is_driven", False)]
    free_logs = [lg for lg in read if not getattr(lg, "is_driven", False)]
    if len(driven) != 1 or not free_logs:
        raise ValueError(
            f"logs: a joint fit needs exactly one driven log and at least one free-motion "
            f"log; got {len(driven)} driven and {len(free_logs)} free-motion"
        )
    if not isinstance(model, DrivenJoint):
        # Without an output encoder the driven log sees tau_c + tau_fout/N, the free-motion
        # log tau_c: the joint fit keeps the output friction at the driven joint's
        # default rather than folding it into the shared tau_c (see fit_driven). A
        # DrivenJoint also keeps a pendulum's Gravity as it is: the free-motion logs fit
        # its zero per set-up (no hanging angle of the driven log's own).
        model = DrivenJoint(Model.default() if model is None else model, 0.05,
                            PositionalError.zeros(max_order if order is None else order))
    alone = fit_driven(
        driven[0], model, order=order, max_order=max_order, fix=fix,
        max_substep=max_substep, max_steps=max_steps, input_hold=input_hold,
    )
    joint = alone.joint
    dproblem: DrivenProblem = alone.problem
    user_fixed = set(_fixed_from(joint, fix))
    names = list(dproblem.free)
    n_total = dproblem.n_unknowns
    parts, index, u_parts, preps = [dproblem], [np.arange(n_total)], [np.asarray(alone.u)], []
    extra_names, extra_u = [], []
    for lg in free_logs:
        # Each free-motion log alone, at the driven fit's inertia: its nuisances (release
        # instants, start angles, offsets) and starts for parameters the driven log
        # cannot see (the spring, when it has no output encoder).
        fr = fit(lg, joint.model, inertia=float(joint.model.inertia),
                 release_time=release_time, max_substep=max_substep)
        fixed_here = [n for n in joint.model.parameter_specs() if n in user_fixed]
        setup = _setup(
            lg, fr.model, fix=fixed_here or None, free_inertia="inertia" not in user_fixed,
            release_time=release_time, max_substep=max_substep,
        )
        fp = setup.problem
        # Weak priors of shared parameters are in the driven part already: count once.
        fp = eqx_tree_set(fp, prior_on=jnp.zeros_like(fp.prior_on))
        idx = []
        for n in fp.free:
            if n in names:
                idx.append(names.index(n))
            elif n in extra_names:
                idx.append(dproblem.n_unknowns + extra_names.index(n))
            else:
                extra_names.append(n)
                spec = fp.base.parameter_specs()[n]
                extra_u.append(to_unconstrained(spec, fr.values[n]))
                idx.append(-len(extra_names))  # placeholder, fixed below
        n_nuis = fp.n_unknowns - fp.n_physical
        parts.append(fp)
        index.append((idx, n_nuis))
        u_parts.append(np.asarray(fr.u)[fr.problem.n_physical:])
        preps.append(setup.prep)
    # Layout: driven unknowns, then parameters only the free-motion logs see, then each
    # free-motion log's nuisances.
    n_extra = len(extra_names)
    pos = dproblem.n_unknowns + n_extra
    final_index = [index[0]]
    for idx, n_nuis in index[1:]:
        idx = [dproblem.n_unknowns + (-i - 1) if i < 0 else i for i in idx]
        final_index.append(np.asarray(idx + list(range(pos, pos + n_nuis))))
        pos += n_nuis
    problem = JointProblem(tuple(parts), tuple(jnp.asarray(i) for i in final_index), pos)
    u0 = np.concatenate([u_parts[0], np.asarray(extra_u, dtype=float)] + u_parts[1:])
    u, problem = _solve(problem, u0, " + ".join(lg.source for lg in read), max_steps)
    result = analyse_driven(
        problem, u, data=alone.data, notes=alone.notes, order_bic=alone.order_bic,
        free_preps=preps, extra_names=extra_names,
    )
    result.wall_time_s = time.perf_counter() - t_start
    return result


def eqx_tree_set(module, **fields):
    import equinox as eqx

    names = list(fields)
    return eqx.tree_at(lambda m: [getattr(m, n) for n in names], module, [fields[n] for n in names])


# ----------------------------------------------------------------------------- pieces


def _read(log, counts_per_rev, torque_constant, output_counts_per_rev):
    """A :class:`Log` as it is (or any object with ``runs``), else read and validated."""
    import pandas as pd

    if isinstance(log, Log) or (hasattr(log, "runs") and not isinstance(log, pd.DataFrame)):
        return log
    kwargs = {"counts_per_rev": counts_per_rev}
    if torque_constant is not None:
        kwargs["torque_constant"] = torque_constant
    if output_counts_per_rev is not None:
        kwargs["output_counts_per_rev"] = output_counts_per_rev
    return read_log(log, **kwargs)


def _as_joint(model, order: int, data: DrivenData | None = None) -> DrivenJoint:
    """A :class:`DrivenJoint` from a model. Its output friction starts at 0 and is fitted
    from the output encoder; without one it is held at 0: eq. 9 alone cannot tell
    ``tau_fout/N`` from WG Coulomb friction, which then carries it. A pendulum's
    :class:`~hdid.effects.Gravity` becomes :class:`~hdid.effects.gravity.AbsoluteGravity`:
    a driven log's angles are the drive's, with no fitted zero per set-up, so where the
    arm hangs is a parameter."""
    if isinstance(model, DrivenJoint):
        return model.with_order(order) if model.positional.order != order else model
    if model is not None and model.reading is not None:  # not modelled here: say so, not ignore
        raise FitError("reading_age: driven fits do not model the readings' age; fit without it")
    m = _with_hanging_angle(Model.default() if model is None else model)
    tau_fout = 0.0 if data is not None and not data.has_output else 0.05
    return DrivenJoint(m, tau_fout, PositionalError.zeros(order))


def _with_hanging_angle(model: Model) -> Model:
    """``model`` with each :class:`~hdid.effects.Gravity` in place given a fitted hanging
    angle (:class:`~hdid.effects.gravity.AbsoluteGravity`, ``theta_g`` = 0 to start)."""
    from ..effects.gravity import AbsoluteGravity, Gravity

    if not any(type(e) is Gravity for e in model.effects):
        return model
    effects = tuple(AbsoluteGravity.of(e) if type(e) is Gravity else e for e in model.effects)
    return Model(effects=effects, inertia=model.inertia, ratio=model.ratio,
                 param_scales=model.param_scales)


def _fixed_from(joint: DrivenJoint, fix) -> dict[str, float]:
    specs = joint.parameter_specs()
    fixed: dict[str, float] = {}
    if fix is not None:
        current = joint.float_values()
        items = fix.items() if isinstance(fix, Mapping) else ((n, None) for n in fix)
        for name, value in items:
            if name not in specs:
                raise KeyError(f"fix: unknown parameter {name!r}; choose from {list(specs)}")
            fixed[name] = current[name] if value is None else float(value)
    return fixed


def _free_names(joint: DrivenJoint, fix, data: DrivenData):
    specs = joint.parameter_specs()
    fixed = _fixed_from(joint, fix)
    notes = []
    if not data.has_output:
        spring = [p.name for p in joint.spring.parameters]
        auto = spring + ["tau_fout"] + list(joint.positional.names())
        notes.append(
            f"no output angle in the log: {', '.join(spring)} and tau_fout are held at their "
            "given values and no positional error is fitted (eq. 9 alone cannot see the "
            "spring, and output friction/N looks like WG Coulomb friction)"
        )
        current = joint.float_values()
        for n in auto:
            fixed.setdefault(n, current[n])
    free = tuple(n for n in specs if n not in fixed)
    return free, fixed, notes


def _priors(joint: DrivenJoint, free) -> dict[str, tuple[float, float]]:
    """Weak priors of the free parameters; a declared mean of ``None`` is centred on the
    (data-derived) starting value ``joint`` holds."""
    specs = joint.parameter_specs()
    values = joint.float_values()
    out = {}
    for n in free:
        prior = specs[n].prior
        if prior is not None:
            mean = prior[0] if prior[0] is not None else float(to_unconstrained(specs[n], values[n]))
            out[n] = (float(mean), float(prior[1]))
    return out


def _pack(problem, joint: DrivenJoint, nuisance=None, data=None) -> np.ndarray:
    specs = joint.parameter_specs()
    values = joint.float_values()
    phys = np.array([to_unconstrained(specs[n], values[n]) for n in problem.free], dtype=float)
    if nuisance is None:
        nuisance = np.concatenate([np.zeros(problem.n_runs), data.omega0 / data.omega_scale])
    return np.concatenate([phys, nuisance])


#: Rounds of "fit, then hand each window the output-friction sign its predecessor's
#: simulation ends with, and refit" (the sign is discrete, so it is not fitted).
DIRECTION_ROUNDS = 3
#: Levenberg–Marquardt iterations per restart of the solver.
LM_CHUNK = 25


def _solve(problem, u0, source: str, max_steps: int, data: DrivenData | None = None):
    """Levenberg–Marquardt from ``u0``; for a driven part, rounds that make each
    window's starting output-friction sign agree with the previous window's end."""
    u = jnp.asarray(u0)
    rounds = DIRECTION_ROUNDS if data is not None else 1
    if (data is not None and not data.has_output and "tau_fout" not in problem.free
            and float(problem.base.tau_fout) == 0.0):
        rounds = 1  # no output friction: the windows' starting signs change nothing
    for _ in range(rounds):
        # In chunks, each restarting the solver: a stick event met far from the optimum
        # can shrink the trust region to nothing, and a fresh start recovers it.
        used = 0
        while used < max_steps:
            U, cost, done, steps = solve_fresh(
                problem, u[None], jnp.ones(1, dtype=bool), jnp.asarray(LM_CHUNK)
            )
            u = U[0]
            used += LM_CHUNK
            if (data is not None and np.isfinite(float(cost[0]))
                    and float(getattr(problem, "noise_scale", 0.0)) == 1.0):
                ratio = _scatter_ratio(problem, u)
                if ratio > MODEL_ERROR_RATIO:
                    problem = eqx_tree_set(problem, noise_scale=jnp.asarray(ratio))
                    if not (bool(done[0]) and not bool(np.any(np.asarray(problem.prior_on)))):
                        continue  # (a uniform σ moves no optimum without priors)
            if bool(done[0]) or not np.isfinite(float(cost[0])):
                break
        if not np.isfinite(float(cost[0])) or not np.all(np.isfinite(np.asarray(u))):
            raise FitError(
                f"{source}: the driven fit diverged (non-finite residuals); check the torque "
                "units (N m at the motor side, or --torque-constant) and the encoder units"
            )
        if data is None:
            break
        new = _window_directions(problem, u, data)
        if np.array_equal(new, np.asarray(problem.direction0)):
            break
        problem = eqx_tree_set(problem, direction0=jnp.asarray(new))
    return np.asarray(u), problem


#: Residual scatter (in quantization σ) above which the model error, not the encoder,
#: sets the scatter: the residuals are then measured in that scatter.
MODEL_ERROR_RATIO = 3.0


def _scatter_ratio(problem, u) -> float:
    """RMS of the weighted WG residuals in units of the current σ."""
    _, sim = _simulate(problem, jnp.asarray(u))
    w = np.asarray(problem.weight)
    r = w * (np.asarray(sim["theta"]) - np.asarray(problem.theta)) / float(problem.sigma)
    return float(np.sqrt(np.sum(r**2) / max(np.sum(w > 0), 1)))


def _window_directions(problem: DrivenProblem, u, data: DrivenData) -> np.ndarray:
    _, sim = _simulate(problem, u)
    s = np.asarray(sim["output_direction"])
    last = (np.asarray(problem.weight) > 0).sum(axis=1) - 1
    new = np.asarray(problem.direction0).copy()
    runs = data.run_of_window
    for w in range(1, len(new)):
        if runs[w] == runs[w - 1]:
            new[w] = s[w - 1, last[w - 1]]
    return new


def choose_order(problem: DrivenProblem, u, max_order: int):
    """BIC of the positional-error order ``K = 0 … max_order`` at the fitted flexibility.

    The positional error is linear in its coefficients, so each order is a linear
    least-squares fit of the kinematic error left after the fitted flexibility part:
    ``BIC_K = n·ln(RSS_K/n) + (2K+1)·ln n`` over the ``n`` output samples.
    """
    joint, sim = problem.simulate(jnp.asarray(u))
    N = joint.ratio
    w = np.asarray(problem.weight) > 0
    theta = np.asarray(problem.theta)
    flex = np.asarray(joint.flexibility_error(problem.load_torque, sim["output_direction"]))
    y = (np.asarray(problem.theta_out) + theta / N - flex)[w]
    th = theta[w]
    n = y.size
    bic = {}
    for K in range(max_order + 1):
        harm = np.arange(1, K + 1)
        A = np.concatenate(
            [np.full((n, 1), 0.5), np.cos(np.outer(th, harm)), np.sin(np.outer(th, harm))], axis=1
        )
        resid = y - A @ np.linalg.lstsq(A, y, rcond=None)[0]
        rss = max(float(resid @ resid), 1e-300)
        bic[K] = n * math.log(rss / n) + (2 * K + 1) * math.log(n)
    best = min(bic, key=bic.get)
    return best, bic
