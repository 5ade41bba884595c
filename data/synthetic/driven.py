"""Independent reference simulator of the *driven* harmonic-drive joint and its synthetic log.

Run ``python data/synthetic/driven.py`` to regenerate, deterministically (fixed seed),
``data/synthetic/driven_csf8.csv`` and its entry ``"driven_csf8.csv"`` of ``truth.json``
(only that key is replaced; the other entries are kept as they are).

This module uses numpy and scipy only.  It shares no code with hdid's JAX simulator, which
it is meant to check (it imports nothing from hdid at all).

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

The design of the shipped log (``DESIGN``) is described in :func:`make_driven_log` and in
the comments of :data:`DESIGN`.
"""

from __future__ import annotations

import copy
import json
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

__all__ = [
    "TRUTH_DRIVEN_CSF8",
    "COUNTS_PER_REV",
    "OUTPUT_COUNTS_PER_REV",
    "DESIGN",
    "capacity",
    "inverse_stiffness",
    "positional_error",
    "sliding_friction",
    "simulate_driven",
    "make_driven_log",
    "build",
]

_HERE = Path(__file__).resolve().parent
FILE_NAME = "driven_csf8.csv"

#: Motor encoder counts per revolution (as the free-motion logs).
COUNTS_PER_REV = 4000
#: Output encoder counts per revolution (a 19-bit absolute encoder).
OUTPUT_COUNTS_PER_REV = 2**19

#: CSF-8-100-like truth: k1 … inertia as ``csf8_paper.csv`` (truth.json) so that a joint fit
#: of both logs is possible; output friction and positional error from the physics notes.
TRUTH_DRIVEN_CSF8: dict = {
    "k1": 940.0,  # N m/rad (output side)
    "k2": 6.5e7,  # N m/rad^3 (output side)
    "tau_c": 2.5e-3,  # N m (WG)
    "tau_s": 4.5e-3,  # N m (WG)
    "v_s": 5.0,  # rad/s (WG)
    "delta": 1.0,  # -
    "c_v": 1.8e-5,  # N m s/rad (WG)
    "inertia": 7.0e-7,  # kg m^2 (WG)
    # Output Coulomb friction 0.05 N m: 3 % of the ~1.7 N m rated-range torque; at the WG it
    # is 5e-4 N m, 11 % of tau_s.  Its sign flips the twist by 2*tau_fout/k1 ≈ 1.1e-4 rad
    # (≈ 9 output counts) between directions: that is what separates it from tau_c.
    "tau_fout": 0.05,  # N m (output side)
    # Positional error (eq. 3), order 3, dominant n = 2 (the WG's two lobes); the periodic
    # part has 4.4e-4 rad peak-to-peak (the notes give <= 5.8e-4 rad).  a0/2 is the zero of
    # the output encoder relative to -theta/N.
    "pos_a0": 3.0e-4,  # rad (output side)
    "pos_a": [3.0e-5, 1.5e-4, -2.5e-5],  # a_1, a_2, a_3 [rad]
    "pos_b": [-2.0e-5, 1.6e-4, 2.0e-5],  # b_1, b_2, b_3 [rad]
}

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


# ------------------------------------------------------------------------ the shipped design


