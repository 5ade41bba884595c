"""One-sample read dropouts: a reading that jumps far away and straight back.

A bus servo (Feetech STS3215, read over a half-duplex serial bus) sometimes answers one
position request with garbage — −π on that bench — and the next sample is fine again. No
mechanism moves a gear there and back within one sample period, so such a sample is no
reading of the angle; fitted, one −π among readings near −1 rad is a residual of 2 rad,
thousands of encoder steps, and it would also pull the encoder grid (its distance to the
other levels is no multiple of the step when the logger writes −π itself).

Within one run, sample ``k`` (``0 < k < n − 1``) is a dropout when

- it is more than ``J`` from *both* neighbours, ``|θ_k − θ_{k±1}| > J``, while
- the neighbours agree with each other, ``|θ_{k+1} − θ_{k−1}| ≤ J/4``, and
- it is more than ``J`` from what the neighbours' curvature allows: its distance ``e_k``
  from the straight line through them, at its own time, exceeds ``J`` as well,

with ``J = SPIKE_FACTOR × S`` and ``S`` the largest one-sample change that the run shows
anywhere else: its largest ``|Δθ|`` among the steps that touch no *lone* spike-shaped
sample (one whose distance from both neighbours is several times their distance from
each other, while the neighbours themselves are not so shaped), and at least the log's
finest nonzero change (about the encoder step: a one-step flicker of a still run is no
dropout). Why this never fires on a real motion: a
smooth angle sampled at ``Δt`` moves at most ``S`` per sample and turns around within it,
so a sample between two neighbours deviates from their line by at most the largest
change between neighbours, ``≤ S`` (a turnaround of a fast release, ~20 encoder steps
per sample on a 250 Hz harmonic-drive log, gives ``e_k ≈ |Δθ| ≤ S``: ten times short of
``J``). A log that really does alternate (an oscillation sampled near two samples per
period, an encoder flickering between two counts) makes whole stretches spike-shaped, not
lone samples: its steps set ``S``; and where lone spike shapes touch half or more of the
:data:`LOCAL_STEPS` steps either side of a sample (a ring at three samples per period has
one at every turnaround), they are that stretch's motion, and all its steps count in ``S``
there; and a value the run comes back to within :data:`LOCAL_STEPS` samples (to within
half the spike's height: a ring's next turnaround) is motion, never a dropout. So a run
never calls its own motion a spike (two dropouts within ten samples that read the same
garbage are left in: each revisits the other). A spike that
is less than ten times any change the run shows is left in the data (the fit sees it as a
residual).

More than :data:`MAX_DROPOUT_FRACTION` of a run's rows as dropouts is no bus glitch: the
log is refused with the fix.
"""

from __future__ import annotations

import numpy as np

from ._table import _show

#: A dropout lies this many times the run's largest physical one-sample change away.
SPIKE_FACTOR = 10.0
#: The neighbours of a dropout agree within this fraction of ``J``.
NEIGHBOUR_FRACTION = 0.25
#: A sample is spike-shaped (its steps are left out of ``S``) when it is this many times
#: farther from both neighbours than they are from each other.
SPIKE_SHAPE = 4.0
#: Steps either side of a sample that tell whether spike shapes are its run's motion.
LOCAL_STEPS = 10
#: Largest fraction of a run's rows that may be read dropouts.
MAX_DROPOUT_FRACTION = 0.01


