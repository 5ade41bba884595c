"""Whether the log samples its own oscillation: a swing at ``f`` needs more than two samples
a period (Nyquist, ``f < fs/2``), and the turning points a fit times need ~2.5 or more.

A log sampled slower than that still fits — the simulator runs between the samples — but
its readings alias the swing: the turning points the log shows belong to a slower false
swing, so the log's own frequency estimate (:attr:`Prepared.frequency_hz`, from those
turns) is itself below Nyquist and cannot tell; the fitted natural frequency can. NumPy
only; used by :func:`hdid._fitting._identifiability.plausibility_warnings` for encoder and
noise logs alike.
"""

from __future__ import annotations

import math

#: Fewest samples a period of the fitted swing below which the log is called aliased: 2 is
#: Nyquist itself; at 2.5 a quarter period is 0.6 samples, so no sample lies near most
#: turning points and the swing is timed by the model alone.
MIN_SAMPLES_PER_PERIOD = 2.5
#: Samples a period the warning asks for (each turning point within a tenth of a period).
ASK_SAMPLES_PER_PERIOD = 10.0


def swing_hz(linear_hz: float, values: dict, twist: float) -> float:
    """The frequency [Hz] of a swing of amplitude ``twist`` [rad at the spring] on a
    hardening spring ``k1·d + k2·d³`` whose small-swing frequency is ``linear_hz``: the
    Duffing backbone, ``f = f₀·√(1 + ¾·k2·A²/k1)`` (first harmonic balance). A cubic term
    that dominates the largest swings (a posterior draw with k2·A²/k1 ≈ 45 at 32 Hz)
    swings them at ~190 Hz: above a 250 Hz log's Nyquist frequency although ``f₀`` is not."""
    k1, k2 = values.get("k1"), values.get("k2")
    if not (k1 and k2 and k1 > 0 and k2 > 0 and math.isfinite(twist)):
        return linear_hz
    return linear_hz * math.sqrt(1.0 + 0.75 * k2 * twist**2 / k1)


def aliasing_warning(sample_period: float, fitted_hz: float, log_hz: float) -> str | None:
    """The warning for a log whose swing — the fitted one ``fitted_hz`` [Hz] (the natural
    frequency, hardened at the log's largest swing: :func:`swing_hz`), or the log's own
    turning-point frequency ``log_hz`` — has fewer than
    :data:`MIN_SAMPLES_PER_PERIOD` samples ``sample_period`` [s] apart a period; None
    otherwise (or where neither frequency is known)."""
    if not (sample_period > 0 and math.isfinite(sample_period)):
        return None
    fs = 1.0 / sample_period
    known = [f for f in (fitted_hz, log_hz) if f is not None and math.isfinite(f) and f > 0]
    if not known:
        return None
    f = max(known)
    per_period = fs / f
    if per_period >= MIN_SAMPLES_PER_PERIOD:
        return None
    where = ("above the log's Nyquist frequency" if per_period < 2.0
             else "near the log's Nyquist frequency")
    which = "fitted swing" if f == fitted_hz else "log's own swing"
    return (
        f"aliased: the {which} {f:.4g} Hz is {where} ({0.5 * fs:.4g} Hz at {fs:.4g} Hz "
        f"sampling: {per_period:.2g} samples a period): the readings do not resolve the swing, "
        "its turning points and stop are timed by the model alone, and the frequency, "
        "friction and their standard errors rest on the model's shape — sample faster (at "
        f"least {ASK_SAMPLES_PER_PERIOD * f:.3g} Hz, {ASK_SAMPLES_PER_PERIOD:g} samples a "
        "period)"
    )
