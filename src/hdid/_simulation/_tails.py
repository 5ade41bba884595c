"""Whether a run's final still stretch is a stop or the ring-down going on under the noise.

A gear held by dry friction stops: its last readings scatter about one rest reading, the
sensor's noise alone. A viscously damped ring-down never stops: it decays geometrically,
and once its swing falls under the still threshold (:func:`hdid._simulation._prepare.prepare`:
5 σ of the noise) the trailing readings still trace the damped oscillation at the log's
frequency (the Silverbox's analog ring-downs: 6–30 trailing samples a run swing 2–5 σ
about the rest, a sinusoid at 68 Hz leaves 0.1–0.8 σ). Such a tail is motion, not one
observation of a rest point, and keeps its full weight in the search
(:func:`hdid._simulation._prepare.search_weight`).
"""

from __future__ import annotations

import math

import numpy as np
from scipy import special

#: False-alarm probability of the oscillation test on a tail of pure noise: a stuck tail
#: is read as moving (and searched at full weight, as the likelihood weighs it) in one
#: run of a thousand.
FALSE_ALARM = 1e-3


def oscillates(t: np.ndarray, th: np.ndarray, frequency_hz: float) -> bool:
    """Whether the readings ``th`` [log units] at times ``t`` [s] continue an oscillation
    at ``frequency_hz`` (or a creep) rather than scatter about one rest reading.

    Nested least squares: a constant (the rest point) against a constant, a linear trend
    and a sinusoid at the log's frequency (a damped oscillation over a few periods, the
    drift of its centre). Under noise alone about a rest point the F statistic of the
    three added terms follows F(3, n − 4) whatever the noise's size, so the test needs no
    noise estimate; the tail oscillates where its tail probability is below
    :data:`FALSE_ALARM`. Five readings at least (one degree of freedom left), else False.
    """
    t = np.asarray(t, dtype=float)
    th = np.asarray(th, dtype=float)
    n = th.size
    if n < 5 or not math.isfinite(frequency_hz) or frequency_hz <= 0:
        return False
    x = t - t.mean()
    span = float(np.ptp(x)) or 1.0
    w = 2.0 * math.pi * frequency_hz
    A = np.column_stack([np.ones(n), x / span, np.cos(w * x), np.sin(w * x)])
    r0 = th - th.mean()
    rss0 = float(r0 @ r0)
    coef, *_ = np.linalg.lstsq(A, th, rcond=None)
    r1 = th - A @ coef
    rss1 = float(r1 @ r1)
    if rss0 <= 0.0:  # one reading repeated: a stop
        return False
    if rss1 <= 1e-12 * rss0:  # the trend and sinusoid explain the tail exactly
        return True
    F = ((rss0 - rss1) / 3.0) / (rss1 / (n - 4))
    return bool(special.fdtrc(3, n - 4, F) < FALSE_ALARM)  # F(3, n-4) upper tail