def _run_dropouts(t: np.ndarray, x: np.ndarray, finest: float) -> np.ndarray:
    """Positions (within the run) of its one-sample dropouts; ``finest`` is the log's
    smallest nonzero one-sample change (about the encoder step)."""
    n = x.size
    if n < 4 or not finest > 0:
        return np.zeros(0, dtype=np.int64)
    step = np.abs(np.diff(x))
    left, right = step[:-1], step[1:]  # |x_k − x_{k−1}|, |x_{k+1} − x_k|, k = 1 … n−2
    across = np.abs(x[2:] - x[:-2])
    near = np.minimum(left, right)
    shaped = near > SPIKE_SHAPE * across
    # a lone spike-shaped sample (its neighbours are not): an alternating motion makes
    # every sample of a stretch spike-shaped, and its steps stay in S
    padded = np.concatenate(([False], shaped, [False]))
    lone = shaped & ~padded[:-2] & ~padded[2:]
    touched = np.zeros(step.size, dtype=bool)  # steps touching a lone spike-shaped sample
    touched[:-1] |= lone
    touched[1:] |= lone
    clean = step[~touched]
    s = np.full(n - 2, max(float(clean.max()) if clean.size else 0.0, finest))
    # where lone spikes are most of the steps around a sample (a ring at three samples
    # per period puts one at every turnaround), they are the motion: all steps count
    w = LOCAL_STEPS
    kernel = np.ones(2 * w)
    frac = np.convolve(touched.astype(float), kernel, "full")[w : w + n - 2]
    count = np.convolve(np.ones(step.size), kernel, "full")[w : w + n - 2]
    busy = frac >= 0.5 * count
    if busy.any():
        local = np.lib.stride_tricks.sliding_window_view(
            np.concatenate((np.zeros(w - 1), step, np.zeros(w - 1))), 2 * w
        ).max(axis=1)
        s = np.where(busy, np.maximum(s, local[: n - 2]), s)
    j = SPIKE_FACTOR * s
    # distance from the neighbours' line at the sample's own time (jittered clocks)
    w = (t[1:-1] - t[:-2]) / (t[2:] - t[:-2])
    e = np.abs(x[1:-1] - (x[:-2] + w * (x[2:] - x[:-2])))
    hit = (near > j) & (across <= NEIGHBOUR_FRACTION * j) & (e > j)
    found = []
    for k in np.flatnonzero(hit) + 1:  # a value the run comes back to is its motion
        around = np.concatenate((x[max(k - LOCAL_STEPS, 0) : k], x[k + 1 : k + 1 + LOCAL_STEPS]))
        if np.min(np.abs(around - x[k])) > 0.5 * near[k - 1]:
            found.append(k)
    return np.asarray(found, dtype=np.int64)


def find_dropouts(time, theta, starts, ends, names, lines, fail, unit_name: str = "rad"):
    """Rows (positions in the arrays) that are one-sample read dropouts, and one note per
    dropout for the report.

    ``starts``/``ends`` bound the runs, ``lines`` are the CSV line numbers, ``fail`` builds
    the :class:`~hdid.LogError` raised when more than :data:`MAX_DROPOUT_FRACTION` of a
    run's rows are dropouts."""
    rows: list[int] = []
    notes: list[str] = []
    within = np.ones(max(theta.size - 1, 0), dtype=bool)
    within[np.asarray(ends, dtype=np.int64)[:-1] - 1] = False  # no step across two runs
    moves = np.abs(np.diff(theta))[within]
    moves = moves[moves > 0]
    finest = float(moves.min()) if moves.size else 0.0
    for a, b, name in zip(starts, ends, names):
        a, b = int(a), int(b)
        found = _run_dropouts(time[a:b], theta[a:b], finest)
        if found.size == 0:
            continue
        if found.size > MAX_DROPOUT_FRACTION * (b - a):
            first = a + int(found[0])
            raise fail(
                f"run {_show(name)} has {found.size} one-sample read dropouts in {b - a} rows "
                f"(more than {MAX_DROPOUT_FRACTION:.0%}; this is the first) — the angle "
                "readings are unreliable: check the encoder/bus connection, or remove those "
                "rows if they are known glitches",
                "theta", first,
            )
        for k in found:
            i = a + int(k)
            far = min(abs(theta[i] - theta[i - 1]), abs(theta[i] - theta[i + 1]))
            rows.append(i)
            notes.append(
                f"run {_show(name)}: row {int(lines[i])} (t = {time[i]:.6g} s) reads "
                f"{theta[i]:.6f} {unit_name}, {far:.3g} {unit_name} from both neighbours "
                "(which agree): a read dropout, dropped"
            )
    return np.asarray(rows, dtype=np.int64), notes
