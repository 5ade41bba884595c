"""A time column of date-times: ``2026-11-27T10:00:00.004`` (ISO 8601, as data loggers,
LabVIEW and Python's ``datetime`` write them) or times of day (``10:00:00.004``) read as
seconds.

Only the differences between samples matter to the fit, so the readings are taken as
seconds after the first row's instant, to the nanosecond (pandas' ``datetime64[ns]``).
A column is read this way when its first filled cell is a date and time of day; a cell
below that is not one is an error naming its row. Times with a UTC offset are compared
in UTC; a daylight-saving jump of a local clock without offsets is the logger's error
and shows as a step back or a break in the run.
"""

from __future__ import annotations

import re

import numpy as np
import pandas as pd

from ._table import _cell_text, _show

#: ``YYYY-MM-DD`` then ``T`` or a space and ``hh:mm`` (seconds and fractions optional).
_ISO = re.compile(r"^\d{4}-\d{2}-\d{2}[T ]\d{1,2}:\d{2}")
#: A time of day alone: ``10:00:00.004`` (a day's log; past midnight, where it drops back
#: by more than half a day, a day is added).
_CLOCK = re.compile(r"^\d{1,2}:\d{2}:\d{2}(\.\d+)?$")


def holds_datetimes(column) -> bool:
    """Whether a column's first filled cell is a date and time of day (or a time of day)."""
    first = next((t for t in map(_cell_text, np.asarray(column, dtype=object)) if t), "")
    return bool(_ISO.match(first) or _CLOCK.match(first))


def timestamp_seconds(column, fail) -> np.ndarray | None:
    """Seconds after the first row of a column of ISO 8601 date-times, or None when the
    column does not hold date-times (it is read as numbers). ``fail(message, pos)`` builds
    the error for a cell that is no date-time."""
    if isinstance(column, pd.Series) and pd.api.types.is_datetime64_any_dtype(column.dtype):
        stamps = pd.to_datetime(column, utc=True)
    else:
        raw = np.asarray(column, dtype=object)
        first = next((t for t in map(_cell_text, raw) if t), "")
        if not first or first[0] in "+-." or first[-1:].isdigit() and ":" not in first:
            return None  # a number (the quick test: most time columns)
        text = np.array([_cell_text(c) for c in raw], dtype=object)
        filled = np.flatnonzero(text != "")
        if _ISO.match(first):
            form = "ISO8601"
        elif _CLOCK.match(first):  # a time of day
            with_fraction = all("." in t for t in text[filled])
            form = "%H:%M:%S.%f" if with_fraction else "mixed"
        else:
            return None
        stamps = pd.to_datetime(pd.Series(text), format=form, utc=True, errors="coerce")
        bad = np.flatnonzero(stamps.isna().to_numpy())
        if bad.size:
            pos = int(bad[0])
            what = f"the text {_show(text[pos])}" if text[pos] else "nothing"
            raise fail(f"cell holds {what} where a date and time like the rows above is "
                       "expected (e.g. 2026-11-27T10:00:00.004) — fix the cell or drop the row",
                       pos)
    ns = stamps.to_numpy(dtype="datetime64[ns]").astype(np.int64)
    if not isinstance(column, pd.Series) or not pd.api.types.is_datetime64_any_dtype(
            column.dtype):
        if form != "ISO8601":  # times of day: past midnight the clock reads 00:00 again
            ns = ns + _DAY_NS * np.cumsum(np.diff(ns, prepend=ns[0]) < -_DAY_NS // 2)
    return (ns - ns[0]).astype(np.float64) * 1e-9


#: One day [ns]: a time of day that drops back by more than half of it crossed midnight.
_DAY_NS = 86_400 * 10**9
