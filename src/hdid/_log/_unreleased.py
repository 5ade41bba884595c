"""Still runs that cannot be rest points: a run logged but never released.

A run that never moves is kept as a rest point inside the stick band (a release from
inside it stays stuck). That holds only where the spring can be held by static friction.
A moving run of the same set-up (same encoder zero) that turned at an angle ``T`` and slid
on shows that the spring torque at ``T`` beat static friction (at a turning point the gear
is at rest for an instant, so only the static limit holds it); the spring torque grows
with the distance from its zero, which lies on the side the run slid towards, so every
angle beyond ``T`` (away from the zero) is held by nothing either. A still run read
beyond the innermost such turning point on its side (by more than the readings' margin)
was therefore held by something else — the brake or servo before a release the logger
did not record — and its reading says nothing about the stick band: it is left out of the
fit, with a note naming it, its level and the turning point that rules it out.

Readings are in rad (the log's angle column). The margin is 2 encoder steps (a one-step
flicker either side of a level), or with no known step 4 sigma of the readings' noise (the
MAD of their second differences, which also holds the motion's curvature: larger, so
fewer runs are left out). A still run within the span of the moving runs' final still
stretches (their rests) is never left out.
"""

from __future__ import annotations

import numpy as np

from ._table import _show


def _turning_points(r: np.ndarray, margin: float) -> tuple[list[float], list[float]]:
    """``(maxima, minima)`` [rad] of one run from which it slid on: every reversal it left
    by more than ``margin`` after reaching it by more than ``margin`` (a zig-zag with that
    hysteresis), and its start when it is held there first (a release from rest)."""
    maxima: list[float] = []
    minima: list[float] = []
    held = r.size >= 2 and r[1] == r[0]
    hi = lo = float(r[0])
    direction = 0
    for x in map(float, r[1:]):
        if direction == 0:
            if x - lo > margin:
                direction, hi = 1, x
                if held:
                    minima.append(lo)
            elif hi - x > margin:
                direction, lo = -1, x
                if held:
                    maxima.append(hi)
            else:
                hi, lo = max(hi, x), min(lo, x)
        elif direction == 1:
            if x > hi:
                hi = x
            elif hi - x > margin:
                maxima.append(hi)
                direction, lo = -1, x
        else:
            if x < lo:
                lo = x
            elif x - lo > margin:
                minima.append(lo)
                direction, hi = 1, x
    return maxima, minima


def _margin(theta, starts, ends, moving, resolution: float | None) -> float:
    """Two encoder steps (a one-step flicker either side of a level), or with no known
    step 4 sigma of the moving runs' noise (robust: the MAD of second differences, whose
    sd is sqrt(6) sigma; a difference of two readings has sd sqrt(2) sigma, so 4 sigma is
    2.8 of its sd)."""
    if resolution is not None:
        return 2.0 * resolution
    d2 = np.concatenate([np.diff(theta[starts[k]:ends[k]], 2) for k in moving])
    if not d2.size:
        return 0.0
    return 4.0 * 1.4826 * float(np.median(np.abs(d2 - np.median(d2)))) / np.sqrt(6.0)


def _rest(r: np.ndarray, margin: float) -> tuple[float, float]:
    """``(low, high)`` [rad] of a run's last still stretch: the longest tail whose readings
    span at most ``2 margin`` (its flicker or noise about the rest; a run stopped mid-swing
    gives its last reading or so, which only widens the rests)."""
    rev = r[::-1]
    span = np.maximum.accumulate(rev) - np.minimum.accumulate(rev)
    n = int(np.argmax(span > 2.0 * margin)) if np.any(span > 2.0 * margin) else rev.size
    tail = rev[:max(n, 1)]
    return float(np.min(tail)), float(np.max(tail))


def unreleased_runs(theta, starts, ends, names, setups, still: list[int],
                    resolution: float | None) -> tuple[list[int], list[str]]:
    """``(left_out, notes)``: the still runs (indices into ``starts``) held beyond the
    innermost turning point on their side from which a moving run of the same set-up slid
    on, and one note for each. ``setups`` holds each run's set-up label."""
    left_out: list[int] = []
    notes: list[str] = []
    still_set = set(still)
    for r in still:
        same = [k for k in range(len(starts))
                if k not in still_set and setups[k] == setups[r]]
        if not same:
            continue
        level = float(np.median(theta[starts[r]:ends[r]]))
        margin = _margin(theta, starts, ends, same, resolution)
        rests = [x for k in same for x in _rest(theta[starts[k]:ends[k]], margin)]
        if min(rests) <= level <= max(rests):
            continue  # between the rests: a rest point (the guard)
        above = level > max(rests)
        best: tuple[float, int] | None = None
        for k in same:
            maxima, minima = _turning_points(theta[starts[k]:ends[k]], margin)
            # on the still run's side of the rests, the innermost point slid on from
            points = ([t for t in maxima if t > max(rests)] if above
                      else [t for t in minima if t < min(rests)])
            for t in points:
                if best is None or (t < best[0] if above else t > best[0]):
                    best = (t, k)
        if best is None or abs(level - best[0]) <= margin or (level < best[0]) == above:
            continue
        turn, k = best
        left_out.append(r)
        setup = "" if len(set(setups)) == 1 else f" of set-up {_show(setups[r])}"
        notes.append(
            f"run {_show(names[r])} never moves, held at {level:.6g} rad: {abs(level - turn):.3g} "
            f"rad beyond the turning point {turn:.6g} rad from which run {_show(names[k])}"
            f"{setup} slid on (the spring there already beat static friction), so it is no "
            "rest point — a run logged but never released (the logger stopped before the "
            "release): left out of the fit. To keep it, give it its own set-up (a 'setup' "
            "column) if its encoder zero differs, or join it to the release it preceded "
            "(one label in the 'run' column)")
    return left_out, notes
