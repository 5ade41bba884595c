"""The checks of a log's rows once its cells are numbers: runs contiguous, labels constant
within a run, time increasing, runs long enough, motion in some run; the sample period
(median step) and the breaks at which a run is split. Each check raises the
:class:`~hdid.LogError` that names the row and the fix (``fail(message, column_key,
position)`` builds it)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pandas as pd

from .._errors import LogError
from ._columns import _first
from ._names import _INERTIA, _MIN_MOTION_UNQUANTIZED, _RUN, _SETUP, _THETA, _TIME
from ._table import _show
from ._unreleased import unreleased_runs

Fail = Callable[..., LogError]


def run_blocks(run_labels: np.ndarray | None, n: int, fail: Fail) -> tuple[np.ndarray, list[str]]:
    """First row of every run and its name; a run label that comes back after other runs
    is an error (the rows of a run must be contiguous)."""
    if run_labels is None:
        return np.array([0], dtype=np.int64), ["1"]
    change = np.flatnonzero(run_labels[1:] != run_labels[:-1]) + 1
    starts = np.concatenate(([0], change)).astype(np.int64)
    block_labels = run_labels[starts]
    codes, uniques = pd.factorize(pd.Series(block_labels, dtype=object))
    if len(uniques) != len(block_labels):
        seen = np.zeros(len(uniques), dtype=bool)
        for b, c in enumerate(codes):
            if seen[c]:
                raise fail(
                    f"run {_show(block_labels[b])} appears again after other runs — the rows "
                    "of a run must be contiguous; sort the rows by run or relabel this block",
                    _RUN,
                    int(starts[b]),
                )
            seen[c] = True
    return starts, [str(v) for v in block_labels]


def _changes_within(values, within, text: Callable[[int], str], key: str, order: int, fail):
    """``(row, order, error)`` for the first row where ``values`` change inside a run."""
    pos = _first((values[1:] != values[:-1]) & within)
    return None if pos is None else (pos + 1, order, fail(text(pos), key, pos + 1))


def check_within_runs(setups, inertia, time, within, fail: Fail) -> None:
    """Set-up and added inertia constant within a run, time strictly increasing; the first
    offending row is reported (ties: set-up, then inertia, then time)."""
    problems = []
    if setups is not None:
        problems.append(_changes_within(
            setups, within, lambda p: (
                f"setup changes from {_show(setups[p])} to {_show(setups[p + 1])} within one "
                "run — a run must have one setup; check the labels or add a 'run' column"),
            _SETUP, 0, fail))
    if inertia is not None:
        problems.append(_changes_within(
            inertia, within, lambda p: (
                f"added inertia changes from {inertia[p]:.6g} to {inertia[p + 1]:.6g} within "
                "one run — it must be constant within a run"),
            _INERTIA, 1, fail))
    steps = np.diff(time)
    pos = _first((steps <= 0) & within)
    if pos is not None:
        if steps[pos] == 0:
            msg = (f"time {time[pos + 1]:.9g} repeats the row above with different readings — "
                   "two samples at one instant (no fixed rate explains the run's stamps): drop "
                   "the wrong one, or log time with more digits")
        else:
            msg = (
                f"time {time[pos + 1]:.9g} is not after the previous {time[pos]:.9g} — time must "
                "increase strictly within a run; sort the rows, or give the rows from here a "
                "'run' label of their own if a new release starts here"
            )
        problems.append((pos + 1, 2, fail(msg, _TIME, pos + 1)))
    problems = [p for p in problems if p is not None]
    if problems:
        raise min(problems, key=lambda p: p[:2])[2]


def check_lengths(lengths, starts, names, min_samples: int, has_run_column: bool, fail: Fail):
    short = _first(lengths < min_samples)
    if short is not None:
        raise fail(
            f"run {_show(names[short])} has only {int(lengths[short])} sample(s), at least "
            f"{min_samples} are needed — drop the run or log it longer",
            _RUN if has_run_column else None,
            int(starts[short]),
        )


#: A time step longer than this many of its run's median steps is a break (the logger
#: stopped). Loggers jitter by up to about ±50 % of their period (raw servo logs: 3.4–5.9
#: ms around 4.5 ms) and drop one to three samples at a time (a late bus cycle: steps of
#: 2–4 periods); the simulator integrates across any such step at the logged times
#: (substeps of at most 0.5 ms), so they are data. A pause of five periods or more is no
#: timing artefact: the test may have been touched meanwhile, so a run is split there
#: when it moves on both sides (the samples after it start a run of their own, with its
#: own start angle and velocity, rather than being predicted across the pause). Where
#: the gear is at rest on one side (a hold that lasted through the pause, a stuck tail)
#: nothing can have happened unseen that the run itself does not show: it stays whole.
BREAK_PERIODS = 5.0


def sample_period(time, within, fail: Fail) -> float:
    """The log's sample period: the median time step within runs [s] (the scale of the
    fit's rates; every interval is simulated at its logged length)."""
    steps = np.diff(time)
    period = float(np.median(steps[within])) if np.any(within) else math.nan
    if not (math.isfinite(period) and period > 0):
        raise fail("time values are too large to take differences — write time in seconds", _TIME)
    return period


