"""From a validated :class:`~hdid._io.Log` to padded arrays, weights and data-driven guesses.

Nothing here fits; it finds the release, the hold and the rest point of every run,
pads the runs to one length (so they can be vmapped) and builds observation weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._errors import LogError
from ._io import Log

#: Encoder step assumed when the log does not reveal one: 4000 counts/rev.
DEFAULT_RESOLUTION = 2 * math.pi / 4000

#: Longest time [s] a release may precede the last sample at the hold reading.
MAX_SILENT_START = 0.012

#: Samples right after the last motion that keep full weight (they time the stop).
FULL_WEIGHT_TAIL = 3


@dataclass(frozen=True)
class Prepared:
    """A log as fixed-shape arrays (runs × samples), plus what the data say directly.

    Attributes
    ----------
    times, theta, weight:
        ``(R, T)`` arrays; runs shorter than ``T`` are padded by repeating their last
        sample with weight 0 (zero-length intervals, so the simulation is unchanged).
    weight:
        Observation weights. A stretch of identical readings — the pre-release hold and
        the stuck tail — carries *one* observation's worth of information (its
        quantization error is the same for every sample), so its samples share a total
        weight of one: ``w = 1/sqrt(n)`` on the residual.
    hold, rest:
        Encoder reading before release and at the end of each run [rad].
    release_lo, release_hi, release_guess:
        Bracket of the release instant per run [s]: after the last sample at the hold
        reading, before the first sample that moved.
    first_moved:
        Index of the first sample that moved.
    """

    source: str
    run_names: tuple[str, ...]
    setup_names: tuple[str, ...]
    setup_index: np.ndarray
    added_inertia: np.ndarray
    times: np.ndarray
    theta: np.ndarray
    weight: np.ndarray
    lengths: np.ndarray
    hold: np.ndarray
    rest: np.ndarray
    release_lo: np.ndarray
    release_hi: np.ndarray
    release_guess: np.ndarray
    first_moved: np.ndarray
    resolution: float
    resolution_known: bool
    sample_period: float

    @property
    def n_runs(self) -> int:
        return len(self.run_names)

    @property
    def n_setups(self) -> int:
        return len(self.setup_names)

    @property
    def n_effective(self) -> float:
        """Effective number of observations, ``Σ w²``."""
        return float(np.sum(self.weight**2))

    def direction(self) -> np.ndarray:
        """Initial direction of motion of each run (+1 / −1)."""
        moved = self.theta[np.arange(self.n_runs), self.first_moved]
        return np.sign(moved - self.hold)


def prepare(log: Log, release_time: float | None = None) -> Prepared:
    """Pad the runs, find holds, releases and rest points, and build weights."""
    if getattr(log, "is_driven", False):
        raise LogError(
            f"{log.source}: this is a driven log (it has a motor torque column), not a "
            "free-motion log; fit it with hdid.fit_driven() or `hdid fit LOG` on its own, "
            "or together with a free-motion log via hdid.fit_joint() / --joint"
        )
    step = log.resolution if log.resolution else DEFAULT_RESOLUTION
    dt = log.sample_period
    runs = log.runs
    T = max(len(r.time) for r in runs)
    R = len(runs)
    times = np.zeros((R, T))
    theta = np.zeros((R, T))
    weight = np.zeros((R, T))
    hold = np.zeros(R)
    rest = np.zeros(R)
    lo = np.zeros(R)
    hi = np.zeros(R)
    guess = np.zeros(R)
    first_moved = np.zeros(R, dtype=int)
    setup_names = log.setups
    for i, run in enumerate(runs):
        n = len(run.time)
        t, th = run.time, run.theta
        times[i, :n], times[i, n:] = t, t[-1]
        theta[i, :n], theta[i, n:] = th, th[-1]
        # Hold reading and its jitter from the first few samples (robust to a flickering
        # count): motion starts where the reading leaves the hold by more than both the
        # quantization and ~5 noise standard deviations.
        head = th[: max(3, min(10, n // 10))]
        h = float(np.median(head))
        noise = 1.4826 * float(np.median(np.abs(head - h)))
        away = np.abs(th - h) > max(1.5 * step, 5.0 * noise)
        # A release moves the gear away for good; a noise spike lasts one sample.
        moved = np.flatnonzero(away & np.append(away[1:], away[-1:]))
        if moved.size == 0:
            raise LogError(
                f"run {run.name!r} never moves more than one encoder step from its first "
                "reading; check that it contains the release or drop the run",
                path=log.source,
                row=run.first_row,
            )
        j = int(moved[0])
        # Readings within one count of the hold (a flickering last digit) still count as
        # held; the release lies before the first sustained departure.
        at_hold = np.flatnonzero(np.abs(th[:j] - h) <= 1.0 * step + 3.0 * noise)
        k0 = int(at_hold[-1]) if at_hold.size else 0
        first_moved[i] = k0 + 1
        hold[i] = np.median(th[: k0 + 1])
        if release_time is not None:
            lo[i] = hi[i] = guess[i] = release_time
        else:
            # A release just outside the stick band starts slowly: it can take several
            # milliseconds to move half a count, so allow it well before the last hold
            # sample (the samples in between are at the hold reading either way).
            lo[i] = t[k0] - max(MAX_SILENT_START, dt)
            hi[i] = t[k0 + 1]
            guess[i] = 0.5 * (t[k0] + t[k0 + 1])
        # Rest: the final reading; the tail is the trailing stretch within one step of it.
        rest[i] = np.median(th[max(n - max(n // 10, 1), 0):])
        off = np.flatnonzero(np.abs(th - rest[i]) > 1.0 * step)
        tail_start = int(off[-1]) + 1 if off.size else n
        w = np.ones(n)
        w[: k0 + 1] = 1.0 / math.sqrt(k0 + 1)
        free_tail = min(tail_start + FULL_WEIGHT_TAIL, n)
        n_tail = n - free_tail
        if n_tail > 0:
            w[free_tail:] = 1.0 / math.sqrt(n_tail)
        weight[i, :n] = w
    return Prepared(
        source=log.source,
        run_names=tuple(r.name for r in runs),
        setup_names=setup_names,
        setup_index=np.array([setup_names.index(r.setup) for r in runs]),
        added_inertia=np.array([r.added_inertia for r in runs], dtype=float),
        times=times,
        theta=theta,
        weight=weight,
        lengths=np.array([len(r.time) for r in runs]),
        hold=hold,
        rest=rest,
        release_lo=lo,
        release_hi=hi,
        release_guess=guess,
        first_moved=first_moved,
        resolution=step,
        resolution_known=log.resolution is not None,
        sample_period=dt,
    )


def offset_guess(prep: Prepared) -> np.ndarray:
    """Per set-up guess of the encoder reading at the spring's zero.

    With releases to both sides the midpoint of the extreme holds (symmetric designs
    like the paper's ±0.157 rad); with one side only, the mean rest point (which lies
    inside the stick band, i.e. within a few hundredths of a radian of the zero).
    """
    out = np.zeros(prep.n_setups)
    d = prep.direction()
    for s in range(prep.n_setups):
        sel = prep.setup_index == s
        if np.any(d[sel] > 0) and np.any(d[sel] < 0):
            out[s] = 0.5 * (prep.hold[sel].max() + prep.hold[sel].min())
        else:
            out[s] = prep.rest[sel].mean()
    return out
