"""Starting values of a driven fit, from the log in hand: its scales (frequency, torque,
twist), the spring from the output twist, friction from the motor torque while stuck."""

from __future__ import annotations

import math

import numpy as np

from .._simulation._driven import DrivenJoint
from .._problems._driven_problem import DrivenData
from ..effects import Scales, StribeckFriction


def _smooth_derivatives(theta, time):
    """Speed and acceleration of a logged angle at its logged times: a 7-point local
    cubic (:func:`~hdid._problems._driven_problem.local_cubic` — Savitzky–Golay at a
    uniform period, the same least-squares cubic at jittered or gapped times, so that
    a log's irregular timestamps are not read as speed changes)."""
    from .._problems._driven_problem import local_cubic

    theta = np.asarray(theta, dtype=float)
    w = min(7, theta.size - (1 - theta.size % 2))
    if w < 5:
        return np.zeros_like(theta), np.zeros_like(theta)
    _, omega, alpha = local_cubic(np.asarray(time, dtype=float), theta, w, second=True)
    return omega, alpha


#: Samples enter the equation-error start when their smoothed speed exceeds this many
#: times the speed noise of the 7-point Savitzky–Golay derivative (the angle noise σ
#: times the filter's gain): a sign of the velocity read there is right with
#: overwhelming probability, in any units.
START_NOISE_FACTOR = 10.0
#: … and at least this fraction of the log's speed scale (its 95th-percentile speed):
#: friction near zero speed (Stribeck, stiction) is not the Coulomb + viscous line.
START_SPEED_FRACTION = 0.02


def _offset_parameters(joint: DrivenJoint, free) -> list[str]:
    """Free parameters of constant-torque effects (:class:`~hdid.effects.TorqueOffset`):
    their torque ``−tau_0`` is one more column of the equation-error regression."""
    from ..effects import TorqueOffset

    return [p.name for e in joint.wg_model.effects if isinstance(e, TorqueOffset)
            for p in e.parameters if p.name in free]


def _gravity_parameters(joint: DrivenJoint, free) -> tuple[str, str] | None:
    """``(mgl, theta_g)`` of a pendulum with a fitted hanging angle
    (:class:`~hdid.effects.gravity.AbsoluteGravity`) when both are free. Its torque at
    the logged axis, ``−(mgl/N)·sin(θ/N − theta_g)``, is linear in ``mgl·cos theta_g``
    and ``mgl·sin theta_g``: two more columns of the equation-error regression."""
    from ..effects.gravity import AbsoluteGravity

    for e in joint.wg_model.effects:
        if isinstance(e, AbsoluteGravity):
            names = tuple(p.name for p in e.parameters)
            return names if set(names) <= set(free) else None
    return None


def _coulomb_effects(joint: DrivenJoint):
    """The model's Stribeck-type friction law (an :class:`~hdid.AbstractFriction` with
    ``tau_c`` and ``tau_s``; its nested special case is Coulomb friction, ``tau_s = tau_c``)."""
    law = joint.wg_model.friction
    names = {p.name for p in law.parameters} if law is not None else set()
    return [law] if {"tau_c", "tau_s"} <= names else []


def log_scales(data: DrivenData, joint: DrivenJoint, inertia: float | None = None,
               coulomb: float | None = None) -> Scales:
    """The driven log's magnitudes in its own units (:class:`~hdid.effects.Scales`)."""
    speeds, torques, spans = [], [], []
    for i in range(data.n_runs):
        n = int(data.weight[i].sum())
        omega, _ = _smooth_derivatives(data.theta[i, :n], data.times[i, :n])
        speeds.append(np.abs(omega))
        torques.append(np.abs(data.motor_torque[i, :n]))
        spans.append(np.ptp(data.theta[i, :n]))
    speed = float(np.percentile(np.concatenate(speeds), 95)) if speeds else 1.0
    drive = float(np.percentile(np.concatenate(torques), 95)) if torques else 1.0
    torque = coulomb if coulomb and coulomb > 0 else 0.1 * drive
    values = joint.float_values()
    N = joint.ratio
    amplitude = max(float(np.max(spans)) if spans else 1.0, data.step)
    d = amplitude / N
    k_out = float(joint.spring_torque(d)) / d if d > 0 else float("nan")
    k_wg = k_out / N**2 if math.isfinite(k_out) and k_out > 0 else drive / amplitude
    return Scales(ratio=N, inertia=float(inertia or values["inertia"]), k_wg=k_wg,
                  amplitude=amplitude, speed=max(speed, 1e-300), torque=max(torque, 1e-300))


