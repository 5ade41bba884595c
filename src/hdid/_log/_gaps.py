"""Tables laid out otherwise than one row per sample: one angle column per run side by
side, and a reading the logger could not take.

- **One column per run (wide).** A spreadsheet or a station's export may put the runs side
  by side: a ``time`` column and one angle column per run, named with the run's label
  (``theta_1 [rad]``, ``theta_2 [rad]``, ``Position run3``). Without a ``theta`` column,
  two or more such columns are read as runs: each run is the rows where its column is
  filled, at the shared times, and keeps the file's line numbers. Cells after a run's last
  reading may be empty (runs of different length); an empty cell between two readings is
  a missing reading (below).
- **A reading the logger could not take.** A station writes an empty cell, ``NaN`` or
  ``NA`` where a read failed, the time still stamped. The sample is then absent — the
  model is evaluated at the logged times, so a missing sample is a dropped one — and the
  row is dropped with a note. Only lone misses are read so (the rows on both sides of it
  hold readings) and at most :data:`MAX_MISSING_FRACTION` of the rows; more, or a missing
  time, stays the error that names the cell. A driven log's rows are never dropped (the
  motor torque of a row acts until the next one: dropping it would change the input).
"""

from __future__ import annotations


import numpy as np
import pandas as pd

from ._headers import header_key
from ._names import _RUN_COLUMN, _THETA, _TIME
from ._table import _Table

#: Most rows that may lack their reading (a logger's failed reads) before it is an error.
MAX_MISSING_FRACTION = 0.01


def wide_to_long(table: _Table, missing) -> tuple[_Table, list[str]]:
    """The table with one row per sample of each run (columns ``time``, ``run`` and
    ``theta [unit]``) when it holds one angle column per run; else the table as it is.
    ``missing(column)`` marks a column's empty and missing-value cells."""
    keys = [header_key(n) for n in table.names]
    if any(k == _THETA for k, _ in keys) or not any(k == _TIME for k, _ in keys):
        return table, []
    runs = [(i, m.group(1) or m.group(2), unit) for i, (k, unit) in enumerate(keys)
            if (m := _RUN_COLUMN.match(k)) is not None]
    units = {u for _, _, u in runs}
    if len(runs) < 2 or len(units) > 1:
        return table, []
    t = next(i for i, (k, _) in enumerate(keys) if k == _TIME)
    time, run, theta, lines = [], [], [], []
    for i, label, _ in runs:
        filled = np.flatnonzero(~missing(table.columns[i]))
        if filled.size == 0:
            continue
        rows = np.arange(filled[-1] + 1)  # to the run's last reading; gaps stay gaps
        time.append(np.asarray(table.columns[t], dtype=object)[rows])
        theta.append(np.asarray(table.columns[i], dtype=object)[rows])
        run.append(np.full(rows.size, label, dtype=object))
        lines.append(table.lines[rows])
    unit = units.pop()
    names = [table.names[t], "run", "theta" if unit is None else f"theta [{unit}]"]
    long = _Table(table.source, table.path, names,
                  [np.concatenate(time), np.concatenate(run), np.concatenate(theta)],
                  np.concatenate(lines), list(table.notes))
    shown = ", ".join(repr(table.names[i]) for i, _, _ in runs[:4])
    return long, [f"one angle column per run ({shown}{', …' if len(runs) > 4 else ''}): "
                  f"read as runs {', '.join(repr(r) for _, r, _ in runs)}"]


def drop_missing_readings(table: _Table, theta: int, time: int, missing
                          ) -> tuple[_Table, list[str]]:
    """The table without the rows whose reading is missing (time present), when each is a
    lone miss and they are at most :data:`MAX_MISSING_FRACTION` of the rows; a note."""
    gone = missing(table.columns[theta])
    n = gone.size
    if not gone.any() or missing(table.columns[time])[gone].any():
        return table, []
    where = np.flatnonzero(gone)
    lone = (where > 0) & (where < n - 1)
    lone[lone] = ~gone[where[lone] - 1] & ~gone[where[lone] + 1]
    if not lone.all() or where.size > MAX_MISSING_FRACTION * n:
        return table, []  # the cell check names the first
    keep = np.flatnonzero(~gone)
    table.columns = [c.iloc[keep].reset_index(drop=True) if isinstance(c, pd.Series)
                     else np.asarray(c)[keep] for c in table.columns]
    rows = [int(table.lines[i]) for i in where]
    table.lines = table.lines[keep]
    if table.block is not None:
        table.block = np.asarray(table.block)[keep]
    shown = ", ".join(map(str, rows[:5])) + (f" and {len(rows) - 5} more" if len(rows) > 5
                                               else "")
    return table, [f"column {table.names[theta]!r}: no reading at row(s) {shown} (an empty "
                   "or missing-value cell with its time: a read the logger missed): the "
                   "sample(s) dropped"]
