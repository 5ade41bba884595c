"""The RK4 substep's phase error, against what a log measures of the swing's frequency.

Classical RK4 on a linear oscillator ``θ̈ = −ω²θ`` with step ``h`` multiplies the state by
``R(iθ)``, ``θ = h·ω``, each step: ``arg R = θ − θ⁵/120 + O(θ⁷)``. The simulated swing runs
slow by ``(h·ω)⁴/120`` of its frequency, and a fit takes that up in the stiffness: the
fitted frequency comes out high by the same share and ``k1`` (∝ ω²) by ``(h·ω)⁴/60``. The
substep rule keeps ``h·ω ≲ 0.26`` (:func:`hdid._fitting._substep.substep_for`): up to
3.8e-5 of the frequency, 7.6e-5 of ``k1`` — far below what a 4000-count encoder measures,
but ahead of it on 2^18–2^20 counts, where the frequency is measured to parts per million
(world logs 04/05/11/14: ``k1`` +9 … +48 ppm at 4–10 of its standard errors, the RMS at
the floor; the bias predicted from each fit's substep and swing, 9–53 ppm, matches them;
simulating the truth at the fit's substep against 1/16 of it: +10 and +21 ppm for logs 05
and 04). Measured here, not modelled: no correction of the fitted values, a warning
(:func:`hdid._fitting._plausibility.integrator_warning`) and the substep that would make
the bias a small share of the error.
"""

from __future__ import annotations

import math

#: The bias a fit may carry, as a share of its frequency's standard error, before the
#: warning: 0.5 sd moves a 95 % interval's coverage to 92 %.
BIAS_SHARE = 0.5
#: The substep suggested is the longest power-of-two division of the fit's own that
#: brings the bias to this share of the standard error or below.
TARGET_SHARE = 0.2


def frequency_bias(substep: float, frequency_hz: float) -> float:
    """Relative amount by which an RK4 simulation at ``substep`` [s] runs a swing of
    ``frequency_hz`` slow (the fitted frequency's bias, high): ``(h·ω)⁴/120``."""
    theta = 2.0 * math.pi * frequency_hz * substep
    return theta**4 / 120.0


def substep_for_error(substep: float, frequency_hz: float, rel_std: float,
                      share: float = TARGET_SHARE) -> float:
    """The longest ``substep / 2^m`` (m ≥ 0) whose :func:`frequency_bias` is at most
    ``share`` of the relative standard error ``rel_std`` of the fitted frequency."""
    h = substep
    for _ in range(12):
        if frequency_bias(h, frequency_hz) <= share * rel_std:
            break
        h *= 0.5
    return h