def _design_note() -> str:
    return (
        "Physics of the design (WG side, truth values): static capacity C = tau_s + "
        "tau_fout/N = 5.0 mN m; sliding friction 3.0 mN m + 2.0 mN m*exp(-|w|/5) + "
        "1.8e-5*|w| (minimum 3.37 mN m near 15 rad/s; the Stribeck branch below that is "
        "unstable under constant torque, so low speeds are crossed in transients only); "
        "mechanical time constant I/c_v = 39 ms (~10 samples at 250 Hz). The motor torque is "
        "u(t) + (mean load over the sample interval)/N: the drive compensates the measured "
        "load (feed-forward) and u, the net drive, is a sequence of ZOH steps and ramps: "
        "(1) slow ramps of u through C make the breakaway instant pin C down (mid-interval, "
        "because the load moves within the interval); (2) steps to cruise levels 3.4-4.3 "
        "mN m give terminal speeds ~20-70 rad/s approached with the 39 ms time constant "
        "(friction at several speeds, c_v) and the accelerations after each step give the "
        "inertia absolutely (torque is known in N m); (3) drops to |u| < C stop the WG and "
        "it sticks for 30-320 ms (stick logic, rest values of the output friction); "
        "(4) steps to |u| > C of opposite sign reverse it without sticking. Each run turns "
        "the WG through several revolutions (positional error sampled over full periods at "
        "many phases) while the load torque sweeps about -1.2...+1.2 N m slowly (0.6-0.9 "
        "Hz, independent of the WG phase), so the twist T_k^-1(tau_l + tau_fout) spans the "
        "cubic range (k2*d^3 is ~9 % of the torque at 1.25 N m); the output friction flips "
        "the twist by 2*tau_fout/k1 = 1.1e-4 rad (9 output counts) at every reversal."
    )


#: Net-drive profile of each run: list of ``(t_end [s], kind, value(s) [N m])`` with kind
#: ``"hold"`` (constant u) or ``"ramp"`` (linear from a to b over the segment, sampled at
#: the interval start).  Load: ``(amplitude [N m], frequency [Hz], kind)``.
DESIGN: dict = {
    "fs": 250.0,
    "seed": 20261122,
    "runs": [
        {   # positive start: ramp breakaway, two cruise speeds, stick, negative, stick, …
            "segments": [
                (0.06, "hold", 0.0),             # stuck, load moving (twist at rest, s_last = 0)
                (0.18, "ramp", (0.0, 5.8e-3)),   # breakaway where u crosses C = 5 mN m
                (0.40, "hold", 3.6e-3),          # settle to ~33 rad/s (39 ms time constant)
                (0.60, "hold", 4.3e-3),          # accelerate to ~72 rad/s
                (0.74, "hold", 0.0),             # coast down (~15 ms) and stick (~120 ms)
                (0.748, "hold", -5.6e-3),        # 2-sample kick: break away negative
                (1.02, "hold", -3.8e-3),         # cruise ~ -44 rad/s
                (1.08, "hold", 1.5e-3),          # stop within ~6 ms and stick (|u| < C)
                (1.088, "hold", 5.4e-3),         # kick: break away positive
                (1.46, "hold", 3.5e-3),          # slow cruise ~27 rad/s
                (1.472, "hold", -5.8e-3),        # 3-sample pulse: reversal without sticking
                (1.80, "hold", -3.6e-3),         # cruise ~ -33 rad/s
            ],
            "load": (1.2, 0.6, "sine"),
        },
        {   # negative start, speed staircase, a brief stick, a hard reversal
            "segments": [
                (0.04, "hold", 0.0),
                (0.16, "ramp", (0.0, -5.8e-3)),  # breakaway at u = -C
                (0.30, "hold", -3.45e-3),        # ~ -23 rad/s
                (0.46, "hold", -3.8e-3),         # ~ -44
                (0.62, "hold", -4.2e-3),         # ~ -66
                (0.66, "hold", -2.0e-3),         # decelerate (~2000 rad/s^2), stop, stick
                (0.68, "hold", -0.5e-3),         # brief stick (~30 ms)
                (0.688, "hold", 6.2e-3),         # kick positive
                (1.10, "hold", 3.9e-3),          # ~ +50
                (1.30, "hold", 3.5e-3),          # slow down to ~ +27
                (1.312, "hold", -6.5e-3),        # hard reversal, no stick
                (1.60, "hold", -3.6e-3),
                (1.76, "hold", 0.0),             # stop and stick to the end
            ],
            "load": (1.2, 0.75, "triangle"),
        },
        {   # square-wave reversals (accelerations, no sticking), then a slow negative ramp
            "segments": [
                (0.03, "hold", 0.0),
                (0.038, "hold", 5.5e-3),         # breakaway by a step (at a sample instant)
                (0.24, "hold", 3.7e-3),          # ~ +39
                (0.252, "hold", -5.2e-3),        # reverse through zero without sticking
                (0.52, "hold", -3.7e-3),
                (0.532, "hold", 5.6e-3),
                (0.80, "hold", 4.0e-3),          # ~ +55
                (0.812, "hold", -5.8e-3),
                (1.08, "hold", -4.0e-3),
                (1.18, "hold", 0.8e-3),          # stop and stick
                (1.30, "ramp", (0.8e-3, -5.8e-3)),  # slow ramp to the negative breakaway
                (1.50, "hold", -3.6e-3),
                (1.70, "hold", -4.3e-3),
            ],
            "load": (1.2, 0.9, "sine"),
        },
        {   # slow ramps both ways (breakaway, Stribeck transients), near-minimum friction
            "segments": [
                (0.05, "hold", 0.0),
                (0.20, "ramp", (0.0, 5.6e-3)),
                (0.42, "hold", 3.4e-3),          # ~ +20 rad/s, near the friction minimum
                (0.50, "hold", 2.5e-3),          # decelerate; sticks
                (0.58, "hold", -1.0e-3),
                (0.78, "ramp", (-1.0e-3, -5.6e-3)),
                (1.00, "hold", -3.5e-3),
                (1.12, "hold", -4.4e-3),         # ~ -75 rad/s peak
                (1.24, "hold", 0.0),             # coast down, stick
                (1.248, "hold", 5.8e-3),
                (1.56, "hold", 3.8e-3),          # ~ +44
                (1.70, "hold", -1.5e-3),         # stop and stick at the end
            ],
            "load": (1.2, 0.7, "sine2"),
        },
    ],
}


