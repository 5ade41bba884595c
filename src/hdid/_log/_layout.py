"""Where the table lies in a logger's text file.

Loggers, controllers and spreadsheets put more than the table in a log file: a preamble
before the header (``# station 4, 2026-11-27``, ``Date: …``), comment lines (``#``) and
whitespace-only lines among the rows or as a footer, a units row under the header
(``,,s,rad``), the header repeated where logs were written one after another, a text
footer (``END``), and — when the logger was stopped mid-write — a last line cut short. This
module finds the header line and the delimiter, empties the lines that are not rows (so
that every row keeps its file line number for the messages), reads a units row into the
header names, and drops a cut last line with a note. It only reads text: the numbers are
parsed by :mod:`._table`.
"""

from __future__ import annotations

import re

import numpy as np

from .. import _units
from ._headers import header_key
from ._names import _COUNTS, _NA_TOKENS, _RUN_COLUMN, _THETA, _TIME

#: Lines searched for the header below a preamble.
_HEADER_SEARCH_LINES = 200
#: A cell that reads as a number (a units row has none).
_NUMBER = re.compile(r"^\s*[-+]?(\d+[.,]?\d*|[.,]\d+)([eE][-+]?\d+)?\s*$")


#: The delimiter of a file whose cells are separated by spaces (``.dat``/``.txt`` exports).
WHITESPACE = r"\s+"


def _line_sep(line: str) -> str:
    """The delimiter of a header line: ``;`` or a tab when it has one of those and no
    comma (a European export), runs of spaces when it has none of the three but two or
    more names, else ``,``."""
    if "," not in line:
        if ";" in line:
            return ";"
        if "\t" in line:
            return "\t"
        if len(_glued_units(line).split()) >= 2:
            return WHITESPACE
    return ","


def _glued_units(line: str) -> str:
    """A space-separated header with its units glued to the names: ``time [s] theta (deg)``
    → ``time[s] theta(deg)`` (spaces inside the brackets dropped too)."""
    line = re.sub(r"\s+([\[(])", r"\1", line)
    return re.sub(r"[\[(][^\])]*[\])]", lambda m: re.sub(r"\s+", "", m.group(0)), line)


def _cells(line: str, sep: str) -> list[str]:
    parts = _glued_units(line).split() if sep == WHITESPACE else line.split(sep)
    return [c.strip().strip('"').strip() for c in parts]


#: What starts a comment line: ``#`` (shells, Python, numpy.savetxt) or ``%`` (MATLAB).
_COMMENT = ("#", "%")


#: First characters of a line that may be a comment or whitespace only.
_MAY_START_A_NON_ROW = frozenset("#% \t\r\ufeff\v\f")


def _is_comment(line: str) -> bool:
    return line.lstrip().lstrip("\ufeff").startswith(_COMMENT)


def _uncommented(line: str) -> str:
    return line.lstrip().lstrip("\ufeff").lstrip("#%").strip()


def _names_time_and_angle(line: str) -> bool:
    """A time column and an angle column, or two or more angle columns labelled with
    their runs (a wide export: ``time [s], theta_1 [deg], theta_2 [deg]``)."""
    keys = [header_key(c)[0] for c in _cells(line, _line_sep(line))]
    wide = sum(_RUN_COLUMN.match(k) is not None for k in keys) >= 2
    return _TIME in keys and (_THETA in keys or _COUNTS in keys or wide)


def _is_ros_header(line: str) -> bool:
    """``%time,field.header.seq,…``: the header ``rostopic echo -p`` writes, no comment."""
    return line.startswith("%time") and "field." in line


