"""Independent reference simulator of the *driven* harmonic-drive joint.

This module uses numpy and scipy only.  It shares no code with hdid's JAX simulator
(``hdid._simulation._driven``), which it is meant to check; the driven log made from it
is :func:`hdid.reference.logs.make_driven_log`.

Model (paper eqs. 3, 8, 9; output inertia neglected, the flexspline is quasi-static)
-------------------------------------------------------------------------------------
θ is the wave-generator (WG, motor) angle in the motor encoder's frame (arbitrary zero),
ω = θ̇, N the gear ratio (100)::

    I·ω̇ = τ_d(t) − (τ_l(t) + τ_fout)/N − τ_din(ω)
    τ_din(ω) = sign(ω)·(τ_c + (τ_s − τ_c)·exp(−|ω/v_s|^δ)) + c_v·ω

* ``τ_d`` — motor torque [N m at the WG], zero-order hold: ``τ_d(t) = motor_torque[k]`` for
  ``t_k ≤ t < t_{k+1}`` (a digital drive's command).
* ``τ_l`` — external torque on the output shaft [N m, output side], linear between samples
  (a measured signal); zero when not given.
* ``τ_fout`` — Coulomb friction at the output, magnitude ``tau_fout`` [N m, output side].
  While the WG slides in direction s = sign(ω): ``τ_fout = tau_fout·s``.  At rest it keeps
  its last sliding value ``tau_fout·s_last`` (the flexspline stays wound; ``s_last = 0``
  before the first motion of a run).
* Stick/slide: with ``F(t) = τ_d − τ_l(t)/N`` and the static capacity
  ``C = τ_s + tau_fout/N``, a WG at rest sticks while ``|F| ≤ C`` and breaks away, in the
  direction of F, when ``|F| > C``.  When a sliding WG reaches ω = 0 the same rule decides
  between sticking and reversing.

Output angle (eq. 8, with the positional error of eq. 3)::

    θ_out = −θ/N + T_k⁻¹(τ_l + τ_fout) + θ̃_p(θ),      T_k(d) = k1·d + k2·d³
    θ̃_p(θ) = a0/2 + Σ_{n=1..K} a_n·cos(nθ) + b_n·sin(nθ)

At a sample instant where the WG is at rest (ω = 0, stuck just before), ``τ_fout`` is the
rest value ``tau_fout·s_last``, even if the WG breaks away at that very instant (a ZOH step
of τ_d): θ_out is the left limit there.

Numerics
--------
Each ZOH interval ``[t_k, t_{k+1})`` is processed on its own (τ_d constant, τ_l linear).
Sliding: :func:`scipy.integrate.solve_ivp` (DOP853, rtol 1e-10, atol 1e-12) with the
friction direction s held fixed, ``|ω|`` evaluated as ``max(s·ω, 0)`` and a terminal,
direction-aware event at ``s·ω = 0``; at the event ω is set to exactly 0 and the
stick/slide rule is applied (a reversal is a stop followed by a breakaway at the same
instant).  Stuck: θ is held exactly; because F is linear in t within the interval, the
breakaway instant is the exact root of ``|F(t)| = C`` (closed form, checked against
:func:`scipy.optimize.brentq` in the tests).  States at the sample instants are interval
end points, so no interpolation is involved.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np
from scipy.integrate import solve_ivp

_PARAM_KEYS = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v", "inertia", "tau_fout")


# ------------------------------------------------------------------------ physics pieces


def _params(params: Mapping) -> dict:
    p = {key: float(params[key]) for key in _PARAM_KEYS}
    for key, value in p.items():
        if not math.isfinite(value):
            raise ValueError(f"{key} must be finite, got {value!r}")
    if p["inertia"] <= 0:
        raise ValueError("inertia must be positive")
    if min(p["tau_c"], p["tau_s"], p["c_v"], p["tau_fout"]) < 0:
        raise ValueError("tau_c, tau_s, c_v and tau_fout must be non-negative")
    if p["v_s"] <= 0 or p["delta"] <= 0:
        raise ValueError("v_s and delta must be positive")
    if p["k1"] <= 0 or p["k2"] < 0:
        raise ValueError("k1 must be positive and k2 non-negative (T_k must be invertible)")
    p["pos_a0"] = float(params.get("pos_a0", 0.0))
    p["pos_a"] = np.asarray(params.get("pos_a", ()), dtype=float).reshape(-1)
    p["pos_b"] = np.asarray(params.get("pos_b", ()), dtype=float).reshape(-1)
    if p["pos_a"].shape != p["pos_b"].shape:
        raise ValueError("pos_a and pos_b must have one coefficient per harmonic each")
    return p


def capacity(params: Mapping, ratio: float = 100.0) -> float:
    """Static capacity at the WG [N m]: ``τ_s + tau_fout/N`` (the stick threshold on
    ``|τ_d − τ_l/N|``)."""
    return float(params["tau_s"]) + float(params["tau_fout"]) / ratio


def sliding_friction(params: Mapping, omega, ratio: float = 100.0):
    """Total friction torque at the WG while sliding at ``omega`` [N m]:
    ``τ_din(ω) + tau_fout·sign(ω)/N`` (what the motor must supply beyond ``τ_l/N`` to
    hold the speed)."""
    w = np.asarray(omega, dtype=float)
    s = np.sign(w)
    a = np.abs(w)
    tau_c, tau_s = float(params["tau_c"]), float(params["tau_s"])
    stribeck = np.exp(-((a / float(params["v_s"])) ** float(params["delta"])))
    return (s * (tau_c + (tau_s - tau_c) * stribeck) + float(params["c_v"]) * w
            + s * float(params["tau_fout"]) / ratio)


def inverse_stiffness(torque, k1: float, k2: float):
    """``T_k⁻¹``: the twist d [rad, output] with ``k1·d + k2·d³ = torque`` [N m].

    Cardano's formula in a cancellation-free form (``d = A − p/A``), polished by two Newton
    steps; ``k2 = 0`` gives ``torque/k1``.
    """
    tau = np.asarray(torque, dtype=float)
    k1 = float(k1)
    k2 = float(k2)
    if k2 == 0.0:
        return tau / k1
    p = k1 / (3.0 * k2)
    q = np.abs(tau) / (2.0 * k2)
    A = np.cbrt(q + np.sqrt(q * q + p**3))
    d = A - p / A
    for _ in range(2):
        d = d - (k1 * d + k2 * d**3 - np.abs(tau)) / (k1 + 3.0 * k2 * d * d)
    return np.sign(tau) * d


def positional_error(theta, pos_a0: float = 0.0, pos_a=(), pos_b=()):
    """Eq. 3: ``a0/2 + Σ_n a_n cos(nθ) + b_n sin(nθ)`` [rad, output] at WG angle(s) θ."""
    th = np.asarray(theta, dtype=float)
    out = np.full(th.shape, 0.5 * float(pos_a0))
    for n, (a, b) in enumerate(zip(np.ravel(pos_a), np.ravel(pos_b)), start=1):
        out = out + a * np.cos(n * th) + b * np.sin(n * th)
    return out


# ------------------------------------------------------------------------ simulator


def simulate_driven(
    params: Mapping,
    times,
    motor_torque,
    load_torque=None,
    theta0: float = 0.0,
    omega0: float = 0.0,
    ratio: float = 100.0,
    *,
    rtol: float = 1e-10,
    atol: float = 1e-12,
    max_events_per_interval: int = 1000,
) -> dict:
    """Simulate a driven run exactly (event-driven) at the sample instants.

    Parameters
    ----------
    params : mapping
        ``k1, k2`` [N m/rad, N m/rad³, output side], ``tau_c, tau_s`` [N m, WG], ``v_s``
        [rad/s], ``delta``, ``c_v`` [N m s/rad], ``inertia`` [kg m²], ``tau_fout`` [N m,
        output side] and optionally ``pos_a0`` [rad], ``pos_a``, ``pos_b`` (a_1…a_K,
        b_1…b_K [rad]).
    times : array_like
        Sample instants [s], strictly increasing (any spacing).
    motor_torque : array_like
        τ_d at each sample [N m, WG], held until the next sample (ZOH).
    load_torque : array_like, optional
        τ_l at each sample [N m, output side], linear in between (default 0).
    theta0, omega0 : float
        WG angle [rad, motor encoder's frame] and speed [rad/s] at ``times[0]``.
        ``omega0 = 0`` (default) starts at rest with ``s_last = 0``.
    ratio : float
        Gear ratio N.
    rtol, atol : float
        DOP853 tolerances.
    max_events_per_interval : int
        Zeno guard: more velocity zeros than this in one interval is an error.

    Returns
    -------
    dict
        ``time``; ``theta`` [rad] and ``omega`` [rad/s] at the samples; ``direction``
        (int8: +1/−1 sliding, 0 stuck, in effect just after each sample); ``fout_sign``
        (int8: sign of τ_fout at the sample, the rest value ``s_last`` when ω = 0 there);
        ``tau_fout`` [N m, output] = ``tau_fout·fout_sign``; ``twist`` = T_k⁻¹(τ_l + τ_fout)
        [rad]; ``positional_error`` [rad]; ``theta_out_clean`` [rad] (eq. 8, unquantized);
        ``load_torque`` (the array used); ``events``: list of ``(t, kind, theta, s)`` with
        kind ``"stick"`` (ω reached 0 and the WG sticks), ``"stop"`` (ω reached 0) or
        ``"slide"`` (breakaway / reversal in direction s); ``stick_intervals``: list of
        ``(t_start, t_end)`` (``t_end`` None if still stuck at the last sample);
        ``reversals``: number of direction changes of the motion; ``capacity``.
    """
    p = _params(params)
    N = float(ratio)
    if not (math.isfinite(N) and N > 0):
        raise ValueError("ratio must be positive")
    t = np.asarray(times, dtype=float).reshape(-1)
    n = t.size
    tau_d = np.asarray(motor_torque, dtype=float).reshape(-1)
    tau_l = np.zeros(n) if load_torque is None else np.asarray(load_torque, dtype=float).reshape(-1)
    if n < 1 or tau_d.size != n or tau_l.size != n:
        raise ValueError("times, motor_torque and load_torque must have the same, nonzero length")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(tau_d)) and np.all(np.isfinite(tau_l))):
        raise ValueError("times and torques must be finite")
    if np.any(np.diff(t) <= 0):
        raise ValueError("times must be strictly increasing")

    I = p["inertia"]
    tau_c, dstrib = p["tau_c"], p["tau_s"] - p["tau_c"]
    v_s, delta, c_v = p["v_s"], p["delta"], p["c_v"]
    fout_wg = p["tau_fout"] / N
    C = p["tau_s"] + fout_wg
    exp = math.exp

    theta = np.empty(n)
    omega = np.empty(n)
    direction = np.zeros(n, dtype=np.int8)
    fout_sign = np.zeros(n, dtype=np.int8)
    events: list[tuple[float, str, float, int]] = []

    th = float(theta0)
    w = float(omega0)
    s = int(np.sign(w))  # 0: at rest (stuck or deciding)
    s_last = s

    def decide(tc: float, F: float, dF: float) -> int:
        """Direction after an at-rest instant: 0 stays stuck, ±1 breaks away."""
        if abs(F) > C:
            return 1 if F > 0 else -1
        # on the boundary and moving outwards: breaks away now (avoids a zero-length stick)
        if abs(F) >= C * (1.0 - 1e-12) and C > 0 and F * dF > 0:
            return 1 if F > 0 else -1
        return 0

    for k in range(n):
        last = k == n - 1
        t0 = t[k]
        Td = tau_d[k]
        L0 = tau_l[k]
        h = None if last else t[k + 1] - t0
        slope = 0.0 if last else (tau_l[k + 1] - L0) / h  # dτ_l/dt
        F0 = Td - L0 / N  # F at t0
        dF = -slope / N  # dF/dt

        def F_at(tt: float) -> float:
            return Td - (L0 + slope * (tt - t0)) / N

        # -- state at the sample (left limit for the output friction)
        theta[k] = th
        omega[k] = w
        fout_sign[k] = s if w != 0.0 else s_last
        if s == 0:
            s = decide(t0, F0, dF)
            if s != 0:
                events.append((t0, "slide", th, s))
                s_last = s
        direction[k] = s
        if last:
            break
        t1 = t[k + 1]
        tc = t0
        n_ev = 0
        while tc < t1:
            if s == 0:
                # stuck on [tc, ...): exact breakaway where |F(t)| = C (F is linear here)
                if dF == 0.0:
                    break
                target = C if dF > 0 else -C
                tb = t0 + (Td - L0 / N - target) * N / slope  # F(tb) = target
                if not (tb < t1):
                    break
                tb = max(tb, tc)
                s = 1 if dF > 0 else -1
                s_last = s
                tc = tb
                events.append((tc, "slide", th, s))
                continue

            def rhs(tt, y, s=s):
                wv = y[1]
                v = s * wv
                if v < 0.0:
                    v = 0.0
                fr = s * (tau_c + (dstrib * exp(-((v / v_s) ** delta)) if dstrib else 0.0))
                fr += c_v * wv + s * fout_wg
                return (wv, (Td - (L0 + slope * (tt - t0)) / N - fr) / I)

            def stop(tt, y, s=s):
                return s * y[1] + 1e-15

            stop.terminal = True
            stop.direction = -1.0
            sol = solve_ivp(rhs, (tc, t1), (th, w), method="DOP853", rtol=rtol, atol=atol,
                            events=stop)
            if sol.status < 0:
                raise RuntimeError(f"driven reference integration failed: {sol.message}")
            if sol.status == 1:
                te = float(sol.t_events[0][0])
                th = float(sol.y_events[0][0][0])
                w = 0.0
                n_ev += 1
                if n_ev > max_events_per_interval:
                    raise RuntimeError(f"more than {max_events_per_interval} velocity zeros in "
                                       f"[{t0}, {t1}] (Zeno chattering)")
                s_prev = s
                s = decide(te, F_at(te), dF) if te < t1 else 0
                if s == 0:
                    events.append((te, "stick", th, s_prev))
                else:
                    events.append((te, "stop", th, s_prev))
                    events.append((te, "slide", th, s))
                    s_last = s
                tc = te
            else:
                th = float(sol.y[0, -1])
                w = float(sol.y[1, -1])
                tc = t1

    # -- stick intervals and reversals from the events
    stick_intervals: list[tuple[float, float | None]] = []
    open_since = float(t[0]) if omega0 == 0.0 else None
    reversals = 0
    prev_dir = int(np.sign(omega0))
    for te, kind, _, sd in events:
        if kind == "stick":
            open_since = te
        elif kind == "slide":
            if open_since is not None:
                stick_intervals.append((open_since, te))
                open_since = None
            if prev_dir != 0 and sd != prev_dir:
                reversals += 1
            prev_dir = sd
    if open_since is not None:
        stick_intervals.append((open_since, None))

    tau_fout = p["tau_fout"] * fout_sign.astype(float)
    twist = inverse_stiffness(tau_l + tau_fout, p["k1"], p["k2"])
    pos = positional_error(theta, p["pos_a0"], p["pos_a"], p["pos_b"])
    return {
        "time": t,
        "theta": theta,
        "omega": omega,
        "direction": direction,
        "fout_sign": fout_sign,
        "tau_fout": tau_fout,
        "load_torque": tau_l,
        "twist": twist,
        "positional_error": pos,
        "theta_out_clean": -theta / N + twist + pos,
        "events": events,
        "stick_intervals": stick_intervals,
        "reversals": reversals,
        "capacity": C,
    }