def _net_drive(segments: Sequence, t: np.ndarray) -> np.ndarray:
    """u at the sample instants from a segment list (each sample takes the segment it is in)."""
    u = np.zeros(t.size)
    start = 0.0
    for end, kind, value in segments:
        m = (t >= start - 1e-12) & (t < end - 1e-12)
        if kind == "hold":
            u[m] = float(value)
        elif kind == "ramp":
            a, b = (float(v) for v in value)
            u[m] = a + (b - a) * (t[m] - start) / (end - start)
        else:
            raise ValueError(f"unknown segment kind {kind!r}")
        start = end
    return u


def _load_profile(spec, t: np.ndarray, phase: float) -> np.ndarray:
    amp, freq, kind = spec
    x = 2.0 * math.pi * freq * t + phase
    if kind == "sine":
        return amp * np.sin(x)
    if kind == "triangle":
        return amp * (2.0 / math.pi) * np.arcsin(np.sin(x))
    if kind == "sine2":  # two tones, scaled so that the larger excursion is the amplitude
        y = np.sin(x) + 0.35 * np.sin(2.7 * x + 1.0)
        return amp * y / np.max(np.abs(y))
    raise ValueError(f"unknown load kind {kind!r}")


def make_driven_log(params: Mapping = TRUTH_DRIVEN_CSF8, design: Mapping = DESIGN,
                    seed: int | None = None) -> tuple[pd.DataFrame, dict]:
    """Make the synthetic driven log and its truth.

    Parameters
    ----------
    params : mapping
        Physical parameters (see :func:`simulate_driven`), default
        :data:`TRUTH_DRIVEN_CSF8`.
    design : mapping
        ``fs`` [Hz], ``runs`` (each: ``segments`` of the net drive u, ``load`` spec), and
        optionally ``counts_per_rev``, ``output_counts_per_rev``, ``ratio``, ``seed``;
        default :data:`DESIGN`.
    seed : int, optional
        Seed of :func:`numpy.random.default_rng` (default ``design["seed"]``).  It draws each
        run's initial WG angle (uniform in [−π, π)) and load phase.

    Returns
    -------
    (pandas.DataFrame, dict)
        Columns ``time`` [s, from 0 in each run], ``run`` (1-based int), ``theta`` [rad, WG,
        quantized to ``counts_per_rev``], ``theta_out`` [rad, quantized to
        ``output_counts_per_rev``], ``motor_torque`` [N m, WG], ``load_torque`` [N m,
        output]; noiseless apart from quantization.  The truth dict has ``params``,
        encoder data, the conventions and per-run statistics.

    Notes
    -----
    The motor torque is ``τ_d[k] = u[k] + (τ_l[k] + τ_l[k+1])/(2N)``: the drive compensates
    the mean measured load over the coming interval, so the net drive ``u`` (design
    segments) sets the motion while the load sweeps the twist through the cubic range; the
    residual ``F(t) − u`` is linear within each interval (≤ 1e-4 N m), which makes
    breakaway happen between samples.  See :func:`_design_note` for the physics of the
    profile choices.
    """
    fs = float(design["fs"])
    N = float(design.get("ratio", 100.0))
    cpr = int(design.get("counts_per_rev", COUNTS_PER_REV))
    out_cpr = int(design.get("output_counts_per_rev", OUTPUT_COUNTS_PER_REV))
    seed = int(design.get("seed", 0) if seed is None else seed)
    rng = np.random.default_rng(seed)
    step = 2.0 * math.pi / cpr
    out_step = 2.0 * math.pi / out_cpr
    p = _params(params)

    frames = []
    runs_info = []
    for i, spec in enumerate(design["runs"], start=1):
        duration = float(spec["segments"][-1][0])
        n = int(round(duration * fs))
        # times and torques exactly as they will be read back from the CSV
        t = np.array([float(f"{x:.12g}") for x in np.arange(n) / fs])
        theta0 = float(rng.uniform(-math.pi, math.pi))
        phase = float(rng.uniform(0.0, 2.0 * math.pi))
        load = _load_profile(spec["load"], t, phase)
        u = _net_drive(spec["segments"], t)
        mean_next = np.append(0.5 * (load[:-1] + load[1:]), load[-1])
        motor = u + mean_next / N
        sim = simulate_driven(p, t, motor, load,
                              theta0=theta0, omega0=0.0, ratio=N)
        theta_q = np.round(sim["theta"] / step) * step
        out_q = np.round(sim["theta_out_clean"] / out_step) * out_step
        frames.append(pd.DataFrame({
            "time": t, "run": i, "theta": theta_q, "theta_out": out_q,
            "motor_torque": motor, "load_torque": load,
        }))
        path = float(np.sum(np.abs(np.diff(sim["theta"]))))
        sticks = [(a, b) for a, b in sim["stick_intervals"]]
        runs_info.append({
            "run": i,
            "theta0": theta0,
            "omega0": 0.0,
            "n_samples": n,
            "duration": float(t[-1] - t[0]),
            "load": {"amplitude": spec["load"][0], "frequency_hz": spec["load"][1],
                     "kind": spec["load"][2], "phase": phase},
            "max_abs_omega": float(np.max(np.abs(sim["omega"]))),
            "reversals": int(sim["reversals"]),
            "stick_intervals": [[a, b] for a, b in sticks],
            "revolutions_travelled": path / (2.0 * math.pi),
            "revolutions_net": float(sim["theta"][-1] - sim["theta"][0]) / (2.0 * math.pi),
            "twist_range": [float(sim["twist"].min()), float(sim["twist"].max())],
            "load_range": [float(load.min()), float(load.max())],
            "motor_torque_range": [float(motor.min()), float(motor.max())],
            "theta_last": float(sim["theta"][-1]),
            "omega_last": float(sim["omega"][-1]),
        })
    df = pd.concat(frames, ignore_index=True)
    truth = {
        "params": {key: p[key] for key in _PARAM_KEYS}
        | {"pos_a0": p["pos_a0"], "pos_a": p["pos_a"].tolist(), "pos_b": p["pos_b"].tolist()},
        "ratio": N,
        "fs": fs,
        "counts_per_rev": cpr,
        "step_rad": step,
        "output_counts_per_rev": out_cpr,
        "output_step_rad": out_step,
        "units": {"theta": "rad", "theta_out": "rad", "motor_torque": "N m (WG)",
                  "load_torque": "N m (output)"},
        "quantized": True,
        "noise_std": 0.0,
        "seed": seed,
        "capacity_wg": capacity(p, N),
        "companion_free_motion_log": "csf8_paper.csv",
        "conventions": (
            "Driven joint, paper eqs. 8-9: I*w' = tau_d - (tau_l + tau_fout)/N - tau_din(w); "
            "tau_d ZOH, tau_l linear between samples; tau_fout = tau_fout*sign(w) while "
            "sliding, its last sliding value at rest (0 before the first motion); the WG "
            "sticks while |tau_d - tau_l/N| <= tau_s + tau_fout/N. theta_out = -theta/N + "
            "T_k^-1(tau_l + tau_fout) + a0/2 + sum a_n cos(n theta) + b_n sin(n theta), "
            "theta the WG angle in the motor encoder's frame (as logged, before "
            "quantization); at a sample where the WG is at rest tau_fout is the rest value "
            "(left limit) even if it breaks away at that instant. Each run starts at rest "
            "(omega0 = 0) at its first sample at the physical angle theta0."
        ),
        "notes": ("Generated by data/synthetic/driven.py (numpy/scipy event-driven "
                  "reference, DOP853 rtol 1e-10, atol 1e-12, exact stick/breakaway). "
                  "Quantized, noiseless. " + _design_note()),
        "runs": runs_info,
    }
    df.attrs["truth"] = truth
    return df, copy.deepcopy(truth)


