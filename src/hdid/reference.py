"""Independent, high-accuracy, event-driven reference simulator of the free-motion test.

This module is the ground truth against which the JAX simulator is tested and the generator
of the synthetic logs in ``data/synthetic``.  It deliberately uses nothing but numpy and
scipy (no JAX), and shares no code with the JAX simulator.

Model (all angles at the wave generator, WG, measured from the spring's zero)::

    I·θ̈ = −T_k(θ/N)/N − τ_f(ω) + τ_x(θ, ω),      T_k(d) = k1·d + k2·d³

    sliding (ω ≠ 0, s = sign ω):
        τ_f = s·(τ_c + (τ_s − τ_c)·exp(−|ω/v_s|^δ)) + c_v·ω

    at rest (ω = 0, at release or whenever the velocity reaches zero), with
    F = −T_k(θ/N)/N + τ_x(θ, 0) the net non-friction torque:
        |F| ≤ τ_s  →  the WG sticks, exactly and for ever;
        |F| > τ_s  →  it slides in direction sign(F), the friction at ω = 0⁺ being τ_s.

``τ_x`` is the optional ``extra_torque(theta, omega)`` (zero by default); the optional
``extra_holding(theta)`` adds static capacity (the stick test becomes
``|F| ≤ τ_s + extra_holding(θ)``) and the optional ``dahl = (f_h, sigma_h)`` adds a Dahl
hysteresis element, an extra state ``z`` with ``dz/dt = sigma_h·ω·(1 − s·z/f_h)`` whose
torque ``−z`` enters both the motion and ``F``; ``z(release) = sign(θ0)·f_h·(1 −
exp(−sigma_h·|θ0|/f_h))`` (the servo twisted the WG monotonically from the spring's zero).
These hooks let the test suite hide effects in synthetic logs with code that shares
nothing with the JAX effects.

Numerics
--------
Each sliding segment is integrated with :func:`scipy.integrate.solve_ivp` (DOP853, dense
output) with the friction direction ``s`` held *fixed*, and a terminal, direction-aware event
on ``s·ω = 0`` (crossing downwards).  Within a segment ``|ω|`` is evaluated as
``max(s·ω, 0)``, so the right-hand side is smooth on the segment's side of ``ω = 0`` and
``|ω/v_s|^δ`` is never evaluated at a negative base; at ``ω = 0`` it is exactly ``0`` (δ > 0),
so the friction there is exactly ``s·τ_s``.  At every event the state is reset to ``ω = 0``
exactly and the stick/slide rule above is applied.  A guard (``max_events``) stops Zeno
chattering by sticking after that many events.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import brentq

__all__ = [
    "ReferenceTrajectory",
    "reference_trajectory",
    "simulate_reference",
    "simulate_reference_dense",
    "stick_band_halfwidth",
    "spring_torque_wg",
]

ExtraTorque = Callable[[float, float], float]


def spring_torque_wg(theta, k1: float, k2: float, ratio: float = 100.0):
    """Spring torque reflected to the wave generator, ``T_k(θ/N)/N``.

    Parameters
    ----------
    theta : float or array_like
        WG angle from the spring's zero [rad].
    k1, k2 : float
        Output-side stiffness coefficients [Nm/rad], [Nm/rad³].
    ratio : float, optional
        Gear ratio ``N``.

    Returns
    -------
    float or numpy.ndarray
        Torque at the WG [Nm] (the restoring torque is its negative).
    """
    d = np.asarray(theta, dtype=float) / ratio
    out = (k1 * d + k2 * d**3) / ratio
    return float(out) if np.ndim(out) == 0 else out


def stick_band_halfwidth(k1: float, k2: float, tau_s: float, ratio: float = 100.0) -> float:
    """Half-width of the stick band at the wave generator.

    Solves ``(k1·(θ_b/N) + k2·(θ_b/N)³)/N = τ_s`` for ``θ_b > 0``: a WG at rest with
    ``|θ| ≤ θ_b`` (and no extra torque) stays stuck.

    Parameters
    ----------
    k1 : float
        Linear output-side stiffness [Nm/rad], ``k1 ≥ 0``.
    k2 : float
        Cubic output-side stiffness [Nm/rad³].  Negative (softening) values are allowed;
        if the spring torque never reaches ``τ_s`` the band is unbounded (``inf``).
    tau_s : float
        Static (breakaway) friction torque at the WG [Nm].
    ratio : float, optional
        Gear ratio ``N`` (default 100).

    Returns
    -------
    float
        ``θ_b`` [rad, WG side]; ``0.0`` if ``τ_s ≤ 0``; ``inf`` if unbounded.
    """
    N = float(ratio)
    k1 = float(k1)
    k2 = float(k2)
    target = N * float(tau_s)  # output-side torque to reach
    if target <= 0.0:
        return 0.0
    if k1 < 0.0:
        raise ValueError("k1 must be non-negative")

    def g(x: float) -> float:
        return k1 * x + k2 * x**3 - target

    if k2 >= 0.0:
        bounds = []
        if k1 > 0.0:
            bounds.append(target / k1)
        if k2 > 0.0:
            bounds.append((target / k2) ** (1.0 / 3.0))
        if not bounds:
            return math.inf
        hi = min(bounds)
    else:
        if k1 == 0.0:
            return math.inf
        hi = math.sqrt(k1 / (3.0 * -k2))  # torque maximum of a softening cubic
        if g(hi) < 0.0:
            return math.inf
    if g(hi) == 0.0:
        return N * hi
    x = brentq(g, 0.0, hi, xtol=1e-300, rtol=4.0 * np.finfo(float).eps, maxiter=500)
    return N * float(x)


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