def find_header(lines: list[str]) -> tuple[int, str]:
    """Index of the header line and the delimiter.

    The header is the first line (not blank, not a ``#`` or ``%`` comment) that names both
    a time and an angle column; the lines above it are a preamble. Failing that, it is the
    first comment line that names them (``# time,theta`` from ``numpy.savetxt``), its
    comment mark dropped. When no line among the first :data:`_HEADER_SEARCH_LINES` does,
    it is the line (not blank, a comment or a ``key: value`` preamble line) followed by the
    longest run of numeric rows with its cell count, else the first line that is not blank
    or a comment (so that a header lacking a required column is named in the error as it
    is, not a preamble's ``Operator: HV``).
    """
    first = None
    for i, line in enumerate(lines[:_HEADER_SEARCH_LINES]):
        if _is_ros_header(line):  # ``rostopic echo -p``: '%time' is a column (._tools)
            return i, _line_sep(line)
        if not line.strip() or _is_comment(line):
            continue
        if first is None:
            first = i
        if _names_time_and_angle(line):
            sep = _line_sep(line)
            if sep == WHITESPACE:  # one cell per name: ``time [s]`` → ``time[s]``
                lines[i] = _glued_units(line)
            return i, sep
    # a header written as a comment (numpy.savetxt's ``# time,theta``, MATLAB's ``%``)
    for i, line in enumerate(lines[:_HEADER_SEARCH_LINES]):
        if _is_comment(line) and _names_time_and_angle(_uncommented(line)):
            lines[i] = _uncommented(line)
            sep = _line_sep(lines[i])
            if sep == WHITESPACE:
                lines[i] = _glued_units(lines[i])
            return i, sep
    if first is None:  # only blank or comment lines: the caller says so
        first = next((i for i, line in enumerate(lines) if line.strip()), 0)
        return first, _line_sep(lines[first]) if lines else ","
    # no line names the columns: the header is the line above the longest run of numeric
    # rows with its cell count, so that a preamble (``Operator: HV``) is not taken for it
    # and the error names the file's real columns
    best, most = first, 0
    for i in range(first, min(len(lines), _HEADER_SEARCH_LINES)):
        line = lines[i]
        if not line.strip() or _is_comment(line) or _KEY_VALUE.match(line):
            continue
        run = _numeric_run(lines, i)
        if run > most:
            best, most = i, run
    return best, _line_sep(lines[best])


#: A preamble line ``Operator: HV``, ``Date: 2026-11-27`` (a name, a colon, a value).
_KEY_VALUE = re.compile(r"^\s*[A-Za-z][\w .()/-]*:\s+\S[^,;\t]*$")
#: Rows looked at below a header candidate (enough to tell a header from a preamble).
_RUN_PROBE = 20


def _numeric_run(lines: list[str], i: int) -> int:
    """How many rows below line ``i`` (one units row under it allowed; blank and comment
    lines skipped) have its cell count and only numbers (or missing-value marks)."""
    sep = _line_sep(lines[i])
    n = len(_cells(lines[i], sep))
    run, j, units = 0, i + 1, True
    while j < len(lines) and run < _RUN_PROBE:
        line = lines[j]
        j += 1
        if not line.strip() or _is_comment(line):
            continue
        cells = _cells(line, sep)
        numbers = [c for c in cells if c and c.lower() not in _NA_TOKENS]
        numeric = bool(numbers) and all(_NUMBER.match(c) for c in numbers)
        if len(cells) != n or not numeric:
            if units and run == 0 and len(cells) == n:  # a units row: ``[us],counts``
                units = False
                continue
            break
        run += 1
    return run


def blank_non_rows(lines: list[str], header_at: int) -> int:
    """Empty (in place) the preamble above the header, every ``#`` comment line and every
    whitespace-only line below it; return how many preamble and comment lines there were."""
    dropped = 0
    for i, line in enumerate(lines):
        if i == header_at or not line:
            continue
        if i > header_at and line[0] not in _MAY_START_A_NON_ROW:
            continue  # a row (the quick test for most lines)
        if i < header_at or _is_comment(line):
            dropped += bool(line.strip())
            lines[i] = ""
        elif not line.strip():
            lines[i] = ""
    return dropped


def blank_repeated_headers(lines: list[str], header_at: int, sep: str) -> list[int]:
    """Empty (in place) the lines below the header that repeat it — logs of several runs
    written one after another into one file (``cat run1.csv run2.csv``), each with its
    header (and byte-order mark) — and return their indices."""
    head = _cells(lines[header_at].lstrip("\ufeff"), sep)
    last = head[-1]  # a quick test before the cells are compared
    repeats = []
    for i in range(header_at + 1, len(lines)):
        if last in lines[i] and _cells(lines[i].lstrip("\ufeff"), sep) == head:
            lines[i] = ""
            repeats.append(i)
    return repeats


def runs_of_repeated_headers(repeats: np.ndarray | None, block: np.ndarray | None,
                             run_labels: np.ndarray | None
                             ) -> tuple[np.ndarray | None, list[str]]:
    """Run labels and a note for a file whose header repeats (``repeats``: their file line
    numbers; ``block``: per row, the repeats above it). Without a run column each log is a
    run, labelled ``'1'``, ``'2'``, …; with one, the rows keep their labels."""
    if repeats is None or repeats.size == 0:
        return run_labels, []
    shown = ", ".join(str(r) for r in repeats[:5])
    more = f" and {repeats.size - 5} more" if repeats.size > 5 else ""
    what = "the rows keep their 'run' labels"
    if run_labels is None:
        run_labels = np.array([str(b + 1) for b in block], dtype=object)
        what = f"each log is a run ('1' … '{repeats.size + 1}')"
    return run_labels, [f"the header repeats at row(s) {shown}{more}: several logs written "
                        f"one after another; {what}"]