def _write_csv(df: pd.DataFrame, path: Path) -> None:
    out = pd.DataFrame({
        "time": [f"{v:.12g}" for v in df["time"]],
        "run": df["run"].astype(int),
        "theta": [f"{v:.15g}" for v in df["theta"]],
        "theta_out": [f"{v:.15g}" for v in df["theta_out"]],
        "motor_torque": [repr(float(v)) for v in df["motor_torque"]],
        "load_torque": [repr(float(v)) for v in df["load_torque"]],
    })
    out.to_csv(path, index=False, lineterminator="\n")


def build(outdir: Path | str = _HERE) -> dict:
    """Write ``driven_csf8.csv`` in `outdir` and set its key in ``truth.json`` (others kept)."""
    outdir = Path(outdir)
    df, truth = make_driven_log(TRUTH_DRIVEN_CSF8, DESIGN)
    _write_csv(df, outdir / FILE_NAME)
    truth_path = outdir / "truth.json"
    files = json.loads(truth_path.read_text()) if truth_path.exists() else {}
    files[FILE_NAME] = truth
    with open(truth_path, "w") as fh:
        json.dump(files, fh, indent=2)
        fh.write("\n")
    return truth


if __name__ == "__main__":
    info = build(_HERE)
    size = (_HERE / FILE_NAME).stat().st_size
    print(f"{FILE_NAME}: {len(info['runs'])} runs, {size / 1024:.1f} kB, "
          f"capacity {info['capacity_wg'] * 1e3:.2f} mN m")
    for r in info["runs"]:
        sticks = ", ".join(f"{a:.3f}-{'end' if b is None else f'{b:.3f}'}"
                           for a, b in r["stick_intervals"])
        print(f"  run {r['run']}: n {r['n_samples']}, max|w| {r['max_abs_omega']:.1f} rad/s, "
              f"reversals {r['reversals']}, revs travelled {r['revolutions_travelled']:.1f} "
              f"(net {r['revolutions_net']:+.1f}), twist [{r['twist_range'][0]:+.3e}, "
              f"{r['twist_range'][1]:+.3e}] rad, sticks {sticks}")