def _at_rest(theta: np.ndarray, finest: float) -> bool:
    """Whether a stretch of readings stays put: within one of the finest changes its run
    shows (an encoder's flicker of one step; exact repeats for readings on no grid)."""
    return bool(np.ptp(theta) <= 1.5 * finest) if theta.size else True


def _long_pieces(cut: list[int], n: int, min_samples: int) -> list[int]:
    """The cuts left when no piece of ``[0, n)`` is shorter than ``min_samples``: a short
    piece joins the one before it (the first, the one after)."""
    cut = list(cut)
    while cut:
        edges = [0] + cut + [n]
        short = [k for k in range(len(edges) - 1) if edges[k + 1] - edges[k] < min_samples]
        if not short:
            break
        k = short[0]
        del cut[k - 1 if k > 0 else 0]
    return cut


def split_at_breaks(time, theta, starts, ends, names, min_samples: int):
    """Split runs at their breaks: steps longer than :data:`BREAK_PERIODS` of the run's
    median step, where the gear moves on both sides. Returns ``(starts, ends, names,
    notes)``: the pieces (the first keeps the run's name, the next are ``name.2``,
    ``name.3``, …; none shorter than ``min_samples``: a short one stays joined to its
    neighbour) and one line per split run for the report."""
    out_s, out_e, out_n, notes = [], [], [], []
    taken = set(names)
    for a, b, name in zip(starts, ends, names):
        steps = np.diff(time[a:b])
        median = float(np.median(steps)) if steps.size else 0.0
        long_steps = np.flatnonzero(steps > BREAK_PERIODS * median) if median > 0 else []
        cut = [int(c) + 1 for c in long_steps]
        if cut:
            moves = np.abs(np.diff(theta[a:b]))
            finest = float(np.min(moves[moves > 0])) if np.any(moves > 0) else 0.0
            # keep a break only between two stretches that both move
            edges = [0] + cut + [b - a]
            keep = []
            for k, c in enumerate(cut):
                before = theta[a + edges[k] : a + c]
                after = theta[a + c : a + edges[k + 2]]
                if not (_at_rest(before, finest) or _at_rest(after, finest)):
                    keep.append(c)
                else:  # merged: the next stretch starts where this one did
                    edges[k + 1] = edges[k]
            cut = keep
        # a piece too short to fit on its own stays with its neighbour (across the break)
        cut = _long_pieces(cut, b - a, min_samples)
        if not cut:
            out_s.append(a), out_e.append(b), out_n.append(name)
            continue
        edges = [a] + [a + c for c in cut] + [b]
        pieces = [name]
        for k in range(1, len(edges) - 1):
            piece = f"{name}.{k + 1}"
            while piece in taken:
                piece += "'"
            taken.add(piece)
            pieces.append(piece)
        out_s += edges[:-1]
        out_e += edges[1:]
        out_n += pieces
        gaps = ", ".join(f"{time[a + c] - time[a + c - 1]:.3g} s at t = {time[a + c]:.6g} s"
                         for c in cut)
        notes.append(
            f"run {_show(name)} has {len(cut)} break(s) in its time column ({gaps}; more "
            f"than {BREAK_PERIODS:g}× its median step {median:.3g} s, in motion): split "
            f"into {', '.join(map(_show, pieces))}, each with its own start")
    return (np.asarray(out_s, dtype=np.int64), np.asarray(out_e, dtype=np.int64), out_n,
            notes)


