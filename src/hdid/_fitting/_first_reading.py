"""Is a run's first reading a hold? The release instant of a logger that starts at the
servo-off.

A run whose readings move from its second or third sample on fits two stories:

* **already moving** — the log was cut after the release (a ring-down): the run starts at
  its first sample with a fitted velocity (:class:`hdid._simulation._prepare.Prepared`,
  ``moving_start``);
* **its first reading is the hold** — the logger started at the servo-off and the gear was
  released during the first interval(s): the run is held at its first reading until a
  release instant fitted between the last held and the first moved sample, from rest.

Both give each run one unknown (its velocity, or its release instant), so the likelihood
decides: both are fitted in full (:func:`hdid.fit`, starts, restarts and limit checks) and
the smaller χ² is kept. Only the second describes a release during the first interval —
the first must put a turning point of the free motion on the first reading — and only the
first a log cut in mid-swing; at 250 Hz a 60 Hz spring moves a tenth of its swing in a
millisecond, so the wrong story costs thousands of χ² units, not a few. A release from
rest is the run's farthest point from the spring's zero (friction only takes energy out),
so the held story is tried only for runs whose first reading is their largest or smallest;
it is tried for all such runs together (one story for the logger).
"""

from __future__ import annotations

import numpy as np

#: A first reading within this many sensor steps of its run's largest (smallest) reading
#: counts as the run's extreme: the readings' own rounding.
EXTREME_STEPS = 2.0
#: What the held story's warning says (and callers find it by).
NOTE_MARK = "first reading is taken as the hold"


def candidates(log, prep, release_time) -> tuple[str, ...]:
    """Runs of ``prep`` that start moving and whose first reading is their run's largest or
    smallest (within ``EXTREME_STEPS`` sensor steps): the held story is worth a fit. None
    when the log already carries that story, or a release instant is given."""
    if (getattr(log, "first_reading_held", ()) or release_time is not None
            or prep.moving_start is None):
        return ()
    tol = EXTREME_STEPS * float(prep.resolution)
    out = []
    for i, name in enumerate(prep.run_names):
        n = int(prep.lengths[i])
        if not prep.moving_start[i] or n < 3:
            continue
        th = np.asarray(prep.theta[i, :n], dtype=float)
        if th[0] >= th.max() - tol or th[0] <= th.min() + tol:
            out.append(name)
    return tuple(out)


def chi2(result) -> float:
    """The data's weighted sum of squares of ``result`` [rad²] (RMS² × Σw²)."""
    return float(result.rms_residual_rad) ** 2 * float(result.n_effective)


def choose(moving, held, names: tuple[str, ...]):
    """The fit of the story with the smaller χ²; the held one says so in its warnings."""
    a, b = chi2(moving), chi2(held)
    if not b < a:
        return moving
    floor2 = float(held.quantization_floor_rad) ** 2
    held.warnings.insert(0, (
        f"run(s) {', '.join(names)} move from their first samples: their {NOTE_MARK}, "
        f"the release falling in the first interval (χ² {b / floor2:.4g} "
        f"in quantization-floor units, against {a / floor2:.4g} for runs already moving at "
        "their first sample)"))
    held.first_reading_held = tuple(names)
    return held

