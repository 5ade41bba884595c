"""A Beckhoff TwinCAT Scope CSV export: a header block of name/value rows, then the
samples with no header line of their own.

The export (TwinCAT Scope View, "Export to CSV"; tab- or ';'-separated, numbers as the
PC's locale writes them) opens with the record's rows (``Name``, ``File``, ``StartRecord``,
``EndRecord``), then one block of rows per channel, side by side — ``Name``, ``NetId``,
``Port``, ``SampleTime[ms]``, ``SymbolName``, ``Data-Type``, … (``Unit`` where the channel
is scaled) — and then the samples: per channel two cells, the time in milliseconds since
the record's first sample and the value. No line names the columns, so a reader that
looks for a header never finds one.

:func:`scope_header` writes that line from the block: each channel's value column is named
by its symbol's last part (``MAIN.Axis.fPosition`` → ``fPosition``; a channel whose name is
hdid's angle, ``theta`` or ``Position``, becomes the angle) with its ``Unit``, and the time
column of the angle's channel is ``time [ms]``; other channels' times keep a name hdid
ignores. The header takes the place of the block's last row, so rows keep their line
numbers.
"""

from __future__ import annotations

import re

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


def scope_header(lines: list[str]) -> list[str]:
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
    if angle is not None:
        times[angle] = "time [ms]"
    last = block[-1]
    for i in range(names_at, last):
        lines[i] = ""
    lines[last] = sep.join(c for pair in zip(times, names) for c in pair)
    return [f"TwinCAT Scope export: channel(s) {', '.join(repr(n) for n in channel_names)}; "
            f"time [ms] since the record's first sample" + (
                f", angle from {channel_names[angle]!r}" if angle is not None else "")]
