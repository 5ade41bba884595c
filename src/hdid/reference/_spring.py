"""The reference's spring: its torque at the wave generator and the stick band it makes with
the static friction (closed form, numpy only)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
from scipy.optimize import brentq


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
