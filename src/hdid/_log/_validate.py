"""The checks of a log's rows once its cells are numbers: runs contiguous, labels constant
within a run, time increasing, runs long enough, one shared sample period, motion in
every run. Each check raises the :class:`~hdid.LogError` that names the row and the fix
(``fail(message, column_key, position)`` builds it)."""

from __future__ import annotations

import math
from collections.abc import Callable

import numpy as np
import pandas as pd

from .._errors import LogError
from ._columns import _first
from ._names import _INERTIA, _MIN_MOTION_UNQUANTIZED, _RUN, _SETUP, _THETA, _TIME
from ._table import _show

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
            msg = f"time {time[pos + 1]:.9g} repeats the previous row — remove the duplicated row"
        else:
            msg = (
                f"time {time[pos + 1]:.9g} is not after the previous {time[pos]:.9g} — time must "
                "increase strictly within a run; sort the rows, or add a 'run' column if a new "
                "release starts here"
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


def sample_period(time, within, starts, ends, names, tolerance: float, fail: Fail) -> float:
    """The log's sample period (median step within runs); every step within
    ``tolerance`` of it, else the run or row that breaks it."""
    steps = np.diff(time)
    period = float(np.median(steps[within]))
    if not math.isfinite(period):
        raise fail("time values are too large to take differences — write time in seconds", _TIME)
    tol = float(tolerance)
    pos = _first((np.abs(steps - period) > tol * period) & within)
    if pos is not None:
        r = int(np.searchsorted(starts, pos, side="right") - 1)
        run_period = float(np.median(np.diff(time[starts[r] : ends[r]])))
        if abs(run_period - period) > tol * period:
            raise fail(
                f"run {_show(names[r])} is sampled every {run_period:.6g} s but the log's period "
                f"is {period:.6g} s — all runs must share one sample rate (within "
                f"{100 * tol:g}%); resample the run or read it separately",
                _TIME,
                int(starts[r]),
            )
        raise fail(
            f"run {_show(names[r])}: time step {steps[pos]:.6g} s differs from the log's sample "
            f"period {period:.6g} s by more than {100 * tol:g}% — resample the log to a "
            "uniform rate or split it into runs at this row",
            _TIME,
            pos + 1,
        )
    return period


def check_motion(theta, starts, names, resolution: float | None, fail: Fail) -> None:
    """Every run moves: at least 2 encoder steps (or 1e-9 rad with no known step)."""
    spans = np.maximum.reduceat(theta, starts) - np.minimum.reduceat(theta, starts)
    if resolution is not None:
        still = spans < (2.0 - 1e-6) * resolution
        why = f"less than 2 encoder steps of {resolution:.6g} rad"
    else:
        still = spans < _MIN_MOTION_UNQUANTIZED
        why = f"less than {_MIN_MOTION_UNQUANTIZED:g} rad"
    r = _first(still)
    if r is not None:
        raise fail(
            f"run {_show(names[r])} shows no motion (theta spans {spans[r]:.6g} rad, {why}) — "
            "check that the drive was twisted and released, or drop the run",
            _THETA,
            int(starts[r]),
        )
