"""The reference trajectory read like a log: sampled at given times (and densely), the
commanded hold before the release included."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np

from ._events import reference_trajectory
from ._spring import ExtraTorque


def simulate_reference(
    times,
    *,
    theta0: float,
    t_release: float,
    k1: float,
    k2: float,
    tau_c: float,
    tau_s: float,
    v_s: float,
    delta: float,
    c_v: float,
    inertia: float,
    ratio: float = 100.0,
    rtol: float = 1e-11,
    atol: float = 1e-14,
    extra_torque: ExtraTorque | None = None,
    max_events: int = 10_000,
    extra_holding: Callable[[float], float] | None = None,
    dahl: tuple[float, float] | None = None,
) -> np.ndarray:
    """WG angle of a free-motion release at the requested times (ground-truth simulator).

    Parameters
    ----------
    times : array_like
        Sample times [s] (any order, any shape).
    theta0 : float
        Physical WG angle from the spring's zero at release [rad].
    t_release : float
        Release instant [s], typically between two samples.
    k1, k2 : float
        Output-side stiffness, ``T_k(d) = k1·d + k2·d³`` [Nm/rad, Nm/rad³].
    tau_c, tau_s : float
        Coulomb and static friction torque at the WG [Nm].
    v_s : float
        Stribeck velocity [rad/s].
    delta : float
        Stribeck exponent [-].
    c_v : float
        Viscous coefficient at the WG [Nm·s/rad].
    inertia : float
        Inertia at the WG [kg·m²].
    ratio : float, optional
        Gear ratio ``N`` (default 100).
    rtol, atol : float, optional
        DOP853 tolerances (defaults 1e-11, 1e-14).
    extra_torque : callable, optional
        Additional smooth WG torque ``extra_torque(theta, omega)`` [Nm] added to the right-hand
        side and to the stick test; see :func:`reference_trajectory`.
    max_events : int, optional
        Zeno guard (default 10 000 velocity zeros, then stick).
    extra_holding, dahl : optional
        Hidden-effect hooks; see :func:`reference_trajectory`.

    Returns
    -------
    numpy.ndarray
        Physical ``θ`` (from the spring's zero) at ``times``; ``θ = theta0`` for
        ``t ≤ t_release``.
    """
    t = np.asarray(times, dtype=float)
    t_end = float(np.max(t)) if t.size else float(t_release)
    t_end = max(t_end, float(t_release))
    traj = reference_trajectory(
        t_end, theta0=theta0, t_release=t_release, k1=k1, k2=k2, tau_c=tau_c, tau_s=tau_s,
        v_s=v_s, delta=delta, c_v=c_v, inertia=inertia, ratio=ratio, rtol=rtol, atol=atol,
        extra_torque=extra_torque, max_events=max_events, extra_holding=extra_holding, dahl=dahl,
    )
    theta, _ = traj.evaluate(t)
    return theta


def simulate_reference_dense(
    t_end: float,
    *,
    theta0: float,
    t_release: float,
    k1: float,
    k2: float,
    tau_c: float,
    tau_s: float,
    v_s: float,
    delta: float,
    c_v: float,
    inertia: float,
    ratio: float = 100.0,
    dt: float = 1e-5,
    t_start: float = 0.0,
    rtol: float = 1e-11,
    atol: float = 1e-14,
    extra_torque: ExtraTorque | None = None,
    max_events: int = 10_000,
    extra_holding: Callable[[float], float] | None = None,
    dahl: tuple[float, float] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Angle and velocity on a fine uniform grid (for plots and tests).

    Parameters
    ----------
    t_end : float
        Last grid time [s].
    theta0, t_release, k1, k2, tau_c, tau_s, v_s, delta, c_v, inertia, ratio, rtol, atol,
    extra_torque, max_events
        As in :func:`simulate_reference`.
    dt : float, optional
        Grid spacing [s] (default 10 µs).
    t_start : float, optional
        First grid time [s] (default 0).

    Returns
    -------
    t, theta, omega : numpy.ndarray
        Grid times, physical WG angle [rad] and WG velocity [rad/s].
    """
    n = int(math.floor((t_end - t_start) / dt + 1e-9)) + 1
    t = t_start + dt * np.arange(n)
    traj = reference_trajectory(
        max(float(t[-1]), float(t_release)), theta0=theta0, t_release=t_release, k1=k1, k2=k2,
        tau_c=tau_c, tau_s=tau_s, v_s=v_s, delta=delta, c_v=c_v, inertia=inertia, ratio=ratio,
        rtol=rtol, atol=atol, extra_torque=extra_torque, max_events=max_events,
        extra_holding=extra_holding, dahl=dahl,
    )
    theta, omega = traj.evaluate(t)
    return t, theta, omega
