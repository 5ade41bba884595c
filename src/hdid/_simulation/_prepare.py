"""From a validated :class:`~hdid._log.Log` to padded arrays, weights and data-driven guesses.

Nothing here fits; it finds the release, the hold and the rest point of every run,
pads the runs to one length (so they can be vmapped) and builds observation weights.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._errors import LogError
from .._log import Log
from ._noise import noise_ahead, noise_sigma, print_floor
from ._search_weight import FULL_WEIGHT_TAIL, search_weight as search_weight  # (re-exported)
from ._print_rounding import print_variance
from ._timing import time_scales

#: Shortest bracket [s] allowed before the last sample at the hold reading for the
#: release instant (a release just outside the stick band starts slowly); the bracket is
#: also at least three sample periods and a quarter of the log's own oscillation period.
MAX_SILENT_START = 0.012



@dataclass(frozen=True)
class Prepared:
    """A log as fixed-shape arrays (runs × samples), plus what the data say directly.

    Attributes
    ----------
    times, theta, weight:
        ``(R, T)`` arrays; runs shorter than ``T`` are padded by repeating their last
        sample with weight 0 (zero-length intervals, so the simulation is unchanged).
    weight:
        Observation weights. On a quantized sensor a stretch of identical readings — the
        pre-release hold and the stuck tail — carries *one* observation's worth of
        information (its quantization error is the same for every sample), so its samples
        share a total weight of one: ``w = 1/sqrt(n)`` on the residual. Readings on no
        grid (analog, interpolated) carry independent noise and keep full weight, except
        a still stretch that repeats one printed level (:func:`_repeats`). The search for
        the optimum weights every stuck tail as one observation (:func:`search_weight`).
    hold, rest:
        Reading before release (a run that starts in motion: its first reading) and at
        the end of each run.
    release_lo, release_hi, release_guess:
        Bracket of the release instant per run [s]: after the last sample at the hold
        reading, before the first sample that moved. A run that starts in motion is
        "released" at its first sample (``lo == hi``) with a fitted initial velocity.
    first_moved:
        Index of the first sample that moved.
    moving_start:
        Runs that the log shows already moving at their first sample (no hold).
    ends_moving:
        Runs whose log ends before the motion stops (no stuck tail).
    resolution, resolution_known, resolution_source:
        The sensor's step in the log's units: ``"given"`` (by the user), ``"estimated"``
        (the readings lie on a grid of that step) — both ``resolution_known`` — or
        ``"noise"``: the readings lie on no grid and ``resolution = σ·√12`` from the
        noise ``σ`` estimated in the log's still stretches (or its third differences),
        so that the residual scale ``resolution/√12`` is that noise.
    frequency_hz:
        The log's own oscillation frequency [Hz] from its turning points (median over
        runs): where the start grid is centred.
    speed:
        Largest speed the log shows [units/s] (chord between samples).
    omega_guess:
        Initial velocity of each run that starts moving (one-sided three-point
        difference at its first sample, at the logged times; 0 for held runs): the
        start of its fit.
    still:
        Runs that never move (a release inside the stick band): kept as data, "released"
        at their first sample from their reading, where a model whose stick band holds
        them stays stuck (residual zero) and one whose band is narrower slides off. Their
        reading is a rest point, and it bounds the band from below.
    log_notes:
        The log's own notes (:attr:`hdid.Log.notes`: runs split at a break, runs that
        never move), for the report's warnings.
    tail_start:
        Index of the first sample of each run's final still stretch (the stuck tail).

    Times are the logged ones: the steps may vary (jitter, dropped samples), and every
    estimate here (speeds, the initial velocity, the still tail's duration) uses them;
    ``sample_period`` (the median step) is only a scale.
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
    moving_start: np.ndarray = None
    ends_moving: np.ndarray = None
    resolution_source: str = "estimated"
    frequency_hz: float = float("nan")
    speed: float = float("nan")
    omega_guess: np.ndarray = None
    #: printing precision of the readings [log units] and why no step was found in them
    #: (:attr:`hdid.Log.print_unit`, :attr:`hdid.Log.resolution_note`)
    print_unit: float | None = None
    resolution_note: str | None = None
    still: np.ndarray = None
    log_notes: tuple[str, ...] = ()
    #: index of the first sample of each run's final still stretch (its length where none)
    tail_start: np.ndarray = None
    #: ``(R, T)`` each reading's error over ``step/√12`` where the stamps are instants cut
    #: to ``time_print_unit`` [s] (:mod:`._timing`; ``weight`` divides by it), else None
    time_scale: np.ndarray = None
    time_print_unit: float | None = None
    #: RMS print error of the encoder's levels [log units] where the readings' print unit
    #: is within a few steps (:mod:`._print_rounding`; ``weight`` divides by it too), else 0
    print_rms: float = 0.0

    @property
    def n_runs(self) -> int:
        return len(self.run_names)

    @property
    def n_setups(self) -> int:
        return len(self.setup_names)

    @property
    def error_scale(self) -> np.ndarray | None:
        """``(R, T)`` each reading's error over ``step/√12``, ``√(s_t² + 12·print_rms²/step²)``
        (``s_t`` the stamps' :attr:`time_scale`), or None where both are absent."""
        extra = 12.0 * (self.print_rms / self.resolution) ** 2 if self.print_rms else 0.0
        if self.time_scale is None and not extra:
            return None
        ts = np.ones_like(self.weight) if self.time_scale is None else self.time_scale
        return np.sqrt(ts**2 + extra)

    @property
    def n_effective(self) -> float:
        """Effective number of observations, ``Σ w²`` (``w`` before :attr:`error_scale`)."""
        scale = self.error_scale
        return float(np.sum(self.weight**2 if scale is None else (self.weight * scale) ** 2))

    @property
    def floor(self) -> float:
        """The residuals' floor [log units]: ``step/√12``; with rounded stamps (:mod:`._timing`)
        or print rounding (:mod:`._print_rounding`) the weighted RMS reached there,
        ``step/√12·√(n_effective/Σw²)`` (``√(step² + 12·print_rms²)/√12`` without stamps)."""
        sigma = self.resolution / math.sqrt(12.0)
        if self.error_scale is None:
            return sigma
        return sigma * math.sqrt(self.n_effective / float(np.sum(self.weight**2)))

    @property
    def quantized(self) -> bool:
        """Whether the readings lie on a known grid (an encoder)."""
        return self.resolution_source != "noise"

    def direction(self) -> np.ndarray:
        """Initial direction of motion of each run (+1 / −1)."""
        moved = self.theta[np.arange(self.n_runs), self.first_moved]
        d = np.sign(moved - self.hold)
        return d if self.still is None else np.where(self.still, 0.0, d)


def turning_points(th: np.ndarray, threshold: float) -> list[int]:
    """Sample indices of the turning points of ``th``: where it reverses by more than
    ``threshold`` (a zig-zag filter, so quantization flicker and noise are not turns).
    The motion's first direction is set once it leaves ``th[0]`` by ``threshold``."""
    out: list[int] = []
    d, ext_i, ext_v, ref = 0, 0, th[0], th[0]
    for k in range(1, len(th)):
        v = th[k]
        if d == 0:
            if abs(v - ref) > threshold:
                d, ext_i, ext_v = (1 if v > ref else -1), k, v
            continue
        if (v - ext_v) * d > 0:
            ext_i, ext_v = k, v
        elif (ext_v - v) * d > threshold:
            out.append(ext_i)
            d, ext_i, ext_v = -d, k, v
            if len(out) >= 40:  # enough for a median; long ring-downs stay cheap
                break
    return out


def _lead_level(th: np.ndarray, still: float) -> float | None:
    """The level a run is held at from its first sample, or None where it starts moving.

    A hold is a stretch of readings within ``still`` (the flicker, or 5σ of noise) of one
    level: the first three readings agree, or the first five lie within ``still`` of their
    median — a difference of two noisy readings has √2σ, so a 3.5σ excursion of one of them
    (in most logs of ~100 held readings a run) breaks the pairwise test. One of the five
    may be a lone noise spike beyond that.
    A smooth motion cannot put one off-level reading between agreeing ones, so a spike at
    the second or third reading is one; a first reading off the others' level is a spike
    only on the side away from the motion that follows (a ring-down cut just before a
    turning point comes from the side it returns to)."""
    n = len(th)
    if n >= 3 and abs(th[1] - th[0]) <= still and abs(th[2] - th[0]) <= still:
        return float(th[0])
    if n < 5:
        return None
    mid = float(np.median(th[:5]))
    off = np.flatnonzero(np.abs(th[:5] - mid) > still)
    if off.size == 0 or (off.size == 1 and off[0] in (1, 2)):
        return mid
    if off.size == 1 and off[0] == 0:
        far = th[int(np.argmax(np.abs(th - mid)))]
        if np.sign(th[0] - mid) != np.sign(far - mid):
            return mid
    return None


def _vertex(t: np.ndarray, th: np.ndarray, i: int) -> float:
    """Time of the extremum near sample ``i`` (parabola through its neighbours)."""
    if 0 < i < len(th) - 1:
        y0, y1, y2 = th[i - 1], th[i], th[i + 1]
        den = y0 - 2 * y1 + y2
        if den != 0:
            return float(t[i] + 0.5 * (y0 - y2) / den * (t[i + 1] - t[i]))
    return float(t[i])


def prepare(log: Log, release_time: float | None = None) -> Prepared:
    """Pad the runs, find holds (or moving starts), releases and rest points, weights."""
    if getattr(log, "is_driven", False):
        raise LogError(
            f"{log.source}: this is a driven log (it has a motor torque column), not a "
            "free-motion log; fit it with hdid.fit_driven() or `hdid fit LOG` on its own, "
            "or together with a free-motion log via hdid.fit_joint() / --joint"
        )
    runs = log.runs
    if log.resolution:
        step = float(log.resolution)
        source = "given" if getattr(log, "resolution_source", None) == "given" else "estimated"
        # A grid found in the readings may be the printing precision of a noisy analog
        # sensor, not an encoder: then the still stretches wander over many levels.
        # Or noise ahead of an encoder's rounding: its still stretches jump by 2 steps or
        # more, or below that spreads a still level over its neighbours (:func:`noise_ahead`)
        # A given step (counts per revolution) is the grid, but not the readings' error:
        # noise ahead of the rounding jumps still stretches by 2 steps or more there too
        # (0.86 steps ahead of a 14-bit count log, read on its given grid: 8x the noise).
        if source == "estimated" and noise_sigma(runs, None, still_only=True) > 2.0 * step:
            step = noise_sigma(runs, None) * math.sqrt(12.0)
            source = "noise"
        elif (err := noise_ahead(runs, step)) > 0.0:  # (below step/2: the levels' spread)
            step = err * math.sqrt(12.0)  # (the readings' error, rounding included)
            source = "noise"
    else:
        # (never below the printing's own rounding, print unit/√12; that rounding itself
        # where it is the readings' resolution, :func:`print_floor`)
        printed = float(getattr(log, "print_unit", None) or 0.0)
        step = (print_floor(runs, printed) * math.sqrt(12.0)
                or max(noise_sigma(runs, None) * math.sqrt(12.0), printed))
        source = "noise"
    quantized = source != "noise"
    sigma = step / math.sqrt(12.0)
    dt = log.sample_period
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
    moving = np.zeros(R, dtype=bool)
    still_run = np.zeros(R, dtype=bool)
    omega_guess = np.zeros(R)
    ends_moving = np.zeros(R, dtype=bool)
    k0s = np.zeros(R, dtype=int)
    tail_starts = np.zeros(R, dtype=int)
    tails = np.zeros(R)  # duration of the still stretch at the end of each run [s]
    half_periods: list[float] = []
    stops: list[float] = []  # release to rest where a run shows no turn: a bound only
    # A reading that differs from its neighbour by more than this is motion (not a flicker
    # of the last digit, not noise).
    still = (1.0 * step + 3.0 * sigma) if quantized else 5.0 * sigma
    for i, run in enumerate(runs):
        n = len(run.time)
        t, th = run.time, run.theta
        times[i, :n], times[i, n:] = t, t[-1]
        theta[i, :n], theta[i, n:] = th, th[-1]
        # A hold: the first readings agree (within the flicker/noise). Otherwise the run
        # starts in motion (a ring-down, a log cut after the release) — unless the fit found
        # that its first reading is a hold, the release falling in the first interval
        # (:mod:`hdid._fitting._first_reading`).
        level = _lead_level(th, still)
        held = level is not None or run.name in log.first_reading_held
        if held:
            level = th[0] if level is None else level
            # the hold's level from its own readings: the leading stretch within the
            # flicker of its level (a short pre-trigger hold has fewer than 10 samples),
            # a lone noise spike skipped (the hold ends where the readings leave for good)
            off_lvl = np.abs(th - level) > still
            off_hold = np.flatnonzero(off_lvl & np.append(off_lvl[1:], off_lvl[-1:]))
            n_lead = int(off_hold[0]) if off_hold.size else n
            head = th[: min(max(3, min(10, n // 10)), n_lead)]
            head = head[np.abs(head - level) <= still]
            h = float(np.median(head))
            noise = 1.4826 * float(np.median(np.abs(head - h)))
            thr = max(1.5 * step, 5.0 * noise) if quantized else max(6.0 * sigma, 5.0 * noise)
            away = np.abs(th - h) > thr
            # A release moves the gear away for good; a noise spike lasts one sample.
            moved = np.flatnonzero(away & np.append(away[1:], away[-1:]))
            if moved.size == 0:  # never moves: a rest point, held from its first sample
                still_run[i] = True
                k0 = n - 1
                hold[i] = np.median(th)
            else:
                j = int(moved[0])
                at_hold = np.flatnonzero(np.abs(th[:j] - h) <= (
                    1.0 * step + 3.0 * noise if quantized else max(5.0 * sigma, 3.0 * noise)))
                k0 = int(at_hold[-1]) if at_hold.size else 0
                hold[i] = np.median(th[: k0 + 1])
        else:
            k0 = 0
            moving[i] = True
            hold[i] = th[0]
            omega_guess[i] = _first_slope(t, th)
        k0s[i] = k0
        first_moved[i] = min(k0 + 1, n - 1)
        # Rest: the final reading; the tail is the trailing stretch within the flicker of it.
        rest[i] = np.median(th[max(n - max(n // 10, 1), 0):]) if quantized else float(
            np.median(th[max(n - 5, 0):]))
        off = np.flatnonzero(np.abs(th - th[-1]) > still)
        tail_start = int(off[-1]) + 1 if off.size else n
        tail_starts[i] = tail_start
        # how long the reading has stayed put at the end, from the last sample that moved
        # ((n − tail_start)·dt at a uniform period; the logged span in general)
        tails[i] = float(t[-1] - t[off[-1]]) if off.size else 0.0
        if still_run[i]:
            tails[i] = float(t[-1] - t[0]) + dt
        w = np.ones(n)
        # (readings on no grid keep full weight, unless the printing repeats one level:
        # :func:`_repeats`)
        if still_run[i] and (quantized or _repeats(th)):  # one reading, one observation
            w[:] = 1.0 / math.sqrt(n)
        elif not still_run[i]:
            if quantized or _repeats(th[: k0 + 1]):
                w[: k0 + 1] = 1.0 / math.sqrt(k0 + 1)
            free_tail = min(tail_start + FULL_WEIGHT_TAIL, n)
            n_tail = n - free_tail
            if n_tail > 0 and (quantized or _repeats(th[tail_start:])):
                w[free_tail:] = 1.0 / math.sqrt(n_tail)
        weight[i, :n] = w
        if still_run[i]:
            continue
        # Half periods from the turning points of the moving part.
        seg = slice(k0, max(tail_start, k0 + 2))
        tp = turning_points(th[seg], max(2.0 * still, 1e-300))
        tt = [_vertex(t[seg], th[seg], int(k)) for k in tp]
        if len(tt) >= 2:
            half_periods.extend(np.diff(tt))
        elif len(tt) == 1 and not moving[i]:
            half_periods.append(tt[0] - 0.5 * (t[k0] + t[min(k0 + 1, n - 1)]))
        elif len(tt) == 1 and tail_start < n:
            # a moving start with one turn, then rest: turn to stop is a half period (a
            # Coulomb stop is a turning point), timed at the first reading at rest (a bound).
            # Without it a log cut at its first moving sample (250 Hz, 60 Hz gear: one turn
            # a run) had no frequency but its length's (0.5 Hz): the fit ran to k1 -> 0
            stops.append(max(t[min(tail_start, n - 1)] - tt[0], dt))
        elif not tt and tail_start < n:
            # reached rest without a turn: the stop (a Coulomb stop is a turning point);
            # from the first reading where the log starts after the release (a bound: the
            # release came earlier). Without it a log whose every run starts moving and
            # stops before a turn had no frequency but its length's (0.24 Hz for a 38 Hz
            # plant logged 1 s), and ~1 s stuck tails read as a pause at a turn
            stops.append(max(t[min(tail_start, n - 1)] - t[k0], dt))
    # (on an encoder the stop is the first sample at the rest count; with noise it is
    # where the noise last left the rest reading, late by up to the tail: there a stop
    # counts only where no run shows a turn — a 66 Hz log at 250 Hz read 3.7 Hz)
    hp = np.asarray([h for h in (half_periods + stops if quantized else half_periods or stops)
                     if h > 0])
    if hp.size:
        frequency = 1.0 / (2.0 * float(np.median(hp)))
    else:  # a log shorter than half a swing: at least one quarter period long
        frequency = 0.25 / max(float(np.max([r.time[-1] - r.time[0] for r in runs])), dt)
    frequency = min(frequency, 0.5 / dt * 4.0)
    silent = max(MAX_SILENT_START, 3.0 * dt, 0.25 / frequency)
    # A run has come to rest when its final still stretch lasts longer than a swing could
    # pause at a turning point (half a period) and more than three samples; otherwise the
    # log ends before the motion does (a ring-down cut short).
    ends_moving = tails < max(3.0 * dt, 0.5 / frequency)
    rest = np.where(ends_moving, [r.theta[-1] for r in runs], rest)
    if still_run.all():
        raise LogError(
            f"{log.source}: no run moves more than its readings' flicker from its first "
            "reading — nothing to fit; check that the drive was twisted and released"
        )
    for i, run in enumerate(runs):
        t = run.time
        n = len(t)
        k0 = k0s[i]
        if moving[i] or still_run[i]:
            lo[i] = hi[i] = guess[i] = t[0]
        elif release_time is not None:
            lo[i] = hi[i] = guess[i] = release_time
        else:
            lo[i] = t[k0] - silent
            hi[i] = t[min(k0 + 1, n - 1)]
            guess[i] = 0.5 * (t[k0] + t[min(k0 + 1, n - 1)])
    speeds = [np.max(np.abs(np.diff(r.theta)) / np.diff(r.time)) for r in runs if len(r.theta) > 1]
    unit = getattr(log, "time_print_unit", None)
    scale = time_scales(runs, unit, step, (R, T)) if quantized else None
    setups = np.array([log.setups.index(r.setup) for r in runs])
    # the readings' print rounding (:mod:`._print_rounding`; beside rounded stamps where it
    # moves the floor their weights reach by 1 %), and the stamps' rounding (:mod:`._timing`)
    pvar = print_variance(runs, step, getattr(log, "print_unit", None), weight,
                          setups, scale) if quantized else 0.0
    if scale is not None or pvar:
        weight = weight / np.sqrt((1.0 if scale is None else scale**2) + 12.0 * pvar / step**2)
    return Prepared(
        source=log.source,
        run_names=tuple(r.name for r in runs),
        setup_names=log.setups,
        setup_index=setups,
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
        resolution_known=quantized,
        sample_period=dt,
        moving_start=moving,
        ends_moving=ends_moving,
        resolution_source=source,
        frequency_hz=float(frequency),
        speed=float(max(speeds)) if speeds else float("nan"),
        omega_guess=omega_guess,
        print_unit=getattr(log, "print_unit", None),
        resolution_note=getattr(log, "resolution_note", None),
        still=still_run,
        log_notes=tuple(getattr(log, "notes", ())),
        tail_start=tail_starts,
        time_scale=scale,
        time_print_unit=unit if scale is not None else None,
        print_rms=math.sqrt(pvar),
    )


def _repeats(th: np.ndarray) -> bool:
    """Whether a still stretch of readings on no grid repeats one printed level (most of
    its steps are exactly 0): its noise is below the print unit, and the error of every
    reading is the same rounding of one value — one reading printed again and again, one
    observation as on an encoder, not independent noise (a 17-bit encoder printed to
    1e-4 rad: ~450 stuck samples a run counted as 450 observations put the friction's
    errors 4 sd from the truth)."""
    return th.size >= 3 and float(np.mean(np.diff(th) == 0.0)) > 0.5


def _first_slope(t: np.ndarray, th: np.ndarray) -> float:
    """Slope at the first sample [units/s]: the derivative at ``t[0]`` of the parabola
    through the first three samples at their logged times (the one-sided three-point
    difference ``(−3θ₀ + 4θ₁ − θ₂)/2h`` when the steps are equal); a chord for two."""
    if len(th) < 3:
        return float((th[1] - th[0]) / (t[1] - t[0]))
    h1, h2 = t[1] - t[0], t[2] - t[1]
    return float(-(2 * h1 + h2) / (h1 * (h1 + h2)) * th[0] + (h1 + h2) / (h1 * h2) * th[1]
                 - h1 / (h2 * (h1 + h2)) * th[2])


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
