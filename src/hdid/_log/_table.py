"""Loading a CSV file or a DataFrame into a table of text cells and numbers."""

from __future__ import annotations

import gzip
import io
import os
import re
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from .._errors import LogError
from . import _layout
from ._lvm import fill_lvm_time
from ._mat import load_mat_frame
from ._scope import scope_header
from ._serial import from_serial
from ._names import _NA_TOKENS


# ---------------------------------------------------------------------- loading


@dataclass
class _Table:
    """Raw table: stripped header names, raw column values and CSV line numbers.

    ``columns`` holds object arrays of the cell text (CSV input) or the
    DataFrame's own columns.
    """

    source: str
    path: str | os.PathLike[str] | None
    names: list[str]
    columns: list[np.ndarray | pd.Series]
    lines: np.ndarray
    #: What the reader made of lines that are not rows (a cut last line), for the log's notes.
    notes: list[str] = field(default_factory=list)
    #: File line numbers of the header's repeats, and per row the number of repeats above
    #: it (the file is several logs one after another when there are any).
    header_repeats: np.ndarray | None = None
    block: np.ndarray | None = None


def _show(text: object, limit: int = 20) -> str:
    """Quote a cell's text for a message: truncated, escaped, one line."""
    text = str(text)
    if len(text) > limit:
        text = text[:limit] + "…"
    return repr(text)


#: Bytes read to recognise the file type and the delimiter before parsing.
_SNIFF_BYTES = 65536
#: A number written with a decimal comma (``-0,157``, ``1,5e-3``).
_DECIMAL_COMMA = re.compile(r"^\s*[-+]?\d*,\d+(?:[eE][-+]?\d+)?\s*$")


