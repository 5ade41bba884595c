"""Logs written by robotics tools, whose columns follow the tool's conventions rather
than a name and a unit: ROS topic dumps and PX4 flight-log exports.

ROS (``rostopic echo -p``, ``rosbag2`` CSV exports): ``%time`` (or ``timestamp``) is when
the recorder *received* each message, in integer nanoseconds since 1970; the message's
own ``header.stamp`` is when the driver *sampled* it — as one integer in nanoseconds
(``field.header.stamp``) or as seconds and nanoseconds (``field.header.stamp.secs`` /
``.nsecs``; ROS 2: ``header.stamp.sec`` / ``.nanosec``). The sample's stamp is the time
(the receipt adds the transport's delay and jitter); the receipt is used only without one.
Nanoseconds since 1970 (1.7e18) are beyond float64's 2^53: read as floats their last
~8 bits are lost (steps of 256 ns), so they are taken in integer arithmetic relative to
the first row. The angle is ``field.position`` (a JointState of one joint:
``field.position0``) or ``field.data`` (a Float64 topic), in radians (ROS REP 103).

PlotJuggler's CSV export: ``__time`` [s since 1970], each series named by its topic path
(``/joint_states/wg_joint/position``).

PX4 (``ulog2csv``): every topic's first column is ``timestamp``, integer microseconds
since boot; a wheel encoder's angle is ``encoder_position[0]``, in counts.

Data loggers and LabVIEW: a bare ``Timestamp`` (or ``DateTime``) of date-times
(``2026-11-27 10:00:00.004``) is the time, read as seconds by :mod:`._timestamps`.
"""

from __future__ import annotations

from decimal import Decimal, InvalidOperation

import numpy as np

from .._errors import LogError
from ._headers import header_key
from ._names import _COUNTS, _THETA, _TIME
from ._timestamps import holds_datetimes

#: ROS time columns, the sample's stamp first: (seconds, nanoseconds) pairs, then one
#: integer in nanoseconds.
_ROS_STAMP_PAIRS = (("field.header.stamp.secs", "field.header.stamp.nsecs"),
                    ("header.stamp.sec", "header.stamp.nanosec"),
                    ("header.stamp.secs", "header.stamp.nsecs"))
_ROS_STAMPS = ("field.header.stamp", "header.stamp", "%time", "timestamp")
#: ROS angle columns (radians), in order of preference.
_ROS_ANGLES = ("field.position0", "field.position", "position0", "position", "field.data",
               "data")
#: PX4's encoder angle (counts).
_PX4_ANGLE = "encoder_position[0]"
#: Bare names of a time column of date-times (``2026-11-27 10:00:00.004``); with a unit
#: (``timestamp [ms]``) the name is a time column of numbers (:mod:`._headers`).
_DATETIME_NAMES = ("timestamp", "time stamp", "time_stamp", "datetime", "date_time", "date time")


def _integers(column) -> list[int] | None:
    """The cells as Python integers, or ``None`` when some cell is not a whole number."""
    out = []
    for cell in np.asarray(column, dtype=object):
        text = str(cell).strip()
        if not text.lstrip("+-").isdigit():
            return None
        out.append(int(text))
    return out


def _relative(ticks: list[int]) -> np.ndarray:
    """Integer stamps relative to the first, as text cells (exact: differences < 2^53)."""
    first = ticks[0]
    return np.array([str(v - first) for v in ticks], dtype=object)


def tool_columns(table) -> list[str]:
    """Rename (and, for time, recompute) a ROS or PX4 log's columns to hdid's, in place;
    the notes that say what was taken. A table with hdid's own time column is left alone."""
    lower = [name.strip().lower() for name in table.names]
    stamps = [i for i, n in enumerate(lower) if n in _DATETIME_NAMES
              and holds_datetimes(table.columns[i][:50])]
    if any(header_key(n)[0] == _TIME for n in table.names):
        return [f"two time columns: the time is read from "
                f"{next(repr(n) for n in table.names if header_key(n)[0] == _TIME)}, not from "
                f"the date-times of '{table.names[i]}'" for i in stamps[:1]]
    if stamps:  # a logger's date-times (LabVIEW, data loggers): seconds (._timestamps)
        notes = [f"time from the date-times of '{table.names[stamps[0]]}'"]
        table.names[stamps[0]] = _TIME
        return notes
    if any(n.startswith(("field.", "%time", "header.stamp")) for n in lower):
        return _ros(table, lower)
    if lower and lower[0] == "__time":
        return _plotjuggler(table, lower)
    if lower and lower[0] == "timestamp" and _integers(table.columns[0][:50]) is not None:
        return _px4(table, lower)
    at = lower.index("timestamp") if "timestamp" in lower else None
    if at is not None and (rel := _epoch_seconds(table.columns[at])) is not None:
        # a Python logger's time.time(): decimal seconds since 1970
        table.columns[at], table.names[at] = rel, f"{_TIME} [s]"
        return ["time from 'timestamp' in s since 1970 (its size), relative to the first row"]
    return []


