"""The event-driven trajectory: sliding segments integrated with DOP853 at a fixed friction
direction, exact stick/slide decisions at every velocity zero (see :mod:`hdid.reference`)."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp

from ._spring import ExtraTorque


@dataclass
class _Segment:
    t0: float
    t1: float
    direction: int
    sol: object  # scipy OdeSolution


@dataclass
class ReferenceTrajectory:
    """Result of one event-driven reference simulation.

    Attributes
    ----------
    theta0, t_release : float
        Initial WG angle (physical) and release time.
    t_end : float
        Last time covered (integration horizon).
    segments : list
        Sliding segments, each with its own DOP853 dense output.
    events : list of tuple
        ``(t, theta, decision)`` for each rest instant (release included), ``decision`` one of
        ``"stick"``, ``"slide+"``, ``"slide-"``, ``"zeno-stick"``.
    stuck : bool
        Whether the WG stuck before ``t_end``.
    t_stick, theta_rest : float or None
        Time and angle at which it stuck (``None`` if it did not).
    """

    theta0: float
    t_release: float
    t_end: float
    segments: list[_Segment] = field(default_factory=list)
    events: list[tuple[float, float, str]] = field(default_factory=list)
    stuck: bool = False
    t_stick: float | None = None
    theta_rest: float | None = None

    @property
    def n_events(self) -> int:
        """Number of rest instants after release (reversals plus the final stick)."""
        return max(len(self.events) - 1, 0)

    @property
    def reversal_times(self) -> np.ndarray:
        """Times of the velocity zeros after release (including the final stick)."""
        return np.array([e[0] for e in self.events[1:]], dtype=float)

    @property
    def reversal_angles(self) -> np.ndarray:
        """Angles at the velocity zeros after release (the successive extrema)."""
        return np.array([e[1] for e in self.events[1:]], dtype=float)

    def evaluate(self, times) -> tuple[np.ndarray, np.ndarray]:
        """Angle and velocity at arbitrary times.

        Parameters
        ----------
        times : array_like
            Any times (unsorted allowed).  Times after ``t_end`` are only valid if the WG stuck.

        Returns
        -------
        theta, omega : numpy.ndarray
            Same shape as ``times``.
        """
        t = np.asarray(times, dtype=float)
        flat = t.ravel()
        theta = np.full(flat.shape, self.theta0, dtype=float)
        omega = np.zeros(flat.shape, dtype=float)
        if self.stuck:
            late = flat >= self.t_stick
            theta[late] = self.theta_rest
        else:
            if np.any(flat > self.t_end + 1e-12 * max(1.0, abs(self.t_end))):
                raise ValueError("times beyond the simulated horizon of a WG that did not stick")
        for seg in self.segments:
            m = (flat > seg.t0) & (flat <= seg.t1)
            if self.stuck:
                m &= flat < self.t_stick
            if np.any(m):
                y = seg.sol(flat[m])
                theta[m] = y[0]
                omega[m] = y[1]
        return theta.reshape(t.shape), omega.reshape(t.shape)


def _check_params(theta0, t_release, k1, k2, tau_c, tau_s, v_s, delta, c_v, inertia, ratio):
    vals = dict(theta0=theta0, t_release=t_release, k1=k1, k2=k2, tau_c=tau_c, tau_s=tau_s,
                v_s=v_s, delta=delta, c_v=c_v, inertia=inertia, ratio=ratio)
    for name, v in vals.items():
        if not math.isfinite(float(v)):
            raise ValueError(f"{name} must be finite, got {v!r}")
    if inertia <= 0:
        raise ValueError("inertia must be positive")
    if ratio <= 0:
        raise ValueError("ratio must be positive")
    if tau_c < 0 or tau_s < 0 or c_v < 0:
        raise ValueError("tau_c, tau_s and c_v must be non-negative")
    if v_s <= 0 or delta <= 0:
        raise ValueError("v_s and delta must be positive")


def reference_trajectory(
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
    rtol: float = 1e-11,
    atol: float = 1e-14,
    extra_torque: ExtraTorque | None = None,
    max_events: int = 10_000,
    extra_holding: Callable[[float], float] | None = None,
    dahl: tuple[float, float] | None = None,
) -> ReferenceTrajectory:
    """Run the event-driven simulation up to ``t_end`` and return the full trajectory object.

    Parameters
    ----------
    t_end : float
        Horizon.  Integration stops earlier if the WG sticks (it then stays put for ever).
    theta0 : float
        WG angle at release, from the spring's zero [rad].
    t_release : float
        Release time [s]; ``θ = theta0`` and ``ω = 0`` for ``t ≤ t_release``.
    k1, k2, tau_c, tau_s, v_s, delta, c_v, inertia : float
        Physical parameters (see module docstring; units Nm/rad, Nm/rad³, Nm, Nm, rad/s, -,
        Nm·s/rad, kg·m²).
    ratio : float, optional
        Gear ratio ``N``.
    rtol, atol : float, optional
        DOP853 tolerances.
    extra_torque : callable, optional
        ``extra_torque(theta, omega) -> float``: an additional smooth torque on the WG [Nm],
        *added* to the right-hand side (positive accelerates towards +θ).  It enters the stick
        test as ``|−T_k(θ/N)/N + extra_torque(θ, 0)| ≤ τ_s``.  A stuck WG stays stuck even if
        ``extra_torque`` would later change (time dependence is ignored).
    max_events : int, optional
        Zeno guard: after this many velocity zeros the WG is declared stuck.
    extra_holding : callable, optional
        ``extra_holding(theta) -> float``: static capacity [Nm] added to ``τ_s`` in the stick
        test (e.g. friction that grows with the load).
    dahl : (float, float), optional
        ``(f_h, sigma_h)``: a Dahl hysteresis element [Nm, Nm/rad] (see module docstring).

    Returns
    -------
    ReferenceTrajectory
    """
    _check_params(theta0, t_release, k1, k2, tau_c, tau_s, v_s, delta, c_v, inertia, ratio)
    N = float(ratio)
    k1 = float(k1)
    k2 = float(k2)
    tau_c = float(tau_c)
    tau_s = float(tau_s)
    v_s = float(v_s)
    delta = float(delta)
    c_v = float(c_v)
    inv_I = 1.0 / float(inertia)
    dstrib = tau_s - tau_c
    exp = math.exp

    if dahl is not None:
        f_h, sigma_h = (float(x) for x in dahl)
        if not (f_h > 0 and sigma_h > 0):
            raise ValueError("dahl = (f_h, sigma_h) must both be positive")
        z = math.copysign(f_h * -math.expm1(-sigma_h * abs(theta0) / f_h), theta0) if theta0 else 0.0
    else:
        z = 0.0

    def net_static_torque(th: float, z: float) -> float:
        d = th / N
        F = -(k1 * d + k2 * d * d * d) / N - z
        if extra_torque is not None:
            F += float(extra_torque(th, 0.0))
        return F

    traj = ReferenceTrajectory(theta0=float(theta0), t_release=float(t_release), t_end=float(t_end))

    t = float(t_release)
    th = float(theta0)
    n_zero = 0
    while True:
        F = net_static_torque(th, z)
        holding = tau_s + (float(extra_holding(th)) if extra_holding is not None else 0.0)
        if abs(F) <= holding:
            decision = "stick"
        elif n_zero > max_events:
            decision = "zeno-stick"
        else:
            decision = "slide+" if F > 0 else "slide-"
        traj.events.append((t, th, decision))
        if decision.endswith("stick"):
            traj.stuck = True
            traj.t_stick = t
            traj.theta_rest = th
            return traj
        if t >= t_end:
            return traj
        s = 1 if F > 0 else -1

        def rhs(_t, y, s=s):
            thv = float(y[0])
            w = float(y[1])
            d = thv / N
            spring = (k1 * d + k2 * d * d * d) / N
            v = s * w
            if v < 0.0:
                v = 0.0
            if dstrib != 0.0:
                fr = s * (tau_c + dstrib * exp(-((v / v_s) ** delta)))
            else:
                fr = s * tau_c
            fr += c_v * w
            acc = -spring - fr
            if extra_torque is not None:
                acc += float(extra_torque(thv, w))
            if dahl is None:
                return np.array([w, acc * inv_I])
            zv = float(y[2])
            return np.array([w, (acc - zv) * inv_I, sigma_h * w * (1.0 - s * zv / f_h)])

        def stop(_t, y, s=s):
            return s * y[1]

        stop.terminal = True
        stop.direction = -1.0

        y0 = np.array([th, 0.0]) if dahl is None else np.array([th, 0.0, z])
        sol = solve_ivp(rhs, (t, t_end), y0, method="DOP853", rtol=rtol,
                        atol=atol, dense_output=True, events=stop)
        if sol.status < 0:
            raise RuntimeError(f"reference integration failed: {sol.message}")
        if sol.status == 1 and len(sol.t_events[0]):
            t_ev = float(sol.t_events[0][0])
            traj.segments.append(_Segment(t, t_ev, s, sol.sol))
            t = t_ev
            th = float(sol.y_events[0][0][0])
            if dahl is not None:
                z = float(sol.y_events[0][0][2])
            n_zero += 1
            continue
        # reached the horizon while sliding
        traj.segments.append(_Segment(t, float(sol.t[-1]), s, sol.sol))
        return traj
