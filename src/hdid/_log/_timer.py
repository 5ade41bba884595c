"""A logger's own clock: a timer register that rolls over, and stamps coarser than the
sampling.

- **A timer that rolls over.** Controllers and data loggers stamp samples with a free-running
  counter: a 16-bit millisecond timer (``0 … 65 535`` ms, 65.5 s), a 32-bit microsecond one
  (71.6 min). Past its end it wraps to 0 (or, signed, from ``2**31 − 1`` to ``−2**31``), and
  time read as written drops back by about ``2**16`` or ``2**32`` units. A wrap is told from
  a clock restarted at a new release (:mod:`._time_order`) by the step it leaves: undone
  (``+2**bits``), the step is an ordinary sample step — positive and at most
  ``BREAK_STEPS`` of the log's median step, the same rate on both sides. A restart drops to
  near zero from anywhere, and undone it would leave a step of thousands of samples. Only
  a time column of whole ticks (whole numbers, or a counter printed in another unit:
  a millisecond timer in seconds, ``65.532``, ticks by 0.001) whose values fit the
  register is read so.
- **A timer restarted near its end.** A logger that restarts its timer at each run may
  start it anywhere, also just before its end: the time then jumps *forward* by nearly a
  register length (a 32-bit µs timer started 1.3 s before its end jumps by
  ``2**32 µs − 1.3 s``, 71.6 min) and the timer's wrap follows a little later. No pause of
  a sampling logger is read so: a forward step of more than half the register is a
  restart, and :func:`unwrap_timer` names its rows (a new run starts there,
  :mod:`._time_order`).
- **Stamps coarser than the sampling.** A fixed-rate logger sampling faster than its
  timestamps resolve (4 kHz stamped to 1 ms) writes each time several times, each with a
  different reading. Where every stamp of a run is its sample's instant cut to the print
  unit — the stamps lie within one print unit of one straight line ``t0 + k·h`` (``k`` the
  sample index) — the samples are uniform and their times are that line; the notes say so.
  Stamps that do not (a repeated stamp in a log whose step is several print units, jitter
  larger than the print unit) stay the error that names the row.
"""

from __future__ import annotations

import numpy as np
import pandas as pd

from ._resolution import column_print_units

#: Widths [bits] of the timer registers loggers stamp samples with.
TIMER_BITS = (16, 32)
#: A wrap undone must leave a step of at most this many median steps (the break rule).
BREAK_STEPS = 5.0


def unwrap_timer(time: np.ndarray, rows: np.ndarray, column: str
                 ) -> tuple[np.ndarray, str | None, np.ndarray]:
    """Time with every timer wrap undone (in the column's own units, file order), a note
    naming the wraps (None when there are none), and the positions of the rows at which
    the timer was restarted near its end (a forward step of more than half the register
    that holds every value; each such row starts a run)."""
    none = np.zeros(0, dtype=np.int64)
    if time.size < 3 or not np.all(np.isfinite(time)):
        return time, None, none
    tick = _tick(time)
    if tick is None:
        return time, None, none  # not a counter's ticks
    steps = np.diff(time)
    ahead = steps[steps > 0]
    if ahead.size == 0:
        return time, None, none
    typical = float(np.median(ahead))
    lo, hi = float(np.min(time)), float(np.max(time))
    restarts = none
    for bits in TIMER_BITS:  # the narrowest register that holds every value
        span = 2.0 ** bits * tick
        if (lo >= 0 and hi < span) or (lo >= -span / 2 and hi < span / 2):
            restarts = np.flatnonzero(steps > span / 2) + 1
            break
    turns = np.zeros(time.size)
    wrapped = []
    for i in np.flatnonzero(steps < 0):
        for bits in TIMER_BITS:
            span = 2.0 ** bits * tick
            if not ((lo >= 0 and hi < span) or (lo >= -span / 2 and hi < span / 2)):
                continue
            undone = steps[i] + span
            if -steps[i] > span / 2 and 0 < undone <= BREAK_STEPS * typical:
                turns[i + 1] = span
                wrapped.append((int(rows[i + 1]), bits))
                break
    if not wrapped:
        return time, None, restarts
    shown = ", ".join(str(r) for r, _ in wrapped[:5])
    more = f" and {len(wrapped) - 5} more" if len(wrapped) > 5 else ""
    bits = "/".join(sorted({str(b) for _, b in wrapped}))
    return time + np.cumsum(turns), (
        f"column {column!r}: the logger's {bits}-bit timer rolls over at row(s) {shown}{more} "
        "(time drops back by the register's length and goes on at the same rate): unwrapped"
    ), restarts


def _tick(time: np.ndarray) -> float | None:
    """The counter's tick in the column's units: 1 for whole numbers, else the finest
    decimal every value is a whole multiple of (a millisecond counter printed in seconds,
    ``65.532``, ticks by 0.001); None for time that is no count of ticks."""
    for decimals in range(0, 10):
        scaled = time * 10.0 ** decimals
        if np.all(np.abs(scaled - np.rint(scaled)) <= 1e-9 * np.maximum(1.0, np.abs(scaled))):
            return 10.0 ** -decimals
    return None


