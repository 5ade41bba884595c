"""A microcontroller's serial prints captured to a file: ``t_ms=123 pos=456`` a line.

An Arduino or Teensy sketch prints each sample as ``key=value`` pairs (``Serial.print``);
a terminal program captures the port. Such a capture starts wherever the port was
opened: its first line is usually the tail of a line already under way (``=12 pos=45``),
and a port opened at the wrong baud rate, or a board resetting, writes a few lines of
bytes that are no text at all. Those lines come *before* the first complete record and
are dropped, with a note. Below it every line must be a record with the same keys: a
line that is not (noise on the line, two prints run together) is an error naming it,
because a sample may be missing there. A last line cut mid-print is dropped (noted).

Time keys are read with their unit: ``ms``/``millis`` (``millis()``), ``us``/``micros``
(``micros()``, a 32-bit counter that rolls over every 71.6 min: :mod:`._timer` unwraps
it), or a suffix (``t_ms``, ``time_us``). A bare ``t`` or ``time`` of whole numbers has no
unit a reader can trust (``millis()`` and ``micros()`` print alike): an error with the fix.
"""

from __future__ import annotations

import re

from .._errors import LogError

#: One ``key=value`` (or ``key: value``) pair of a record.
_PAIR = r"([A-Za-z_][\w.\[\]]*)\s*[=:]\s*([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"
_RECORD = re.compile(rf"^\s*{_PAIR}(?:[\s,;\t]+{_PAIR})*[\s,;\t]*$")
_PAIRS = re.compile(_PAIR)
#: Keys that are the time in a unit (``millis()``, ``micros()``).
_TIME_KEYS = {"ms": "time [ms]", "millis": "time [ms]", "us": "time [us]",
              "micros": "time [us]"}
#: Lines of the head that must be records for the file to be read as a capture.
_MIN_RECORDS = 5


def _records(lines: list[bytes]) -> list[tuple[str, ...] | None]:
    """Each line's keys, or ``None`` for a line that is no record (or no text)."""
    out = []
    for raw in lines:
        try:
            line = raw.decode("utf-8").strip("\r")
        except UnicodeDecodeError:
            out.append(None)
            continue
        out.append(tuple(k for k, _ in _PAIRS.findall(line)) if _RECORD.match(line) else None)
    return out


def from_serial(data: bytes, path) -> tuple[bytes, list[str], int] | None:
    """A serial capture as CSV bytes (a header of its keys, one row per record; dropped
    lines left blank so that rows keep their line numbers), the notes and the lines every
    row moved down (0 or 1), or ``None`` when ``data`` is no capture of ``key=value``
    records."""
    if b"=" not in data[:4096] and b": " not in data[:4096]:
        return None
    lines = data.split(b"\n")
    head = _records(lines[:200])
    complete = [k for k in head if k]
    if len(complete) < _MIN_RECORDS:
        return None
    keys = max(set(complete), key=complete.count)  # the sketch's record
    if complete.count(keys) < 0.8 * sum(1 for raw in lines[:200] if raw.strip()):
        return None
    first = head.index(keys)
    keys_of = _records(lines)
    cut_last = not data.endswith(b"\n") and keys_of[-1] != keys
    rows = []
    for i, found in enumerate(keys_of[first:], start=first):
        if found == keys:
            rows.append(",".join(v for _, v in _PAIRS.findall(lines[i].decode("utf-8"))))
        elif not lines[i].strip() or (cut_last and i == len(lines) - 1):
            rows.append("")
        else:
            shown = lines[i][:40].decode("utf-8", "replace")
            raise LogError(
                f"line {shown!r} is not a record like the others "
                f"({' '.join(k + '=…' for k in keys)}): noise on the serial line or two prints run together — delete the line (a "
                "sample may be missing there) or recapture", path=path, row=i + 1)
    values = [r.split(",") for r in rows[:50] if r]
    names = [_time_name(k, [v[j] for v in values], path, first) for j, k in enumerate(keys)]
    notes = []
    if first:
        notes.append(f"serial capture: the first {first} line(s), before the first complete "
                     f"record (a line already under way when the port opened, noise), dropped")
    if cut_last:
        notes.append(f"serial capture: the last line (row {len(lines)}), cut mid-print, dropped")
    # the header on line 1 (a dropped line's place); with none dropped, every row moves
    # down one line, which the caller takes back (``shift``)
    text = "\n".join([",".join(names)] + [""] * max(first - 1, 0) + rows) + "\n"
    return text.encode(), notes, int(first == 0)


def _time_name(key: str, cells: list[str], path, first: int) -> str:
    """The column name of a record's key: a time key with its unit."""
    low = key.lower()
    if low in _TIME_KEYS:
        return _TIME_KEYS[low]
    if low in ("t", "time") and all(c.lstrip("+-").isdigit() for c in cells):
        raise LogError(
            f"the serial record's time key {key!r} gives no unit and millis() and micros() "
            f"print alike — print it as '{key}_ms=' (millis()) or '{key}_us=' (micros()), or "
            "in seconds with decimals", path=path, row=first + 1)
    return key
