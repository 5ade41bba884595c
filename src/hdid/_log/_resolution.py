"""The encoder step, estimated from the reading levels of a log."""

from __future__ import annotations

import math

import numpy as np


# ------------------------------------------------------------------ resolution


#: Largest divisor of the smallest gap between reading levels tried as the step.
MAX_STEP_DIVISOR = 64


def estimate_resolution(theta: np.ndarray, *, rtol: float = 1e-6) -> float | None:
    """Estimate the quantization step of a quantized signal.

    The distinct levels of `theta` are sorted; the step ``q`` is the largest divisor
    ``g/k`` (``k`` = 1 … ``MAX_STEP_DIVISOR``) of the smallest gap ``g`` between adjacent
    levels of which every gap is an integer multiple within ``rtol`` per step. Only differences of
    values are used, so a constant offset (``offset + k*q``) does not matter.
    The returned step is refined as (highest - lowest level) / (number of steps).

    Parameters
    ----------
    theta : numpy.ndarray
        Signal samples (any shape; non-finite values are ignored).
    rtol : float, default 1e-6
        Tolerance on each gap, as a fraction of the step. The default accepts
        values computed in floating point; raise it (e.g. to 1e-3) for values
        printed with few decimals.

    Returns
    -------
    float or None
        The step, or ``None`` when the signal does not look quantized (gaps not
        commensurate, fewer than two distinct levels, or two levels from only
        two samples).

    Examples
    --------
    >>> q = 2 * np.pi / 4000
    >>> round(estimate_resolution(0.3 + q * np.array([0, 1, 1, 3, 2, 7])) / q, 9)
    1.0
    """
    x = np.asarray(theta, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    if x.size < 2:
        return None
    values = np.unique(x)
    # Merge levels that differ only by floating-point rounding.
    merge_below = 1e-9 * max(float(np.max(np.abs(values))), np.finfo(float).tiny)
    gaps = np.diff(values)
    levels = values[np.concatenate(([True], gaps > merge_below))]
    if levels.size < 2 or (levels.size == 2 and x.size < 3):
        return None
    gaps = np.diff(levels)
    # The step is the greatest common divisor of the gaps: the smallest gap divided by
    # 1, 2, … (a short 250 Hz run may show levels 4, 13 and 25 counts apart but never two
    # adjacent counts). Readings on no grid fail every divisor: with many gaps the chance
    # that all lie within rtol of integers is nil.
    g0 = float(gaps.min())
    for k in range(1, MAX_STEP_DIVISOR + 1):
        q0 = g0 / k
        steps = np.rint(gaps / q0)
        if np.all(np.abs(gaps / q0 - steps) <= rtol * np.maximum(steps, 1.0)):
            q = float((levels[-1] - levels[0]) / steps.sum())
            return q if q > 0 and math.isfinite(q) else None
    return None