def _start_values(data: DrivenData, joint: DrivenJoint, free) -> DrivenJoint:
    """Equation-error estimates (for starting values only): linear least squares of
    eq. 9 on smoothed encoder derivatives, and of the kinematic error on the load.

    Every threshold is relative to the log (its angle noise and speed scale), so the
    same physical log in any consistent units starts from the same physics."""
    from scipy.signal import savgol_coeffs

    N = joint.ratio
    dt = data.sample_period
    gain = float(np.sqrt(np.sum(savgol_coeffs(7, 3, deriv=1, delta=dt) ** 2)))
    speed_noise = data.sigma * gain
    scales0 = log_scales(data, joint)
    threshold = max(START_NOISE_FACTOR * speed_noise, START_SPEED_FRACTION * scales0.speed)
    offsets = _offset_parameters(joint, free)
    gravity = _gravity_parameters(joint, free)
    rows, target, kin_rows, kin_y = [], [], [], []
    K = joint.positional.order
    for i in range(data.n_runs):
        n = int(data.weight[i].sum())
        th = data.theta[i, :n]
        omega, alpha = _smooth_derivatives(th, data.times[i, :n])
        td = data.motor_torque[i, :n]
        # the held torque about each sample: the intervals before and after it, weighted
        # by their logged lengths (the plain mean at a uniform period)
        t = data.times[i, :n]
        before, after = np.diff(t, prepend=t[0]), np.diff(t, append=t[-1])
        td_prev = np.concatenate([[td[0]], td[:-1]])
        span = before + after
        td_mid = np.where(span > 0, (td_prev * before + td * after) / np.where(span > 0, span, 1.0), td)
        tl = data.load_torque[i, :n]
        moving = np.abs(omega) > threshold
        moving[[0, -1]] = False
        s = np.sign(omega)
        cols = [alpha, s, omega] + ([np.ones(n)] if offsets else [])
        if gravity:
            # the drive holds (mgl/N)·sin(θ/N − θ_g) = (mgl/N)·(cos θ_g·sin(θ/N) − sin θ_g·cos(θ/N))
            cols += [np.sin(th / N) / N, np.cos(th / N) / N]
        rows.append(np.stack(cols, axis=1)[moving])
        target.append((td_mid - tl / N)[moving])
        if data.has_output:
            held = s.copy()
            # the output friction keeps its sign while at rest: a window that starts
            # at rest starts with the sign of the encoder's last change before it
            # (``direction0``), not with the sign of a speed that is only noise there
            if abs(omega[0]) <= threshold:
                held[0] = data.direction0[i]
            for k in range(1, n):
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
    coulomb = None
    if X.shape[0] > X.shape[1] + 1:
        coef = np.linalg.lstsq(X, y, rcond=None)[0]
        inertia, coulomb, c_v = coef[:3]
        if inertia > 0:
            new["inertia"] = float(inertia)
        if c_v > 0:
            new["c_v"] = float(c_v)
        for name in offsets:
            new[name] = float(coef[3])
        if gravity:
            a, b = coef[-2:]  # mgl·cos θ_g, −mgl·sin θ_g
            if math.hypot(a, b) > 0:
                new[gravity[0]] = float(math.hypot(a, b))
                new[gravity[1]] = float(math.atan2(-b, a))
    if data.has_output:
        A, b = np.concatenate(kin_rows), np.concatenate(kin_y)
        coef = np.linalg.lstsq(A, b, rcond=None)[0]
        if coef[0] > 0:
            k_est = 1.0 / coef[0]
            load = float(np.max(np.abs(data.load_torque)))
            new.update(_spring_rescaled(joint, k_est, load / k_est if load > 0 else 1.0 / k_est))
            if coef[1] > 0:
                new["tau_fout"] = float(coef[1] * k_est)
        new["pos_a0"] = float(coef[2])
        for h in range(1, K + 1):
            new[f"pos_a{h}"] = float(coef[2 + h])
            new[f"pos_b{h}"] = float(coef[2 + K + h])
    tau_fout = new.get("tau_fout", values["tau_fout"])
    scales = log_scales(data, joint, new.get("inertia"), coulomb)
    if coulomb is not None and coulomb > 0:
        tau_c = max(coulomb - tau_fout / N, 0.3 * coulomb)
        # Start at the nested Coulomb case (tau_s just above tau_c) with the Stribeck
        # velocity a tenth of the log's speeds: from there the fit can only improve on
        # Coulomb friction, never start in the v_s → 0 corner.
        new["tau_c"] = tau_c
        new["tau_s"] = 1.05 * tau_c
    # Library parameters with a data-derived start the regression did not give.
    for e in joint.model.effects:
        for p in e.parameters:
            if p.start is not None and p.name not in new and p.name in free:
                try:
                    new[p.name] = float(p.start(scales))
                except (AttributeError, ArithmeticError, ValueError):
                    pass  # a start needing magnitudes a driven log does not give
    new = {k: v for k, v in new.items() if k in free and k in values}
    return joint.replace(**new) if new else joint


def _spring_rescaled(joint: DrivenJoint, k_est: float, twist: float) -> dict[str, float]:
    """The spring law's parameters scaled so that its secant stiffness over the log's
    largest load twist is ``k_est`` (whatever the spring effect calls its parameters:
    every parameter in torque or stiffness units, ``N m…``, scales with the law)."""
    k_now = float(joint.spring_torque(twist)) / twist
    if not (math.isfinite(k_now) and k_now > 0):
        return {}
    c = k_est / k_now
    values = joint.float_values()
    return {p.name: values[p.name] * c for p in joint.spring.parameters if p.unit.startswith("N m")}
