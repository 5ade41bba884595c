"""The time column's rounding as angle noise: what a reading's printed instant costs.

A logger that prints each sample's instant cut to a print unit ``u`` (whole milliseconds,
microseconds) puts every reading at a time off its true instant by ``δ``, uniform on
``±u/2`` where the instants do not fall on the print grid. A reading taken at speed ``ω``
is then compared with the model at the wrong instant: its error is ``ω·δ``, variance
``ω²u²/12``, on top of the encoder's rounding ``step²/12``. On a fine encoder this is far
larger than the step (2^20 counts, 36 rad/s, stamps to 1 µs: 6× the step's rounding at
the peak speed) and it is largest exactly where the readings time the swing, so a fit that
weights every reading by the step alone is at once above its floor and overconfident
(world log 21: k1 2.4e-5 off at 21.9 of its standard errors, 2.54× the floor, no warning).

Where the instants do fall on the print grid — a uniform clock whose period is a whole
number of print units, every step of a run the same — the stamps are exact (a shared
offset is the release instant's) and nothing is added. Jitter that the stamps themselves
show is the real timing, not an error; jitter a logger hides behind nominal stamps cannot
be seen in the log and is not modelled.

Each reading's variance becomes ``σ_i² = step²/12·(1 + (ω_i u / step)²)``, with ``ω_i`` the
readings' own speed (central differences at the logged instants): the weight on its
residual is divided by ``s_i = σ_i / (step/√12)`` (:func:`time_scale`), the weighted
least-squares weight for independent errors of known variance.
"""

from __future__ import annotations

import numpy as np

#: Stamps of a run whose steps differ by more than this many print units from their median
#: are instants cut to the print unit (jitter, or a period that is no whole number of
#: units); steps that agree this well are a uniform clock on the print grid (exact).
UNEVEN_STEPS = 0.5
#: Largest ``s_i − 1`` at which the stamps' rounding is left out: ``s_i`` within 1 % of 1
#: at every reading changes no reading's variance by more than 2 %.
NEGLIGIBLE_TIMING = 0.01


def stamps_rounded(times: list[np.ndarray], unit: float | None) -> bool:
    """Whether any run's stamps are instants rounded to ``unit`` [s] (not a uniform clock
    on the print grid): its steps spread by more than :data:`UNEVEN_STEPS` units."""
    if not unit or not np.isfinite(unit) or unit <= 0:
        return False
    for t in times:
        d = np.diff(np.asarray(t, dtype=float))
        if d.size >= 2 and float(np.max(np.abs(d - np.median(d)))) > UNEVEN_STEPS * unit:
            return True
    return False


def time_scale(t: np.ndarray, theta: np.ndarray, unit: float, step: float) -> np.ndarray:
    """``s_i = √(1 + (ω_i·unit/step)²)`` per reading of one run: its error's standard
    deviation over the encoder step's rounding ``step/√12`` when its instant is printed to
    ``unit`` [s] (``ω_i``: central differences of the readings at the logged times,
    one-sided at the ends)."""
    t = np.asarray(t, dtype=float)
    theta = np.asarray(theta, dtype=float)
    if t.size < 2 or not step > 0:
        return np.ones(t.size)
    omega = np.gradient(theta, t)
    return np.sqrt(1.0 + (omega * unit / step) ** 2)


def time_scales(runs, unit: float | None, step: float, shape: tuple[int, int]
                ) -> np.ndarray | None:
    """``(R, T)`` :func:`time_scale` of every run's readings (1 in the padding) where the
    stamps are rounded instants (:func:`stamps_rounded`) and the rounding is not negligible
    (:data:`NEGLIGIBLE_TIMING`: real logs stamped to 1 µs add 2e-5 of the step's variance);
    else None. ``runs``: the log's runs (``time`` [s], ``theta``)."""
    if not stamps_rounded([r.time for r in runs], unit):
        return None
    scale = np.ones(shape)
    for i, run in enumerate(runs):
        scale[i, : len(run.time)] = time_scale(run.time, run.theta, unit, step)
    return scale if float(np.max(scale)) >= 1.0 + NEGLIGIBLE_TIMING else None
