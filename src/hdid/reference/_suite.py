"""Broad plants for the diagnose suite and its calibrations: a CSF-8-like gear scaled by a
factor of 0.3-3 (every parameter drawn around it), the paper design (4 releases of 0.157 rad
at 250 Hz, two set-ups) or a rich design (8 releases of 0.05-0.3 rad at 0.5-2 kHz), and the
size of each hidden effect relative to the drawn plant (:func:`hidden_params`). Used by
``benchmarks/diagnose_independent.py`` (the independent suite) and
``calibration/floor_thresholds.py``; the logs themselves come from :func:`make_log`."""

from __future__ import annotations

import math

import numpy as np

N = 100.0
SAMPLES = 300  # per run, rich design (hold 40 samples): the calibration's rich shape


def draw_plant(design: str, seed: int) -> tuple[dict, dict]:
    """A plant (``generate.make_log``'s truth) and a design for one log."""
    rng = np.random.default_rng(seed)
    g = math.exp(rng.uniform(math.log(0.3), math.log(3.0)))
    if design == "rich":
        a_min, a_max = rng.uniform(0.05, 0.08), rng.uniform(0.2, 0.3)
        mid = np.sort(rng.uniform(a_min + 0.02, a_max - 0.02, 2))[::-1]
        mags = [a_max, *mid, a_min]
        fs = float(rng.choice([500.0, 1000.0, 2000.0]))
        des = dict(amplitudes=[s * a for a in mags for s in (1, -1)], fs=fs, duration=SAMPLES / fs, hold=40 / fs,
                   offsets_by_setup={"A": float(rng.uniform(-0.02, 0.02))})
    else:
        a_min = 0.157
        des = dict(amplitudes=[0.157, -0.157, 0.157, -0.157], fs=250.0, duration=0.5,
                   hold=0.04, offsets_by_setup={"A": float(rng.uniform(-0.03, 0.03)),
                                                "B": float(rng.uniform(-0.03, 0.03))})
    k1 = 940.0 * g * rng.uniform(0.8, 1.25)
    k_wg = k1 / N**2
    r = rng.uniform(1.3, 2.0)
    tau_c = min(2.5e-3 * g * rng.uniform(0.6, 1.4), 0.4 * k_wg * a_min / r)
    truth = {"k1": k1, "k2": 6.5e7 * g * rng.uniform(0.5, 1.5), "tau_c": tau_c,
             "tau_s": r * tau_c, "v_s": rng.uniform(2.0, 10.0), "delta": rng.uniform(0.5, 2.5),
             "c_v": 1.8e-5 * g * rng.uniform(0.5, 2.0), "inertia": 7e-7 * g * rng.uniform(0.6, 1.6)}
    return truth, {**des, "gear_factor": g}


def hidden_params(name: str, truth: dict, design: dict, rng) -> dict:
    """Magnitudes of the hidden effect, relative to the drawn plant and design."""
    k1, k_wg, tc = truth["k1"], truth["k1"] / N**2, truth["tau_c"]
    amps = [abs(a) for a in design["amplitudes"]]
    a_max = max(amps)
    if name == "backlash":
        return {"backlash": rng.uniform(0.01, 0.025)}
    if name == "hysteresis":
        return {"f_h": rng.uniform(0.3, 0.6) * tc, "sigma_h": rng.uniform(0.7, 1.5) * k_wg}
    if name == "asymmetric_friction":
        return {"asym": rng.choice([-1, 1]) * rng.uniform(0.2, 0.4)}
    if name == "load_friction":
        return {"c_load": rng.uniform(0.05, 0.15) * k_wg}
    if name == "ripple":
        amp, ph = rng.uniform(0.15, 0.35) * tc, rng.uniform(0, 2 * math.pi)
        return {"ripple_a": amp * math.cos(ph), "ripple_b": amp * math.sin(ph),
                "order": float(rng.choice([8.0, 12.0, 16.0, 24.0, 36.0]))}
    if name == "soft_windup":
        d = a_max / N
        t_max = k1 * d + truth["k2"] * d**3
        return {"K1": rng.uniform(0.55, 0.7) * k1, "K2": rng.uniform(1.0, 1.1) * k1,
                "K3": 1.25 * k1, "T1": rng.uniform(0.08, 0.15) * t_max, "dT12": rng.uniform(0.3, 0.4) * t_max}
    if name == "kinematic_error":
        return {"ke_a": rng.choice([-1, 1]) * rng.uniform(1.5e-4, 2.5e-4),
                "ke_b": rng.choice([-1, 1]) * rng.uniform(1.5e-4, 2.5e-4), "order": 2.0}
    if name == "quadratic_drag":
        return {"c_2": rng.uniform(0.7, 1.5) * 1e-6 * truth["inertia"] / 7e-7}
    raise KeyError(name)


def suite_log(design: str, seed: int, name: str) -> tuple[dict, dict, dict]:
    """The suite's draw for one log: truth, design and the hidden effect's parameters."""
    truth, des = draw_plant(design, seed)
    hp = hidden_params(name, truth, des, np.random.default_rng(seed + 10_000)) if name != "none" else {}
    return truth, des, hp
