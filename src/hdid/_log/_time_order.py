"""Rows whose time does not increase: a sample written twice, or a clock that restarts.

- **A row written twice.** A logger that writes one sample twice (a retried write, a
  buffer flushed again) repeats a row exactly: the same time and the same readings in
  every column hdid reads. It holds no second observation — kept, it would be a zero time
  step — so the copy is dropped and the log's notes name it. A repeated time with
  *different* readings is two samples at one instant, which no reading resolves: it stays
  an error naming the row (:func:`hdid._log._validate.check_within_runs`) unless the
  stamps are a fixed-rate logger's, coarser than its sampling (:mod:`._timer`).
- **Runs interleaved row by row.** Rows labelled by their run but written in turn (several
  stations logged into one file) are grouped by run, each in file order, when every
  run's time increases in file order.
- **A clock that restarts.** Without a ``run`` column, a logger that restarts its clock
  at each release writes time that drops back (to 0, or to the start of the stretch
  before it). Each stretch is then a run of its own (``'1'``, ``'2'``, …; in a file of
  logs written one after another, a log's later stretches are ``'name.2'``, …) and the
  notes name the rows. Only a drop back into the first half of the stretch so far is a
  restart, and only when every stretch is long enough to be a run: two rows out of order
  (time drops by a sample or two) stay the error that asks to sort the rows. With a
  ``run`` column, time that drops inside one run stays an error.
- **A timer restarted near its end, a long pause.** A timer restarted just before its
  register ends jumps *forward* by nearly a register length (:mod:`._timer`), and a
  logger stopped and started again leaves a step of many sample periods. Without a
  ``run`` column, a forward step of more than :data:`RESTART_PERIODS` of the log's median
  step, or one the timer reader names a restart, starts a run too, whether the gear
  moves there or not: nothing links the samples across it, and simulating the pause
  would cost millions of substeps.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ._table import _Table

#: A forward time step longer than this many of the log's median steps is a new start
#: (a logger stopped and started again), not a sample the logger dropped: loggers drop
#: one to a few samples at a time (:data:`hdid._log._validate.BREAK_PERIODS`).
RESTART_PERIODS = 1000.0


def repeated_rows(values: list[np.ndarray | None]) -> np.ndarray:
    """Positions of the rows that repeat the row above in every one of ``values`` (the
    columns hdid reads: numbers compared exactly, labels as text; ``None`` skipped)."""
    same = None
    for v in values:
        if v is None:
            continue
        eq = np.asarray(v[1:] == v[:-1], dtype=bool)
        same = eq if same is None else same & eq
    if same is None:
        return np.zeros(0, dtype=np.int64)
    return np.flatnonzero(same) + 1


def repeated_rows_note(lines: np.ndarray, rows: np.ndarray) -> str:
    shown = ", ".join(str(int(lines[r])) for r in rows[:5])
    more = f" and {rows.size - 5} more" if rows.size > 5 else ""
    return (f"row(s) {shown}{more} repeat the row above exactly (the same time and readings: "
            "a sample written twice): dropped")


def take_rows(table: _Table, keep: np.ndarray) -> None:
    """Keep only the rows at positions ``keep`` of ``table`` (in place)."""
    table.columns = [c.iloc[keep].reset_index(drop=True) if isinstance(c, pd.Series)
                     else np.asarray(c)[keep] for c in table.columns]
    table.lines = table.lines[keep]
    if table.block is not None:
        table.block = np.asarray(table.block)[keep]


def runs_at_restarts(time: np.ndarray, run_labels: np.ndarray | None, lines: np.ndarray,
                     min_samples: int, jumps: np.ndarray | None = None,
                     labelled: bool = False) -> tuple[np.ndarray | None, list[str]]:
    """Run labels for a log without a ``run`` column whose time restarts, and a note
    (``run_labels`` unchanged and no note when it does not, or when a stretch would be
    too short to be a run: the time check then names the row). ``jumps``: positions of
    rows at which the timer reader found a restart (a forward jump); forward steps over
    :data:`RESTART_PERIODS` median steps are restarts too. ``labelled``: the labels are
    the log's own ``run`` column; only forward jumps split a run then (``'3'`` becomes
    ``'3'``, ``'3.2'``: a logger paused and started again inside one labelled test, where
    the fit would otherwise simulate the pause), and time that drops back inside a
    labelled run stays the time check's error."""
    n = time.size
    if n < 2:
        return run_labels, []
    block_start = np.zeros(n, dtype=bool)
    block_start[0] = True
    if run_labels is not None:
        block_start[1:] = run_labels[1:] != run_labels[:-1]
    steps = np.diff(time)
    ahead = steps[(steps > 0) & ~block_start[1:]]
    forward = np.zeros(n, dtype=bool)
    if ahead.size:
        forward[1:] = steps > RESTART_PERIODS * float(np.median(ahead))
    if jumps is not None:
        forward[np.asarray(jumps, dtype=np.int64)] = True
    forward &= ~block_start
    back = np.zeros(n - 1, dtype=bool) if labelled else (steps < 0) & ~block_start[1:]
    drops = np.flatnonzero(back | forward[1:]) + 1
    if drops.size == 0:
        return run_labels, []
    starts = np.flatnonzero(block_start)
    cut = np.zeros(n, dtype=bool)
    piece_start = 0
    for i in drops:  # in file order: each stretch starts at its block's start or a drop
        piece_start = max(piece_start, int(starts[np.searchsorted(starts, i, side="right") - 1]))
        # a restart drops back into the first half of the stretch so far
        if not forward[i] and time[i] > time[piece_start] + 0.5 * (time[i - 1]
                                                                     - time[piece_start]):
            return run_labels, []
        cut[i] = True
        piece_start = int(i)
    edges = np.flatnonzero(block_start | cut)
    if np.min(np.diff(np.append(edges, n))) < min_samples:
        return run_labels, []
    labels = np.empty(n, dtype=object)
    names = []
    for e, f in zip(edges, np.append(edges[1:], n)):
        if run_labels is None:
            name = str(len(names) + 1)
        else:
            block = str(run_labels[e])
            k = int(np.sum(cut[starts[np.searchsorted(starts, e, side="right") - 1]:e + 1]))
            name = block if k == 0 else f"{block}.{k + 1}"
        labels[e:f] = name
        names.append(name)
    shown = ", ".join(f"{int(lines[i])} ({time[i - 1]:.6g} s → {time[i]:.6g} s"
                      f"{', a forward jump' if forward[i] else ''})" for i in drops[:5])
    more = f" and {drops.size - 5} more" if drops.size > 5 else ""
    listed = f"{', '.join(repr(m) for m in names[:6])}{', …' if len(names) > 6 else ''}"
    if labelled:
        return labels, [f"time jumps forward inside a labelled run at row(s) {shown}{more} (over "
                        f"{RESTART_PERIODS:g} median steps or a timer restart: the logger "
                        f"started again): each stretch is a run ({listed})"]
    return labels, [f"time restarts at row(s) {shown}{more} and the log has no 'run' column: "
                    f"each stretch is a run ({listed})"]


def group_interleaved(run_labels: np.ndarray | None, time: np.ndarray, lines: np.ndarray
                      ) -> tuple[np.ndarray | None, str | None]:
    """Row order that groups runs written interleaved (a logger writing several stations'
    samples row by row, each with its run label), and a note; ``(None, None)`` when the
    runs are contiguous already, or when some run's time does not increase in file order
    (the rows are then out of order, not interleaved: the run check names them)."""
    if run_labels is None or run_labels.size < 2:
        return None, None
    codes, uniques = pd.factorize(run_labels)
    changes = int(np.count_nonzero(codes[1:] != codes[:-1]))
    if changes == uniques.size - 1:
        return None, None
    order = np.argsort(codes, kind="stable")
    grouped_time, grouped = time[order], codes[order]
    same = grouped[1:] == grouped[:-1]
    if np.any(np.diff(grouped_time)[same] <= 0):
        return None, None
    first = int(lines[int(np.flatnonzero(codes[1:] != codes[:-1])[0]) + 1])
    return order, (f"the runs are interleaved row by row (from row {first}, each row labelled "
                   f"by its run): rows grouped by run, {uniques.size} runs, each in file order")