def _decimals(cell: str) -> int | None:
    cell = cell.strip()
    if not _NUMBER.match(cell) or "e" in cell.lower():
        return None
    for mark in ".,":
        if mark in cell:
            return len(cell) - cell.index(mark) - 1
    return 0


def cut_last_line(text: str, lines: list[str], header_at: int, sep: str) -> str | None:
    """Empty a last line that a logger stopped mid-write and return a note, else None.

    Only a last line without a line end can be cut. It is cut when it has fewer cells than
    the header, an empty last cell, or a last cell printed to fewer decimals than every one
    of the (up to 20) rows above it, which all print the same number of decimals.
    """
    if text.endswith(("\n", "\r")):
        return None
    last = max((i for i, line in enumerate(lines) if line.strip()), default=-1)
    if last <= header_at or last != len(lines) - 1:
        return None
    n_header = len(_cells(lines[header_at], sep))
    cells = _cells(lines[last], sep)
    if _is_comment(lines[last]) or not any(_NUMBER.match(c) for c in cells):
        return None  # a comment or a footer of words, not a row
    why = None
    if len(cells) < n_header:
        why = f"{len(cells)} of the header's {n_header} cells"
    elif cells[-1] == "":
        why = "an empty last cell"
    else:
        above = [_cells(line, sep) for line in lines[header_at + 1 : last] if line.strip()][-20:]
        d_above = {_decimals(c[-1]) for c in above if len(c) == len(cells)}
        d_last = _decimals(cells[-1])
        if (len(d_above) == 1 and None not in d_above and d_last is not None
                and d_last < next(iter(d_above))):
            why = (f"its last cell {cells[-1]!r} printed to {d_last} decimals where the rows "
                   f"above print {next(iter(d_above))}")
    if why is None:
        return None
    lines[last] = ""
    return (f"the last line (row {last + 1}) has no line end and {why}: the logger stopped "
            "while writing it — dropped")


def text_footer(names: list[str], raw: list[np.ndarray], keep: np.ndarray,
                header_at: int) -> tuple[np.ndarray, str | None]:
    """Drop a footer: the last rows of the file whose time cell is words (``Samples: 500``,
    ``End of data``; not a number, a date or a missing-value token), or that hold words and
    no number at all (``END`` in the first cell).
    Returns the rows kept and a note naming the footer (None without one)."""
    at = next((i for i, n in enumerate(names) if header_key(n)[0] == _TIME), None)
    if at is None:
        return keep, None
    n = keep.size
    def words(cell: str) -> bool:
        return bool(re.match(r"^[^\W\d_]", cell)) and cell.lower() not in _NA_TOKENS

    while n > 0:
        row = [str(values[keep[n - 1]]).strip() for values in raw]
        if not (words(row[at]) or (any(words(c) for c in row)
                                   and not any(_NUMBER.match(c) for c in row))):
            break
        n -= 1
    if n == keep.size or n == 0:
        return keep, None
    first = int(keep[n]) + 1 + header_at
    shown = next(c for c in (str(v[keep[n]]).strip() for v in raw) if c)
    return keep[:n], (f"the file ends in a footer of words from row {first} "
                      f"({shown[:30]!r}): not data — dropped")


def units_row(names: list[str], raw: list[np.ndarray], keep: np.ndarray
              ) -> tuple[list[str], np.ndarray]:
    """Read a units row under the header (``,,s,rad``, ``[s];[deg]``) into the names.

    The first row below the header is a units row when none of its cells is a number and
    the time or the angle column's cell is a unit that column knows. Its units are written
    into the header names (``time`` → ``time [s]``) where the header gives none, and the
    row is dropped. An unknown unit there becomes the header's unit, so that the column's
    unknown-unit error names it.
    """
    if keep.size == 0:
        return names, keep
    row = [str(values[keep[0]]).strip() for values in raw]
    if any(_NUMBER.match(c) for c in row if c):
        return names, keep
    units = [c[1:-1].strip() if c[:1] in "[(" and c[-1:] in "])" else c for c in row]
    # an angle column per run (``theta_1``) takes an angle's units, as ``theta`` does
    keys = [(_THETA if _RUN_COLUMN.match(k) else k, unit)
            for k, unit in (header_key(n) for n in names)]
    if not any(k in (_TIME, _THETA) and unit is None and u and _units.scale(k, u) is not None
               for (k, unit), u in zip(keys, units)):
        return names, keep
    out = list(names)
    for i, ((key, unit), u) in enumerate(zip(keys, units)):
        if unit is None and u and key in _units.UNITS:
            out[i] = f"{names[i]} [{u}]"
    return out, keep[1:]
