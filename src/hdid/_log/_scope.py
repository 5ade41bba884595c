"""A Beckhoff TwinCAT Scope CSV export: a header block of name/value rows, then the
samples with no header line of their own.

The export (TwinCAT Scope View, "Export to CSV"; tab- or ';'-separated, numbers as the
PC's locale writes them) opens with the record's rows (``Name``, ``File``, ``StartRecord``,
``EndRecord``), then one block of rows per channel, side by side — ``Name``, ``NetId``,
``Port``, ``SampleTime[ms]``, ``SymbolName``, ``Data-Type``, … (``Unit`` where the channel
is scaled) — and then the samples: per channel two cells, the time in milliseconds since
the record's first sample (with "Full Timestamp": a Windows file time, 100 ns ticks since
1601, read relative to the first) and the value. No line names the columns, so a reader
that looks for a header never finds one. An export without a time column per channel
("Timelines: None" or shared) is an error asking for "Timelines: All".

:func:`scope_header` writes that line from the block: each channel's value column is named
by its symbol's last part (``MAIN.Axis.fPosition`` → ``fPosition``; a channel whose name is
hdid's angle, ``theta`` or ``Position``, becomes the angle) with its ``Unit``, and the time
column of the angle's channel is ``time [ms]``; other channels' times keep a name hdid
ignores. The header takes the place of the block's last row, so rows keep their line
numbers.
"""

from __future__ import annotations

import re

from .._errors import LogError
from ._headers import header_key
from ._names import _COUNTS, _THETA

#: Rows of a channel block (first cell), any of which marks the export.
_CHANNEL_ROWS = frozenset({"netid", "port", "sampletime[ms]", "symbolbased", "symbolname",
                           "symbolcomment", "indexgroup", "indexoffset", "data-type",
                           "variablesize", "unit", "offset", "scalefactor", "bitmask"})
#: Lines searched for the block.
_BLOCK_LINES = 60


def _cells(line: str, sep: str) -> list[str]:
    return [c.strip().strip('"').strip() for c in line.rstrip("\r").split(sep)]


#: A time cell above this is a Windows file time (100 ns ticks since 1601: 1.3e17 in
#: 2026), the export's "Full Timestamp" option, not milliseconds since the first sample.
_FILETIME_MIN = 10**16


def _full_timestamps(lines: list[str], data: int, sep: str, col: int) -> bool:
    """Rewrite (in place) the time cells of column ``col`` from Windows file times to ns
    after the first (integer arithmetic: 1.3e17 ticks exceed float64's integers); whether
    they were file times."""
    first = _cells(lines[data], sep)[col]
    if not first.isdigit() or int(first) < _FILETIME_MIN:
        return False
    origin = int(first)
    for i in range(data, len(lines)):
        cells = lines[i].rstrip("\r").split(sep)
        if len(cells) > col and cells[col].strip().isdigit():
            cells[col] = str((int(cells[col].strip()) - origin) * 100)
            lines[i] = sep.join(cells)
    return True


def scope_header(lines: list[str], path=None) -> list[str]:
    """Write a TwinCAT Scope export's header line in place (module notes); the notes.
    Other files are left alone."""
    head = lines[:_BLOCK_LINES]
    sep = next((s for s in ("\t", ";") if any(s in line for line in head)), None)
    if sep is None:
        return []
    firsts = [_cells(line, sep)[0].lower() if line.strip() else "" for line in head]
    block = [i for i, f in enumerate(firsts) if f in _CHANNEL_ROWS]
    if len(block) < 3 or "name" not in firsts or "sampletime[ms]" not in firsts:
        return []
    names_at = max(i for i, f in enumerate(firsts[:block[0]]) if f == "name")
    channel_names = _cells(lines[names_at], sep)[1::2]
    symbols = dict.fromkeys(range(len(channel_names)), "")
    units = dict.fromkeys(range(len(channel_names)), "")
    for i in block:
        cells = _cells(lines[i], sep)
        values = cells[1::2]
        if firsts[i] == "symbolname":
            symbols = dict(enumerate(values))
        elif firsts[i] == "unit":
            units = dict(enumerate(values))
    names, angle = [], None
    for j, name in enumerate(channel_names):
        short = re.split(r"[.\s]", symbols.get(j) or name)[-1] or name
        unit = units.get(j, "")
        label = f"{short} [{unit}]" if unit else short
        if angle is None and header_key(label)[0] in (_THETA, _COUNTS):
            angle = j
        names.append(label)
    times = [f"time of {n}" for n in names]
    last = block[-1]
    data = next((i for i in range(last + 1, len(lines)) if lines[i].strip()), None)
    if data is not None and len(_cells(lines[data], sep)) != 2 * len(names):
        raise LogError(
            f"a TwinCAT Scope export whose rows hold {len(_cells(lines[data], sep))} cells for "
            f"{len(names)} channel(s), not a time and a value each — export it again with "
            "'Timelines: All' (a time column per channel)", path=path, row=data + 1)
    full = False
    if angle is not None:
        times[angle] = "time [ms]"
        if data is not None:
            full = _full_timestamps(lines, data, sep, 2 * angle)
            times[angle] = "time [ns]" if full else times[angle]
    for i in range(names_at, last):
        lines[i] = ""
    lines[last] = sep.join(c for pair in zip(times, names) for c in pair)
    clock = ("Windows file times (100 ns since 1601), relative to the first" if full
             else "time [ms] since the record's first sample")
    return [f"TwinCAT Scope export: channel(s) {', '.join(repr(n) for n in channel_names)}; "
            f"{clock}" + (
                f", angle from {channel_names[angle]!r}" if angle is not None else "")]
