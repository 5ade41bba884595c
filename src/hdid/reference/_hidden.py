"""Hidden effects for the diagnosis suite, written for the *reference* simulator.

Each entry of :data:`HIDDEN` hides one physical effect in a synthetic log: ``truth`` are the
effect's parameters (named as in the hdid effect that models it, so a test can compare
them), ``library`` is the ``hdid diagnose`` candidate that should find it (``None`` for an
effect outside the library), and ``reference(base) -> dict`` returns the keyword arguments
(``extra_torque``, ``extra_holding``, ``dahl``) of :func:`hdid.reference.reference_trajectory`.
Everything here is plain numpy written from the equations, sharing no code with the JAX
effects in ``src/hdid/effects`` — that is what makes the suite an independent check.

Sizes follow ``shared/reference/physics-notes.md`` (typical values for a CSF-8-100),
chosen at the visible end of each range; the notes beside each say why.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

N = 100.0


def _cubic_wg(theta: float, k1: float, k2: float) -> float:
    d = theta / N
    return (k1 * d + k2 * d**3) / N


def _backlash(base: Mapping, b: float) -> dict:
    # dead zone of total width b [rad, WG] in the spring; replaces the cubic spring:
    # extra = (restoring torque with the zone) − (restoring torque without it)
    k1, k2 = base["k1"], base["k2"]

    def extra(theta, omega):
        d = theta / N
        e = math.copysign(max(abs(d) - 0.5 * b / N, 0.0), d)
        return _cubic_wg(theta, k1, k2) - (k1 * e + k2 * e**3) / N

    return {"extra_torque": extra}


def _segments(base: Mapping, K1, K2, K3, T1, dT12) -> dict:
    k1, k2 = base["k1"], base["k2"]
    d1 = T1 / K1
    d2 = d1 + dT12 / K2

    def spring(d):
        a = abs(d)
        if a <= d1:
            t = K1 * a
        elif a <= d2:
            t = T1 + K2 * (a - d1)
        else:
            t = T1 + dT12 + K3 * (a - d2)
        return math.copysign(t, d)

    def extra(theta, omega):
        return _cubic_wg(theta, k1, k2) - spring(theta / N) / N

    return {"extra_torque": extra}


def _kinematic(base: Mapping, ke_a, ke_b, order) -> dict:
    k1, k2 = base["k1"], base["k2"]

    def extra(theta, omega):
        d = theta / N + ke_a * math.sin(order * theta) + ke_b * math.cos(order * theta)
        dd = 1.0 / N + order * (ke_a * math.cos(order * theta) - ke_b * math.sin(order * theta))
        return _cubic_wg(theta, k1, k2) - (k1 * d + k2 * d**3) * dd

    return {"extra_torque": extra}


def _asymmetric(base: Mapping, asym) -> dict:
    # sliding friction (1 + s·asym)·m(ω) in direction s; the reference applies the
    # symmetric s·m(ω), so the difference is −asym·m(ω) — at rest too (m(0) = tau_s).
    tc, ts, vs, dl = base["tau_c"], base["tau_s"], base["v_s"], base["delta"]

    def extra(theta, omega):
        return -asym * (tc + (ts - tc) * math.exp(-((abs(omega) / vs) ** dl)))

    return {"extra_torque": extra}


def _load(base: Mapping, c_load) -> dict:
    def extra(theta, omega):
        return -np.sign(omega) * c_load * abs(theta)

    return {"extra_torque": extra, "extra_holding": lambda theta: c_load * abs(theta)}


def _ripple(base: Mapping, ripple_a, ripple_b, order) -> dict:
    def extra(theta, omega):
        return ripple_a * math.sin(order * theta) + ripple_b * math.cos(order * theta)

    return {"extra_torque": extra}


def _dahl(base: Mapping, f_h, sigma_h) -> dict:
    return {"dahl": (f_h, sigma_h)}


def _quadratic_drag(base: Mapping, c_2) -> dict:
    # outside the library: a drag growing with the square of the speed (churning grease)
    def extra(theta, omega):
        return -c_2 * omega * abs(omega)

    return {"extra_torque": extra}


#: name → {"library": candidate key or None, "truth": parameters, "reference": builder}
HIDDEN: dict[str, dict] = {
    # notes: free play up to ~0.03 rad at the WG; 0.02 rad is 13 counts of dead zone
    "backlash": {"library": "backlash", "truth": {"backlash": 0.02},
                 "reference": lambda base, backlash: _backlash(base, backlash)},
    # notes: hysteresis loop width ~1 arcmin output ≈ 0.03 rad WG; a Dahl element of
    # f_h = 1 mNm over k1/N² = 0.094 N m/rad makes a 0.02 rad loop, corners 0.01 rad wide
    "hysteresis": {"library": "hysteresis", "truth": {"f_h": 1.0e-3, "sigma_h": 0.1},
                   "reference": lambda base, f_h, sigma_h: _dahl(base, f_h, sigma_h)},
    # notes: asymmetry of a few % to several-fold in robot joints; 30 %
    "asymmetric_friction": {"library": "asymmetric_friction", "truth": {"asym": 0.3},
                            "reference": lambda base, asym: _asymmetric(base, asym)},
    # notes: μ 0.05 … 0.3 of the spring torque; μ = 0.1 → c_load = 0.1·k1/N²
    "load_friction": {"library": "load_friction", "truth": {"c_load": 9.4e-3},
                      "reference": lambda base, c_load: _load(base, c_load)},
    # notes: 0.1 … 1 mNm position-periodic torque; 0.5 mNm at 24 cycles/rev (motor cogging)
    "ripple": {"library": "ripple", "truth": {"ripple_a": 4.0e-4, "ripple_b": 3.0e-4, "order": 24.0},
               "reference": lambda base, ripple_a, ripple_b, order: _ripple(base, ripple_a, ripple_b, order)},
    # notes: soft wind-up, K1 < K2 < K3; a softer centre than the CSF-8 catalog (whose
    # segments a cubic follows within ~0.01 N m) so the mark is visible: K1 = 600
    "soft_windup": {"library": "soft_windup",
                    "truth": {"K1": 600.0, "K2": 1000.0, "K3": 1200.0, "T1": 0.2, "dT12": 0.55},
                    "reference": lambda base, **p: _segments(base, **p)},
    # notes: ≤ 5.8e-4 rad p-p output per rev; 2 cycles per WG rev, amplitude 2.9e-4
    "kinematic_error": {"library": "kinematic_error",
                        "truth": {"ke_a": 2.0e-4, "ke_b": 2.0e-4, "order": 2.0},
                        "reference": lambda base, ke_a, ke_b, order: _kinematic(base, ke_a, ke_b, order)},
    # outside the library: quadratic drag (churning grease); 1e-6 N m s²/rad² is 3.6 mNm
    # at 60 rad/s — at 2e-7 the base model's viscous + Stribeck terms absorbed it entirely
    "quadratic_drag": {"library": None, "truth": {"c_2": 1.0e-6},
                       "reference": lambda base, c_2: _quadratic_drag(base, c_2)},
}


def reference_kwargs(name: str, base: Mapping, **override: float) -> dict:
    """Keyword arguments for the reference simulator that hide effect ``name``."""
    entry = HIDDEN[name]
    params = {**entry["truth"], **override}
    return entry["reference"](base, **params)
