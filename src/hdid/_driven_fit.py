"""Fitting driven (input/output) logs, alone or jointly with free-motion logs."""

from __future__ import annotations

import math
import os
import time
from collections.abc import Iterable, Mapping, Sequence

import jax
import jax.numpy as jnp
import numpy as np

from . import _config  # noqa: F401
from ._driven import DrivenJoint
from ._driven_problem import (
    OMEGA0_SCALE,
    DrivenData,
    DrivenProblem,
    JointProblem,
    build_driven_problem,
)
from ._driven_result import DrivenFitResult, analyse_driven
from ._errors import FitError
from ._io import Log, read_log
from ._model import Model
from ._positional import PositionalError
from ._transforms import to_unconstrained

#: Highest positional-error order tried when the order is chosen by BIC.
DEFAULT_MAX_ORDER = 6
#: |ω| above which a sample enters the equation-error starting estimate [rad/s]: well
#: above the speed noise of a 7-sample Savitzky–Golay derivative of a 4000-count
#: encoder at 250 Hz (≈ step·fs/√(window) ≈ 0.15 rad/s).
START_MIN_SPEED = 1.0


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
    """
    t_start = time.perf_counter()
    log = _read(log, counts_per_rev, torque_constant, output_counts_per_rev)
    data = DrivenData.from_log(log)
    joint = _as_joint(model, max_order if order is None else order)
    free, fixed, notes = _free_names(joint, fix, data)
    joint = joint.replace(**fixed) if fixed else joint
    joint = _start_values(data, joint, free)
    problem = build_driven_problem(data, joint, free, _priors(joint, free), max_substep)
    u, problem = _solve(problem, _pack(problem, joint, data=data), data.source, max_steps, data)
    bic = None
    if order is None and data.has_output:
        best_k, bic = choose_order(problem, u, max_order)
        if best_k != joint.positional.order:
            joint2 = problem.joint(u).with_order(best_k)
            free2 = tuple(n for n in free if not n.startswith("pos_")) + tuple(
                n for n in joint2.positional.names() if n not in fixed
            )
            problem2 = build_driven_problem(data, joint2, free2, _priors(joint2, free2), max_substep)
            u0 = _pack(problem2, joint2, nuisance=np.asarray(u[problem.n_physical:]))
            problem2 = eqx_tree_set(problem2, direction0=problem.direction0)
            u, problem = _solve(problem2, u0, data.source, max_steps, data)
    result = analyse_driven(problem, u, data=data, notes=notes, order_bic=bic)
    result.wall_time_s = time.perf_counter() - t_start
    return result


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
) -> DrivenFitResult:
    """One set of physical parameters for a free-motion log and a driven log of one gear.

    ``logs`` holds exactly one driven log and one or more free-motion logs (in any
    order; each log's kind is read from its columns). The free-motion logs fix the
    stiffness and friction *relative to* the inertia with high precision; the driven
    log fixes the absolute scale (known motor torque), the output friction and the
    positional error. Starting values come from a fit of each log alone.
    """
    from ._fit import _setup, fit

    t_start = time.perf_counter()
    read = [_read(lg, counts_per_rev, torque_constant, output_counts_per_rev) for lg in logs]
    driven = [lg for lg in read if getattr(lg, "is_driven", False)]
    free_logs = [lg for lg in read if not getattr(lg, "is_driven", False)]
    if len(driven) != 1 or not free_logs:
        raise ValueError(
            f"logs: a joint fit needs exactly one driven log and at least one free-motion "
            f"log; got {len(driven)} driven and {len(free_logs)} free-motion"
        )
    alone = fit_driven(
        driven[0], model, order=order, max_order=max_order, fix=fix,
        max_substep=max_substep, max_steps=max_steps,
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


def _as_joint(model, order: int) -> DrivenJoint:
    if isinstance(model, DrivenJoint):
        return model.with_order(order) if model.positional.order != order else model
    return DrivenJoint(Model.default() if model is None else model, 0.05, PositionalError.zeros(order))


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
    specs = joint.parameter_specs()
    return {n: specs[n].prior for n in free if specs[n].prior is not None}


def _pack(problem, joint: DrivenJoint, nuisance=None, data=None) -> np.ndarray:
    specs = joint.parameter_specs()
    values = joint.float_values()
    phys = np.array([to_unconstrained(specs[n], values[n]) for n in problem.free], dtype=float)
    if nuisance is None:
        nuisance = np.concatenate([np.zeros(problem.n_runs), data.omega0 / OMEGA0_SCALE])
    return np.concatenate([phys, nuisance])




#: Rounds of "fit, then hand each window the output-friction sign its predecessor's
#: simulation ends with, and refit" (the sign is discrete, so it is not fitted).
DIRECTION_ROUNDS = 3
#: Levenberg–Marquardt iterations per restart of the solver.
LM_CHUNK = 25


def _solve(problem, u0, source: str, max_steps: int, data: DrivenData | None = None):
    """Levenberg–Marquardt from ``u0``; for a driven part, rounds that make each
    window's starting output-friction sign agree with the previous window's end."""
    from ._fit import _solve_many

    u = jnp.asarray(u0)
    for _ in range(DIRECTION_ROUNDS if data is not None else 1):
        # In chunks, each restarting the solver: a stick event met far from the optimum
        # can shrink the trust region to nothing, and a fresh start recovers it.
        used = 0
        while used < max_steps:
            U, cost, done, steps = _solve_many(
                problem, u[None], jnp.ones(1, dtype=bool), jnp.asarray(LM_CHUNK)
            )
            u = U[0]
            used += LM_CHUNK
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


def _window_directions(problem: DrivenProblem, u, data: DrivenData) -> np.ndarray:
    from ._driven_result import _simulate

    _, sim = _simulate(problem, u)
    s = np.asarray(sim["output_direction"])
    last = (np.asarray(problem.weight) > 0).sum(axis=1) - 1
    new = np.asarray(problem.direction0).copy()
    runs = data.run_of_window
    for w in range(1, len(new)):
        if runs[w] == runs[w - 1]:
            new[w] = s[w - 1, last[w - 1]]
    return new


def _smooth_derivatives(theta, dt):
    from scipy.signal import savgol_filter

    w = min(7, theta.size - (1 - theta.size % 2))
    if w < 5:
        return np.zeros_like(theta), np.zeros_like(theta)
    omega = savgol_filter(theta, w, 3, deriv=1, delta=dt)
    alpha = savgol_filter(theta, w, 3, deriv=2, delta=dt)
    return omega, alpha


def _start_values(data: DrivenData, joint: DrivenJoint, free) -> DrivenJoint:
    """Equation-error estimates (for starting values only): linear least squares of
    eq. 9 on smoothed encoder derivatives, and of the kinematic error on the load."""
    N = joint.ratio
    rows, target, kin_rows, kin_y = [], [], [], []
    K = joint.positional.order
    for i in range(data.n_runs):
        n = int(data.weight[i].sum())
        th = data.theta[i, :n]
        omega, alpha = _smooth_derivatives(th, data.sample_period)
        td = data.motor_torque[i, :n]
        td_mid = 0.5 * (td + np.concatenate([[td[0]], td[:-1]]))
        tl = data.load_torque[i, :n]
        moving = np.abs(omega) > START_MIN_SPEED
        moving[[0, -1]] = False
        s = np.sign(omega)
        rows.append(np.stack([alpha, s, omega], axis=1)[moving])
        target.append((td_mid - tl / N)[moving])
        if data.has_output:
            held = s.copy()
            for k in range(1, n):  # the output friction keeps its sign while at rest
                if not moving[k]:
                    held[k] = held[k - 1]
            harm = np.arange(1, K + 1)
            basis = [tl, held, np.full(n, 0.5)]
            basis += [np.cos(h * th) for h in harm] + [np.sin(h * th) for h in harm]
            kin_rows.append(np.stack(basis, axis=1))
            kin_y.append(data.theta_out[i, :n] + th / N)
    values = joint.float_values()
    new = {}
    X, y = np.concatenate(rows), np.concatenate(target)
    if X.shape[0] > 3:
        inertia, coulomb, c_v = np.linalg.lstsq(X, y, rcond=None)[0]
        if inertia > 0:
            new["inertia"] = float(inertia)
        if c_v > 0:
            new["c_v"] = float(c_v)
    else:
        coulomb = values["tau_c"]
    if data.has_output:
        A, b = np.concatenate(kin_rows), np.concatenate(kin_y)
        coef = np.linalg.lstsq(A, b, rcond=None)[0]
        if coef[0] > 0:
            k1 = 1.0 / coef[0]
            new["k1"] = k1
            new["k2"] = values["k2"] * k1 / values["k1"]
            if coef[1] > 0:
                new["tau_fout"] = float(coef[1] * k1)
        new["pos_a0"] = float(coef[2])
        for h in range(1, K + 1):
            new[f"pos_a{h}"] = float(coef[2 + h])
            new[f"pos_b{h}"] = float(coef[2 + K + h])
    tau_fout = new.get("tau_fout", values["tau_fout"])
    if coulomb > 0:
        tau_c = max(coulomb - tau_fout / N, 0.3 * coulomb)
        new["tau_c"] = tau_c
        new["tau_s"] = 1.5 * tau_c
    new = {k: v for k, v in new.items() if k in free and k in values}
    return joint.replace(**new) if new else joint


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
