"""The synthetic driven log: the design of ``data/synthetic/driven_csf8.csv`` and
:func:`make_driven_log`, which runs it through the driven reference simulator
(:mod:`hdid.reference._driven`; numpy/scipy only, no code shared with hdid's JAX simulator).

The design of the shipped log (:data:`DRIVEN_DESIGN`) is described in
:func:`make_driven_log`, in :func:`_design_note` and in the comments of the design.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from ._driven import _PARAM_KEYS, _params, capacity, simulate_driven
from ._logs import COUNTS_PER_REV  # the motor encoder, as the free-motion logs

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
DRIVEN_DESIGN: dict = {
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


def make_driven_log(params: Mapping = TRUTH_DRIVEN_CSF8, design: Mapping = DRIVEN_DESIGN,
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
        default :data:`DRIVEN_DESIGN`.
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