def _epoch_seconds(column) -> np.ndarray | None:
    """Text cells of decimal seconds since 1970 (``time.time()`` printed: 1.5e9-2.5e9, with
    a decimal point) as text seconds after the first, exact (decimal arithmetic: float64
    keeps only ~0.2 µs at 1.7e9 s); ``None`` for anything else."""
    cells = [str(c).strip() for c in column]
    if not cells or not all("." in c for c in cells[:50]):
        return None
    try:
        values = [Decimal(c) for c in cells]
        if not all(Decimal("1.5e9") <= v <= Decimal("2.5e9") for v in values):
            return None
    except InvalidOperation:  # an empty cell, NaN, words
        return None
    return np.array([str(v - values[0]) for v in values], dtype=object)


def _has_angle(table) -> bool:
    return any(header_key(n)[0] in (_THETA, _COUNTS) for n in table.names)


def _ros(table, lower: list[str]) -> list[str]:
    notes, taken = [], None
    for secs, nsecs in _ROS_STAMP_PAIRS:
        if secs in lower and nsecs in lower:
            s = _integers(table.columns[lower.index(secs)])
            ns = _integers(table.columns[lower.index(nsecs)])
            if s is not None and ns is not None:
                at = lower.index(secs)
                table.columns[at] = _relative([a * 1_000_000_000 + b for a, b in zip(s, ns)])
                taken = (f"'{table.names[at]}' + '{table.names[lower.index(nsecs)]}'", True)
                table.names[at] = f"{_TIME} [ns]"
                break
    for name in () if taken else _ROS_STAMPS:
        if name in lower:
            at = lower.index(name)
            ticks = _integers(table.columns[at])
            if ticks is not None:
                table.columns[at] = _relative(ticks)
                taken = (f"'{table.names[at]}'", "stamp" in name)
                table.names[at] = f"{_TIME} [ns]"
                break
    if taken:
        what = ("the sample's header stamp" if taken[1]
                else "the recorder's receipt: no header stamp")
        notes.append(f"ROS log: time from {taken[0]} in ns ({what}), relative to the first "
                     "message")
    if not _has_angle(table):
        joints = [n for n in lower if n.startswith("field.position") and n != "field.position0"]
        if joints and "field.position0" in lower:
            raise LogError(
                f"a joint state of {len(joints) + 1} joints ('field.position0', "
                f"{', '.join(repr(table.names[lower.index(n)]) for n in joints)}): rename the "
                "column of the joint to fit 'theta'", path=table.path)
        for name in _ROS_ANGLES:
            if name in lower and not (name == "field.position0" and joints):
                at = lower.index(name)
                notes.append(f"ROS log: angle from '{table.names[at]}' [rad]")
                table.names[at] = _THETA
                break
    return notes


def _plotjuggler(table, lower: list[str]) -> list[str]:
    """PlotJuggler's CSV export: ``__time`` in seconds since 1970, one column per plotted
    series named by its path (``/joint_states/wg_joint/position``)."""
    table.names[0] = _TIME
    notes = ["PlotJuggler export: time from '__time' [s]"]
    if not _has_angle(table):
        found = [i for i, n in enumerate(lower)
                 if n.rsplit("/", 1)[-1] in ("position", "position[0]", "data")]
        if len(found) == 1:
            notes.append(f"PlotJuggler export: angle from '{table.names[found[0]]}' [rad]")
            table.names[found[0]] = _THETA
        elif found:
            raise LogError(
                f"{len(found)} position series ({', '.join(repr(table.names[i]) for i in found)})"
                ": rename the one to fit 'theta'", path=table.path)
    return notes


#: Integer stamps since 1970 in each unit, now (2017-2049: 1.5e9-2.5e9 s).
_EPOCH = (("ns", 10**9), ("us", 10**6), ("ms", 10**3), ("s", 1))
#: Fewest µs between samples of a log stamped in µs since boot (50 kHz): finer steps
#: are no µs (an Arduino's millis() printed as a 'timestamp').
_MIN_US_STEP = 20


def _px4(table, lower: list[str]) -> list[str]:
    """An integer ``timestamp`` first column: since 1970 in the unit its size says (a
    rosbag2 export's ns, 1.7e18), else µs since boot (PX4's ulog)."""
    ticks = _integers(table.columns[0])
    first = ticks[0]
    unit = next((u for u, per_s in _EPOCH if 1.5e9 * per_s <= first <= 2.5e9 * per_s), None)
    if unit is not None:
        what = f"in {unit} since 1970 (its size)"
    else:
        steps = np.diff(np.asarray(ticks[:1000], dtype=np.float64))
        step = float(np.median(steps)) if steps.size else 0.0
        if 0 < step < _MIN_US_STEP:
            raise LogError(
                f"'{table.names[0]}' of whole numbers {step:g} apart: as µs since boot (PX4's "
                f"ulog) that is {1e3 / step:g} kHz sampling — name its unit in the header "
                "('timestamp [ms]')", path=table.path, column=table.names[0])
        unit, what = "us", "in µs since boot (PX4 ulog's convention)"
    table.columns[0] = _relative(ticks)
    table.names[0] = f"{_TIME} [{unit}]"
    notes = [f"time from 'timestamp' {what}, relative to the first row"]
    if _PX4_ANGLE in lower and not _has_angle(table):
        at = lower.index(_PX4_ANGLE)
        notes.append(f"PX4 log: angle from '{table.names[at]}' in encoder counts")
        table.names[at] = _COUNTS
    return notes