def still_runs(theta, starts, ends, names, resolution: float | None) -> list[int]:
    """Runs that never move: their readings span less than 2 encoder steps (or 1e-9 rad
    with no known step). Such a run is data (a release inside the stick band: its
    reading is a rest point); only a log in which every run is still is an error."""
    spans = np.array([np.ptp(theta[a:b]) for a, b in zip(starts, ends)])
    if resolution is not None:
        still = spans < (2.0 - 1e-6) * resolution
    else:
        still = spans < _MIN_MOTION_UNQUANTIZED
    return [int(r) for r in np.flatnonzero(still)]


def check_motion(theta, starts, ends, names, resolution: float | None, fail: Fail,
                 setups=None) -> tuple[list[str], list[int]]:
    """At least one run moves (a log of still runs has nothing to fit). Returns ``(notes,
    left_out)``: a run that never moves is kept as a rest point and named in a note, unless
    it is held beyond a turning point a moving run of its set-up (``setups``: one label per
    run) slid on from — a run never released, left out (its index in ``left_out``) and
    named with the turning point that rules it out (:mod:`._unreleased`)."""
    still = still_runs(theta, starts, ends, names, resolution)
    why = (f"less than 2 encoder steps of {resolution:.6g} rad" if resolution is not None
           else f"less than {_MIN_MOTION_UNQUANTIZED:g} rad")
    if len(still) == len(starts):
        raise fail(
            f"no run shows motion (each spans {why}) — nothing to fit; check that the drive "
            "was twisted and released, and that theta is the encoder's angle",
            _THETA,
            int(starts[0]),
        )
    if not still:
        return [], []
    left_out, notes = unreleased_runs(theta, starts, ends, names,
                                      setups if setups is not None else ["1"] * len(starts),
                                      still, resolution)
    kept = [r for r in still if r not in left_out]
    if kept:
        label = ", ".join(_show(names[r]) for r in kept)
        notes.append(f"run(s) {label} never move ({why}): kept as rest points inside the "
                     "stick band (released from inside it, they stay stuck)")
    return notes, left_out


def _held_level(held: np.ndarray) -> float | None:
    """The reading a run is held at before its release: its first, repeated at once, or
    (noise ahead of the rounding flickers the first readings) the reading that 3 of its
    first 5 show; ``None`` for a run already moving at its first reading."""
    if held.size < 3:
        return None
    if held[1] == held[0]:
        return float(held[0])
    values, counts = np.unique(held[:5], return_counts=True)
    return float(values[np.argmax(counts)]) if counts.max() >= 3 else None


def check_shared_zero(theta, rows, names, setups, fail: Fail) -> None:
    """Runs of one set-up share the encoder's zero (the fit gives each set-up one offset).
    Two of its runs held at the very same reading that move off it in opposite directions
    contradict that: from one held angle the spring (or gravity) pushes one way. That is
    the signature of a counter zeroed at each release (every run starts at 0); it is an
    error naming both runs, with the fix, rather than a fit of one spring to two zeros.
    ``rows`` holds each run's row positions (read dropouts already left out).

    A run's direction is the side its readings swing to: released from a held angle, a
    damped swing never comes back beyond it (it has less energy at every later turn), so
    readings on the far side are the sensor's noise alone. The first reading off the held
    level is not the direction: 0.3 steps of noise ahead of an encoder's rounding flicker
    the held level by one count either way before the release. A run whose far side
    reaches more than half its swing (a run that never leaves its noise) tells no
    direction."""
    first_move: dict[tuple[str, float], tuple[int, float]] = {}
    for k, run_rows in enumerate(rows):
        held = theta[run_rows]
        level = _held_level(held)
        if level is None:
            continue  # a run already moving at its first reading says nothing here
        up, down = float(np.max(held - level)), float(np.max(level - held))
        if max(up, down) <= 0.0 or min(up, down) > 0.5 * max(up, down):
            continue  # never moves (a rest point in the stick band), or moves within noise
        direction = 1.0 if up > down else -1.0
        setup = "1" if setups is None else str(setups[run_rows[0]])
        key = (setup, level)
        if key in first_move and first_move[key][1] != direction:
            other = first_move[key][0]
            raise fail(
                f"runs {_show(names[other])} and {_show(names[k])} of set-up {_show(setup)} are "
                f"both held at the reading {level:.6g} but move off it in opposite "
                "directions — one spring cannot push both ways from one angle: the encoder "
                "was zeroed at each release; give each run its own set-up (a 'setup' column "
                "holding the run's label)",
                _THETA, int(run_rows[0]))
        first_move.setdefault(key, (k, direction))