def uniform_stamps(time: np.ndarray, block_start: np.ndarray, print_units,
                   rows: np.ndarray, names: np.ndarray | None
                   ) -> tuple[np.ndarray, list[str]]:
    """Time [s] with each run whose stamps repeat (a fixed-rate logger faster than its
    stamps) rebuilt as uniform steps, when every stamp is within one print unit of one
    line; notes naming the runs. ``block_start`` marks each run's first row,
    ``print_units()`` gives each cell's print unit [s] (None: numbers never printed:
    nothing is rebuilt); it is asked only when some stamp repeats.

    One logger samples every run at one rate: the step ``h`` is fitted to all such runs
    together (each with its own start), which they must all fit; else each its own."""
    edges = np.append(np.flatnonzero(block_start), time.size)
    blocks = []
    for a, b in zip(edges[:-1], edges[1:]):
        steps = np.diff(time[a:b])
        if b - a >= 8 and np.any(steps == 0) and not np.any(steps < 0):
            blocks.append((int(a), int(b)))
    print_unit = print_units() if blocks else None
    if print_unit is None:
        return time, []
    blocks = [(a, b, float(np.max(print_unit[a:b]))) for a, b in blocks]

    def line(a: int, b: int, h: float | None = None) -> tuple[float, float]:
        k = np.arange(b - a, dtype=np.float64)
        if h is None:
            h = float(np.polyfit(k, time[a:b], 1)[0])
        return h, float(np.mean(time[a:b] - h * k))

    def fits(a: int, b: int, unit: float, h: float, c: float) -> bool:
        # cut to the print unit, the stamps lie within one unit of the instants: their
        # residuals from the line span under one unit, plus the fitted step's error
        # (~unit/sqrt(n) over the run)
        resid = time[a:b] - (c + h * np.arange(b - a))
        return 0 < h < unit and np.ptp(resid) <= unit * (1.0 + 4.0 / np.sqrt(b - a))

    own = {a: line(a, b) for a, b, _ in blocks}
    good = [(a, b, u) for a, b, u in blocks if fits(a, b, u, *own[a])]
    if not good:
        return time, []
    k_all = [np.arange(b - a, dtype=np.float64) for a, b, _ in good]
    sxy = sum(np.sum((k - k.mean()) * (time[a:b] - time[a:b].mean()))
              for k, (a, b, _) in zip(k_all, good))
    sxx = sum(np.sum((k - k.mean()) ** 2) for k in k_all)
    pooled = float(sxy / sxx)
    shared = all(fits(a, b, u, *line(a, b, pooled)) for a, b, u in good)
    out = time.copy()
    for a, b, _ in good:
        h, c = line(a, b, pooled) if shared else own[a]
        out[a:b] = c + h * np.arange(b - a)
    which = "" if names is None else "run(s) " + ", ".join(
        repr(str(names[a])) for a, _, _ in good[:6]) + (", …" if len(good) > 6 else "") + ": "
    step = f"every {pooled:.6g} s" if shared else "at a fixed rate"
    return out, [
        f"{which}time repeats (rows {int(rows[good[0][0]])}-{int(rows[good[-1][1] - 1])}), "
        f"stamped to {good[0][2]:.3g} s by a logger sampling {step}: every stamp lies within "
        "one print unit of uniform steps, so the time is rebuilt as those steps"
    ]


def time_print_unit(column, scale: float) -> np.ndarray | None:
    """Each time cell's print unit [s]: its last written digit (a column of whole numbers,
    parsed as integers, is printed to 1 of its unit); None for numbers never printed."""
    if isinstance(column, pd.Series) and pd.api.types.is_integer_dtype(column.dtype):
        return np.full(column.size, float(scale))
    return column_print_units(column, scale)


#: Cells of a time column read for :func:`largest_time_print_unit` (a strided sample).
_TIME_CELLS = 4096


def largest_time_print_unit(column, scale: float, rows: np.ndarray,
                            time: np.ndarray) -> float | None:
    """The coarsest print unit [s] of the time cells at ``rows`` (:func:`time_print_unit`),
    read on a strided sample of :data:`_TIME_CELLS` cells and the largest |time| (where a
    column printed to significant digits is coarsest): every time cell is distinct, and
    parsing all of a 100 000-row log's would double its read time. ``None`` for numbers
    never printed."""
    if isinstance(column, pd.Series) and pd.api.types.is_integer_dtype(column.dtype):
        return float(scale)
    if rows.size > _TIME_CELLS:
        rows = np.unique(np.concatenate((rows[:: rows.size // _TIME_CELLS + 1],
                                         rows[[int(np.argmax(np.abs(time[rows]))), -1]])))
    cells = column.iloc[rows] if isinstance(column, pd.Series) else np.asarray(column)[rows]
    units = time_print_unit(cells.reset_index(drop=True) if isinstance(cells, pd.Series)
                            else cells, scale)
    return None if units is None else float(np.max(units))