def _sniff(head: bytes, err) -> None:
    """Recognise what the file is from its first bytes.

    Spreadsheets renamed ``.csv``, UTF-16 text, other 8-bit encodings and binary
    files get a one-line error naming what the file is.
    """
    if head.startswith(b"PK\x03\x04") or head.startswith(b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1"):
        raise err(
            "this is a spreadsheet (Excel/OpenDocument) file, not CSV text — in the "
            "spreadsheet program use 'Save as' CSV (comma-separated)"
        )
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or (
        len(head) >= 4 and head[1::2].count(0) > len(head) // 4 and head[0::2].count(0) == 0
    ) or (len(head) >= 4 and head[0::2].count(0) > len(head) // 4 and head[1::2].count(0) == 0):
        raise err("this is UTF-16 text — save the log as a UTF-8 CSV file (comma-separated)")
    if head.startswith(b"MATLAB 5.0 MAT-file") or head.startswith(b"\x89HDF\r\n"):
        raise err("this is a MATLAB .mat file, not CSV text — give it the .mat extension "
                  "(hdid reads its vectors by name) or export a CSV file")
    if b"\x00" in head:
        raise err("this is a binary file, not a CSV text file — give the exported CSV log")
    try:
        text = head.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        if exc.start >= len(head) - 3 and len(head) == _SNIFF_BYTES:
            text = head[: exc.start].decode("utf-8-sig")  # a character cut at the end
        elif sum(b < 9 or 13 < b < 32 for b in head) > len(head) // 100:
            raise err(
                "this is a binary file, not a CSV text file — give the exported CSV log"
            ) from None
        else:
            raise err(
                "this text is not UTF-8 (Latin-1 or Windows-1252?) — save the log as a "
                "UTF-8 CSV file (comma-separated)"
            ) from None
    if sum(ord(c) < 9 or 13 < ord(c) < 32 for c in text) > len(text) // 100:
        raise err("this is a binary file, not a CSV text file — give the exported CSV log")


def _read_text(path, err, serial: list | None = None) -> str:
    """The file's text (UTF-8, a byte-order mark dropped; a gzip-compressed file
    uncompressed; a serial capture of ``key=value`` records as CSV, its notes and line
    shift appended to ``serial``: :mod:`._serial`), or a LogError naming why not."""
    try:
        with open(path, "rb") as fh:
            data = fh.read()
    except FileNotFoundError:
        raise err("file not found — check the path") from None
    except IsADirectoryError:
        raise err("is a directory, not a CSV file — give the path of the log file") from None
    except PermissionError:
        raise err("cannot read the file (permission denied) — check its permissions") from None
    except OSError as exc:
        raise err(f"cannot read the file ({exc.strerror or exc}) — check the path") from None
    if data.startswith(b"\x1f\x8b"):  # a gzip-compressed log (log.csv.gz)
        try:
            data = gzip.decompress(data)
        except (OSError, EOFError, ValueError):
            raise err("this gzip file is damaged or cut short — compress the log again, or "
                      "give the uncompressed CSV file") from None
    captured = from_serial(data, path)
    if captured is not None:
        data = captured[0]
        if serial is not None:
            serial.extend(captured[1:])
    _sniff(data[:_SNIFF_BYTES], err)
    try:
        return data.decode("utf-8-sig")
    except UnicodeDecodeError as exc:
        row = data[: exc.start].count(b"\n") + 1
        raise err(
            f"line {row} is not UTF-8 text (Latin-1 or Windows-1252?) — save the log as a "
            "UTF-8 CSV file (comma-separated)"
        ) from None


def _workbook_text(path: str, err) -> str:
    """The first sheet of an Excel workbook (``.xlsx``) as CSV text, read with openpyxl
    (an optional dependency: without it, the error says how to get it)."""
    try:
        import openpyxl  # noqa: F401
    except ImportError:
        raise err("this is an Excel workbook and the package that reads it is not "
                  "installed — pip install openpyxl, or export the sheet as CSV") from None
    try:
        frame = pd.read_excel(path, sheet_name=0, header=None, dtype=object)
    except Exception as exc:
        raise err(f"cannot read the Excel workbook ({type(exc).__name__}: {_show(exc, 80)}) "
                  "— export the sheet as CSV (comma-separated)") from None
    frame = frame.map(lambda c: "" if c is None or (isinstance(c, float) and c != c)
                      else c.isoformat() if hasattr(c, "isoformat") else repr(c)
                      if isinstance(c, float) else str(c))
    return frame.to_csv(header=False, index=False, lineterminator="\n")


def _decimal_commas(values: np.ndarray) -> np.ndarray:
    """Cells like ``0,157`` as ``0.157`` (a ';'- or tab-separated European export)."""
    cells = pd.Series(values, dtype=object)
    has = cells.str.contains(",", regex=False, na=False)
    if not has.any():
        return values
    hit = cells[has]
    match = hit.str.match(_DECIMAL_COMMA, na=False)
    cells.loc[match[match].index] = hit[match].str.replace(",", ".", regex=False)
    return cells.to_numpy(dtype=object)


#: Digit grouping: ``12,345`` or ``1,234.5`` (',' groups, '.' decimal) and ``12.345`` or
#: ``1.234,5`` ('.' groups, ',' decimal).
_GROUPED = {",": re.compile(r"^\s*[-+]?\d{1,3}(?:,\d{3})+(?:\.\d*)?\s*$"),
            ".": re.compile(r"^\s*[-+]?\d{1,3}(?:\.\d{3})+(?:,\d*)?\s*$")}
#: A number with a decimal point that is no digit grouping (``0.157``, ``4.0``).
_DECIMAL_POINT = re.compile(r"^\s*[-+]?\d*\.\d+(?:[eE][-+]?\d+)?\s*$")
#: A time of day with a decimal comma (``10:00:00,004``: a European export).
_CLOCK_COMMA = re.compile(r"^\s*\d{1,2}:\d{2}:\d{2},\d+\s*$")


def _number_format(raw: list[np.ndarray]) -> list[np.ndarray]:
    """The cells of a ';'- or tab-separated file with its own number format read as plain
    numbers: decimal commas (``0,157``, ``10:00:00,004``) and digit grouping (``12,345``
    where the file's other numbers show a decimal point; ``1.234,5``). A file has one
    decimal separator: cells that can only be read with a point (``4.0``) and none that
    can only be read with a comma (``0,1571``) make every comma a grouping mark, and the
    other way round. Only the cells holding the mark in question are matched."""
    cells = [pd.Series(v, dtype=object).astype(str) for v in raw]
    commas = [c.str.contains(",", regex=False).to_numpy() for c in cells]
    if not any(m.any() for m in commas):
        return raw  # no decimal comma, no ',' grouping, hence no '.' grouping either
    dots = [c.str.contains(".", regex=False).to_numpy() for c in cells]

    def only(mark: str) -> bool:
        """Some cell reads only with ``mark`` as the decimal separator: a decimal that is
        no digit grouping of the other kind (``0.1571``), or a grouped number with a
        decimal part (``1,004.0``)."""
        other = "," if mark == "." else "."
        decimal = _DECIMAL_POINT if mark == "." else _DECIMAL_COMMA
        for c, dot, comma in zip(cells, dots, commas):
            has, has_other = (dot, comma) if mark == "." else (comma, dot)
            sub = c[has]
            if sub.empty:
                continue
            if (sub.str.match(decimal) & ~sub.str.match(_GROUPED[mark])).any():
                return True
            both = c[has & has_other]
            if not both.empty and both.str.match(_GROUPED[other]).any():
                return True
        return False

    point, comma = only("."), only(",")
    out = []
    for c, values, dot, has_comma in zip(cells, raw, dots, commas):
        if point and not comma:  # ',' groups digits
            if has_comma.any():
                hit = np.flatnonzero(has_comma)[c[has_comma].str.match(_GROUPED[","]).to_numpy()]
                values = values.copy()
                values[hit] = c.iloc[hit].str.replace(",", "", regex=False).to_numpy()
        elif has_comma.any():
            if comma and not point and dot.any():  # '.' groups digits
                hit = np.flatnonzero(dot)[c[dot].str.match(_GROUPED["."]).to_numpy()]
                values = values.copy()
                values[hit] = c.iloc[hit].str.replace(".", "", regex=False).to_numpy()
            values = _decimal_commas(values)
            text = pd.Series(values, dtype=object).astype(str)
            clock = text.str.contains(":", regex=False).to_numpy().copy()
            if clock.any():
                clock[clock] = text[clock].str.match(_CLOCK_COMMA).to_numpy()
                values = values.copy()
                values[clock] = [v.replace(",", ".") for v in values[clock]]
        out.append(values)
    return out


def _load_csv(path: str | os.PathLike[str]) -> _Table:
    source = os.fspath(path)
    err = lambda message, **kw: LogError(message, path=path, **kw)  # noqa: E731
    suffix = Path(source).suffix.lower()
    if suffix == ".mat":  # MATLAB vectors named like the columns (hdid._log._mat)
        return _load_frame(load_mat_frame(path), source=source, path=path)
    if suffix in {".xls", ".ods"}:
        raise err("this is a spreadsheet, not a CSV file — export it as CSV (comma-separated)")
    serial: list = []
    text = (_workbook_text(source, err) if suffix in {".xlsx", ".xlsm"}
            else _read_text(source, err, serial))
    notes, shift = (serial[0], serial[1]) if serial else ([], 0)
    text = fill_lvm_time(text)  # a LabVIEW file whose rows lack their times (hdid._log._lvm)
    if not text:
        raise err("file is empty — expected a CSV file with a header line such as 'time,theta'")
    if not text.strip():
        raise err("file holds only blank lines — expected a header line such as 'time,theta'")
    # the header below any preamble; comment, preamble and whitespace-only lines emptied,
    # a cut last line dropped (hdid._log._layout); every row keeps its file line number
    lines = text.split("\n")
    notes = notes + scope_header(lines, path)  # a TwinCAT Scope export's header (._scope)
    header_at, sep = _layout.find_header(lines)
    cut = _layout.cut_last_line(text, lines, header_at, sep)
    if cut is not None:
        notes.append(cut)
    _layout.blank_non_rows(lines, header_at)
    repeats = np.asarray(_layout.blank_repeated_headers(lines, header_at, sep), dtype=np.int64)
    try:
        # header=None: the header line is handled here, so that names are not
        # mangled by pandas and frame row i is exactly file line i + 1.
        frame = pd.read_csv(
            io.StringIO("\n".join(lines)),
            header=None,
            skiprows=header_at,  # the preamble (pandas cannot start at a blank line)
            sep=sep,
            dtype=object,
            keep_default_na=False,
            na_filter=False,
            skip_blank_lines=False,
            engine="c",
        )
    except pd.errors.EmptyDataError:
        raise err(
            "file is empty — expected a CSV file with a header line such as 'time,theta'"
        ) from None
    except pd.errors.ParserError as exc:
        raise _parser_error(exc, path) from None
    except Exception as exc:  # pandas may raise assorted errors on garbage input
        raise err(
            f"cannot parse the file as CSV ({type(exc).__name__}: {_show(exc, 80)}) — "
            "check that it is a comma-separated text file with a header line"
        ) from None

    raw = [frame[col].to_numpy(dtype=object) for col in frame.columns]
    if sep != ",":
        raw = _number_format(raw)
    blank = np.ones(len(frame), dtype=bool)
    for values in raw:
        blank &= values == ""
    nonblank = np.flatnonzero(~blank)
    if nonblank.size == 0:
        raise err("file holds only blank lines — expected a header line such as 'time,theta'")
    first = int(nonblank[0])  # the header line (frame row 0 is file line header_at + 1)
    names = [str(values[first]).strip() for values in raw]
    names, keep = _layout.units_row(names, raw, nonblank[1:])
    keep, footer = _layout.text_footer(names, raw, keep, header_at)
    notes += [footer] if footer else []
    rows = keep.astype(np.int64) + 1 + header_at - shift
    return _Table(source, path, names, [values[keep] for values in raw], rows, notes,
                  repeats + 1, np.searchsorted(repeats + 1, rows))


def _parser_error(exc: Exception, path) -> LogError:
    text = " ".join(str(exc).split())
    m = re.search(r"Expected (\d+) fields in line (\d+), saw (\d+)", text)
    if m:
        expected, line, saw = (int(g) for g in m.groups())
        return LogError(
            f"has {saw} cells but the header has {expected} — check the delimiter and "
            "quoting, or remove the extra cells",
            path=path,
            row=line,
        )
    m = re.search(r"inside string starting at row (\d+)", text)
    if m:
        return LogError(
            "a quote (\") opened here is never closed — remove or close the quote",
            path=path,
            row=int(m.group(1)) + 1,
        )
    return LogError(
        f"cannot parse the file as CSV ({_show(text, 80)}) — check that it is a "
        "comma-separated text file with a header line",
        path=path,
    )


def _load_frame(frame: pd.DataFrame, source: str = "<DataFrame>", path=None) -> _Table:
    names = [str(c).strip() for c in frame.columns]
    columns = [frame.iloc[:, i] for i in range(frame.shape[1])]
    lines = np.arange(2, len(frame) + 2, dtype=np.int64)
    return _Table(source, path, names, columns, lines)


# ---------------------------------------------------------------------- parsing


def _cell_text(cell: object) -> str:
    """Stripped text of one raw cell ('' for a missing value)."""
    if cell is None:
        return ""
    if not isinstance(cell, str):
        try:
            if pd.isna(cell):
                return ""
        except (TypeError, ValueError):
            pass
    return str(cell).strip()


def _exact(raw: np.ndarray, values: np.ndarray) -> np.ndarray:
    """``values`` with every finite text cell re-read by Python's ``float`` (correctly
    rounded). pandas' fast text-to-float parser is not: pandas 3.0.6 read
    ``repr(0.036)`` as 0.036000000000000004, one unit in the last place off, so a log
    written with ``repr`` would not read back to the same numbers. ``to_numeric`` still
    decides which cells are numbers."""
    ok = np.isfinite(values)
    try:
        values[ok] = np.asarray(raw[ok], dtype=np.float64)  # float() of each cell, in C
    except (TypeError, ValueError):  # a form pandas reads and Python does not: cell by cell
        for i in np.flatnonzero(ok):
            try:
                values[i] = float(raw[i])
            except (TypeError, ValueError):
                pass
    return values


class _Cells:
    """Parses columns and remembers the first bad cell (earliest row, then column)."""

    def __init__(self, table: _Table) -> None:
        self.table = table
        self.first_bad: tuple[int, int, str] | None = None  # (row_pos, col_idx, message)

    def _note(self, pos: int, col: int, msg: str) -> None:
        if self.first_bad is None or (pos, col) < self.first_bad[:2]:
            self.first_bad = (pos, col, msg)

    def labels(self, col: int) -> np.ndarray:
        """Column as an object array of stripped label strings."""
        raw = self.table.columns[col]
        codes, uniques = pd.factorize(np.asarray(raw, dtype=object), use_na_sentinel=False)
        text = np.array([_cell_text(u) for u in uniques], dtype=object)
        values = text[codes]
        empty = values == ""
        if empty.any():
            self._note(int(np.argmax(empty)), col, "cell is empty — fill it or drop the row")
        return values

    def numbers(self, col: int) -> np.ndarray:
        """Column as float64; non-finite entries mark bad cells."""
        column = self.table.columns[col]
        if (
            isinstance(column, pd.Series)
            and pd.api.types.is_numeric_dtype(column.dtype)
            and not pd.api.types.is_bool_dtype(column.dtype)
        ):
            values = column.to_numpy(dtype=np.float64, na_value=np.nan)
            raw = None
        else:
            raw = np.asarray(column, dtype=object)
            if isinstance(column, pd.Series) and pd.api.types.is_bool_dtype(column.dtype):
                raw = raw.astype(str)  # True/False are not numbers here
            values = np.asarray(pd.to_numeric(raw, errors="coerce"), dtype=np.float64)
            values = _exact(raw, values)
        bad = ~np.isfinite(values)
        if bad.any():
            pos = int(np.argmax(bad))
            text = None if raw is None else _cell_text(raw[pos])
            self._note(pos, col, self._describe(values[pos], text))
        return values

    @staticmethod
    def _describe(value: float, text: str | None) -> str:
        if np.isinf(value):
            shown = f" ({_show(text)})" if text else ""
            return f"value is infinite{shown} — replace it with a finite number or drop the row"
        if not text:
            return "cell is empty — fill it or drop the row"
        if text.lower() in _NA_TOKENS:
            return f"cell holds the missing value {_show(text)} — fill it or drop the row"
        return (
            f"cell holds the text {_show(text)} where a number is expected — write a "
            "plain number with '.' as decimal separator"
        )

    def raise_first(self) -> None:
        if self.first_bad is not None:
            pos, col, msg = self.first_bad
            raise LogError(
                msg,
                path=self.table.path,
                column=self.table.names[col],
                row=int(self.table.lines[pos]),
            )
