"""Single-turn angles that wrap at one revolution: an absolute encoder reads its angle
within one turn, and a gear at rest near the wrap point reads on both ends of the range.

A motor's absolute single-turn encoder reads counts ``0 … cpr − 1``; a controller prints
its angle in ``[0, 2π)`` or ``[−π, π)`` rad, ``[0, 360)`` or ``[−180, 180)`` degrees.
Released near the wrap point (a rest at 4090 of 4096 counts, at 359.9°), the gear swings
across it and the readings step by about one revolution between two samples — a motion
no gear makes in one sample period. The readings lie within one revolution (their span,
as read, is at most 2π rad), and a wrap is a step between two samples of one run larger
than half a revolution which, undone (±2π), is

- nearer the motion around it (the mean of the nearest ordinary steps either side: the
  gear's speed) than as read, and
- no larger than :data:`SPEED_FACTOR` times the log's largest ordinary one-sample change
  (the speed the gear reaches anywhere else).

A read dropout (a bus servo's −π among readings near −1 rad) fails the second test by
far: it is left as read, a step that returns at the next sample, and :mod:`._dropouts`
drops it. A one-sample excursion across the wrap point that passes both (the peak of a
swing, the encoder flickering at the wrap point) is motion, unwrapped like any wrap.

Each wrap is undone by adding ±2π to every later reading of its run. The runs of a
set-up share the encoder's zero (the fit gives each set-up one offset), so once a set-up
has a wrap, or its runs sit on both ends of the range (their medians more than half a
revolution apart as read), each of its runs is moved by whole revolutions to lie within
half a revolution of the set-up's circular mean — all of them on one side of the wrap
point, as the gear is — and the log's notes say so.
"""

from __future__ import annotations

import math

import numpy as np

from ._table import _show

#: One revolution [rad].
REVOLUTION = 2.0 * math.pi
#: Readings that span more than this many revolutions are no single-turn angle (a
#: printed 2π that rounds up, ``6.2832``, still is one).
SPAN_TOLERANCE = 1e-3
#: An undone wrap is at most this many times the log's largest ordinary one-sample
#: change (a wrap at the fastest instant of the fastest run is about 1×; a read dropout,
#: −π among readings a radian or more away, is many times it).
SPEED_FACTOR = 4.0


def _run_wraps(x: np.ndarray, largest: float) -> np.ndarray:
    """Positions ``i`` of the steps ``x[i] → x[i+1]`` of one run that are wraps;
    ``largest`` is the log's largest ordinary one-sample change."""
    d = np.diff(x)
    wide = np.abs(d) > REVOLUTION / 2
    if not wide.any() or wide.all():
        return np.zeros(0, dtype=np.int64)
    ok = np.flatnonzero(~wide)
    cand = np.flatnonzero(wide)
    left = ok[np.clip(np.searchsorted(ok, cand) - 1, 0, None)]
    right = ok[np.clip(np.searchsorted(ok, cand), None, ok.size - 1)]
    speed = 0.5 * (d[left] + d[right])
    u = d - REVOLUTION * np.rint(d / REVOLUTION)  # every step, undone
    keep = (np.abs(u[cand] - speed) < np.abs(d[cand] - speed)) & (
        np.abs(u[cand]) <= SPEED_FACTOR * largest)
    return cand[keep]


def _circular_mean(x: np.ndarray) -> float:
    return float(np.angle(np.mean(np.exp(1j * x))))


def unwrap_revolutions(theta: np.ndarray, starts, ends, names, setups, lines,
                       column: str, per_rev: float) -> tuple[np.ndarray, list[str]]:
    """Readings [rad] with every wrap at one revolution undone and each wrapped set-up's
    runs on one side of the wrap point, and the notes (none when nothing moved).

    ``starts``/``ends`` bound the runs (file positions), ``names`` name them, ``setups``
    holds each row's set-up label (``None``: one set-up), ``lines`` the file line numbers,
    ``column`` the column's header and ``per_rev`` one revolution in its units (for the
    note)."""
    if theta.size < 2 or not np.all(np.isfinite(theta)):
        return theta, []
    if float(np.ptp(theta)) > REVOLUTION * (1.0 + SPAN_TOLERANCE):
        return theta, []
    within = np.ones(theta.size - 1, dtype=bool)
    within[np.asarray(ends, dtype=np.int64)[:-1] - 1] = False  # no step across two runs
    steps = np.abs(np.diff(theta))[within]
    ordinary = steps[steps <= REVOLUTION / 2]
    largest = float(ordinary.max()) if ordinary.size else 0.0
    out = theta.copy()
    wrapped_rows: list[int] = []
    wrapped_runs: set[int] = set()
    for k, (a, b) in enumerate(zip(starts, ends)):
        a, b = int(a), int(b)
        wraps = _run_wraps(theta[a:b], largest)
        if wraps.size == 0:
            continue
        d = np.diff(theta[a:b])
        turns = np.zeros(b - a)
        turns[wraps + 1] = -np.rint(d[wraps] / REVOLUTION)
        out[a:b] += REVOLUTION * np.cumsum(turns)
        wrapped_rows += [int(lines[a + i + 1]) for i in wraps]
        wrapped_runs.add(k)
    # the runs of a set-up on one side of the wrap point (one shared zero)
    labels = ["1" if setups is None else str(setups[int(a)]) for a in starts]
    moved: list[str] = []
    for label in dict.fromkeys(labels):
        runs = [k for k, s in enumerate(labels) if s == label]
        medians = np.array([np.median(out[int(starts[k]):int(ends[k])]) for k in runs])
        straddle = float(np.ptp(medians)) > REVOLUTION / 2
        if not (straddle or wrapped_runs.intersection(runs)):
            continue
        rows = np.concatenate([np.arange(int(starts[k]), int(ends[k])) for k in runs])
        centre = _circular_mean(theta[rows])
        shift = -REVOLUTION * np.rint((medians - centre) / REVOLUTION)
        if float(np.ptp(medians + shift)) > REVOLUTION / 2:
            continue  # the runs share no half revolution: leave them as read
        values, counts = np.unique(shift, return_counts=True)
        shift = shift - values[np.argmax(counts)]  # most runs stay as read
        for k, s in zip(runs, shift):
            if s != 0.0:
                out[int(starts[k]):int(ends[k])] += s
                if k not in wrapped_runs:
                    moved.append(names[k])
    if not wrapped_rows and not moved:
        return theta, []
    unit = "2π" if abs(per_rev - REVOLUTION) < 1e-9 else f"{per_rev:.6g}"
    notes = []
    if wrapped_rows:
        shown = ", ".join(map(str, wrapped_rows[:5]))
        more = f" and {len(wrapped_rows) - 5} more" if len(wrapped_rows) > 5 else ""
        notes.append(
            f"column {column!r}: a single-turn angle wraps at one revolution ({unit} "
            f"in its units) at row(s) {shown}{more} (a step of more than half a revolution "
            "between two samples that the motion around it does not continue): unwrapped by "
            "one revolution")
    if moved:
        notes.append(
            f"column {column!r}: run(s) {', '.join(map(_show, moved))} read on the other end "
            f"of the single-turn range than the rest of their set-up: moved by one "
            f"revolution ({unit} in the column's units) to share its zero")
    return out, notes
