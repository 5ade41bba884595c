"""Reading, validating and writing encoder logs: free-motion and driven.

A free-motion test twists the wave generator (the motor side of the harmonic
drive) by about ±0.157 rad, releases it and logs its encoder at a constant rate
(~250 Hz) while it springs back and sticks. A *log* is a CSV file with a header
line and the columns

``time``
    Sample time [s]; strictly increasing within a run (it may restart at each
    run).
``theta``
    Wave-generator angle [rad], or raw encoder counts when ``counts_per_rev`` is
    given (``counts`` is accepted as an alias in that case).
``run`` (optional)
    Label of the release the row belongs to; the rows of one run must be
    contiguous. Without it the whole file is one run named ``"1"``.
``setup`` (optional)
    Set-up label, constant within a run (default ``"1"``).
``added_inertia`` (optional)
    Known inertia added at the wave generator for this run [kg m^2] (an inertia
    mounted at the output counts divided by N²), ``>= 0`` and constant within a run
    (default 0).

Driven logs (paper eqs. 8–9: the motor drives the gear, the output turns against a
load) add the columns

``motor_torque`` (driven logs)
    Motor torque at the wave generator [N m], zero-order hold: the value of row
    ``k`` acts from ``time[k]`` until ``time[k+1]`` (a digital drive's command).
``motor_current`` (instead of ``motor_torque``)
    Motor current [A]; needs ``torque_constant`` (N m/A) and is converted to
    ``motor_torque = torque_constant * motor_current``. Both columns at once is an
    error.
``theta_out`` (optional, driven logs only)
    Output-shaft angle [rad, output encoder's frame], or raw output encoder counts
    when ``output_counts_per_rev`` is given (``output_counts`` is accepted as an
    alias in that case).
``load_torque`` (optional, driven logs only)
    External torque applied on the output shaft [N m, output side], linearly
    interpolated between samples (a measured signal); absent means zero load.

A log is driven when it has a motor-torque column; then every run must have it
(a log mixing driven and free-motion runs is an error) and every cell of a driven
column must be filled. ``theta_out`` and ``load_torque`` without a motor torque
are errors. A driven run need not show motion (it may stay stuck).

Column names are matched case-insensitively after stripping whitespace; other
columns are ignored. :func:`read_log` checks everything and raises
:class:`~hdid._errors.LogError` with a one-line message naming the file, the
column and/or the CSV line and the fix. The file is only ever read.

This module must stay light: it imports numpy and pandas only (no JAX).
"""

from __future__ import annotations

import math
import os
import re
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from . import _units
from ._errors import LogError

__all__ = ["Log", "Run", "estimate_resolution", "read_log", "write_log"]

#: Canonical column names.
_TIME, _THETA, _COUNTS, _RUN, _SETUP, _INERTIA = (
    "time",
    "theta",
    "counts",
    "run",
    "setup",
    "added_inertia",
)
#: Driven-log columns (paper eqs. 8–9).
_MOTOR_TORQUE, _MOTOR_CURRENT, _THETA_OUT, _OUTPUT_COUNTS, _LOAD_TORQUE = (
    "motor_torque",
    "motor_current",
    "theta_out",
    "output_counts",
    "load_torque",
)
#: Key under which the motor-torque column (torque or current) is indexed.
_MOTOR = "<motor>"
_KNOWN_COLUMNS = (
    _TIME,
    _THETA,
    _COUNTS,
    _RUN,
    _SETUP,
    _INERTIA,
    _MOTOR_TORQUE,
    _MOTOR_CURRENT,
    _THETA_OUT,
    _OUTPUT_COUNTS,
    _LOAD_TORQUE,
)
#: ``|theta|`` above this cannot be radians in a ±0.157 rad test.
_COUNTS_LOOKING_MAX = 20.0
#: Tolerance for "is an integer" on raw encoder counts (relative, >= absolute).
_INTEGER_TOL = 1e-6
#: Motion threshold [rad] when the encoder resolution is unknown.
_MIN_MOTION_UNQUANTIZED = 1e-9
#: Text that stands for a missing value rather than a typo.
_NA_TOKENS = frozenset(
    {"nan", "-nan", "+nan", "na", "n/a", "#n/a", "null", "none", "nat", "-", "?"}
)
_COUNTS_HINT = "pass --counts-per-rev N (e.g. 4000)"
_OUTPUT_COUNTS_HINT = "pass output_counts_per_rev=N (e.g. 524288 = 2**19)"
_MOTOR_HINT = (
    "a driven log needs 'motor_torque' [N m] (or 'motor_current' [A] with torque_constant)"
)
_EXPECTED_COLUMNS = (
    "'time' and 'theta' (or 'counts' with --counts-per-rev); optional 'run', "
    "'setup', 'added_inertia'; driven logs: 'motor_torque' (or 'motor_current'), "
    "'theta_out' (or 'output_counts'), 'load_torque'"
)


# --------------------------------------------------------------------------- data


def _frozen_float_array(values, name: str) -> np.ndarray:
    arr = np.array(values, dtype=np.float64, copy=True)
    if arr.ndim != 1:
        raise ValueError(f"Run.{name} must be one-dimensional, got shape {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Run:
    """One release of the drive: a contiguous block of samples of a log.

    Parameters
    ----------
    name : str
        Run label (the ``run`` column value as text; ``"1"`` if the log has no
        ``run`` column).
    time : numpy.ndarray
        Sample times [s], float64, strictly increasing, as in the file.
    theta : numpy.ndarray
        Wave-generator (motor) angle [rad], float64, converted from encoder
        counts if the log held counts.
    setup : str, default "1"
        Set-up label (the ``setup`` column; ``"1"`` if absent).
    added_inertia : float, default 0.0
        Inertia added for this run [kg m^2] (the ``added_inertia`` column).
    first_row : int, default 0
        CSV line number of the run's first sample (header is line 1); 0 when the
        run was not read from a file.
    motor_torque : numpy.ndarray or None, default None
        Driven runs: motor torque at the wave generator [N m] per sample, held
        from each sample to the next (zero-order hold). ``None`` for a
        free-motion run.
    theta_out : numpy.ndarray or None, default None
        Driven runs: output angle [rad, output encoder's frame], or ``None``.
    load_torque : numpy.ndarray or None, default None
        Driven runs: external torque on the output [N m, output side], linear
        between samples; ``None`` means zero load.

    Notes
    -----
    The arrays are copied to read-only float64 arrays. ``theta_out`` and
    ``load_torque`` need ``motor_torque`` (``ValueError`` otherwise). Runs compare by
    identity (``eq=False``) because element-wise array equality has no single
    truth value.
    """

    name: str
    time: np.ndarray
    theta: np.ndarray
    setup: str = "1"
    added_inertia: float = 0.0
    first_row: int = 0
    motor_torque: np.ndarray | None = None
    theta_out: np.ndarray | None = None
    load_torque: np.ndarray | None = None

    def __post_init__(self) -> None:
        time = _frozen_float_array(self.time, "time")
        theta = _frozen_float_array(self.theta, "theta")
        if time.shape != theta.shape:
            raise ValueError(
                f"Run {self.name!r}: time has {time.size} samples but theta has {theta.size}"
            )
        for key in ("motor_torque", "theta_out", "load_torque"):
            value = getattr(self, key)
            if value is None:
                continue
            arr = _frozen_float_array(value, key)
            if arr.shape != time.shape:
                raise ValueError(
                    f"Run {self.name!r}: time has {time.size} samples but {key} has {arr.size}"
                )
            if key != "motor_torque" and self.motor_torque is None:
                raise ValueError(
                    f"Run {self.name!r}: {key} is given without motor_torque — a driven run "
                    "needs the motor torque"
                )
            object.__setattr__(self, key, arr)
        object.__setattr__(self, "name", str(self.name))
        object.__setattr__(self, "setup", str(self.setup))
        object.__setattr__(self, "added_inertia", float(self.added_inertia))
        object.__setattr__(self, "first_row", int(self.first_row))
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "theta", theta)

    @property
    def n_samples(self) -> int:
        """Number of samples in the run."""
        return int(self.time.size)

    @property
    def is_driven(self) -> bool:
        """Whether the run has a motor torque (a driven run, paper eqs. 8–9)."""
        return self.motor_torque is not None


@dataclass(frozen=True)
class Log:
    """A validated log: one or more runs at a common sample rate.

    Parameters
    ----------
    source : str
        The path as given to :func:`read_log`, or ``"<DataFrame>"``.
    runs : tuple of Run
        The runs, in order of first appearance in the file.
    sample_period : float
        Common sample period [s]: median of the time steps over all runs.
    resolution : float or None
        Encoder step [rad]: ``2*pi/counts_per_rev`` when that was given, else
        estimated from the data by :func:`estimate_resolution`; ``None`` if the
        data do not look quantized.
    counts_per_rev : float or None
        Encoder counts per revolution if the log held raw counts.
    output_resolution : float or None
        Output encoder step [rad]: ``2*pi/output_counts_per_rev`` when that was
        given, else estimated from ``theta_out`` like ``resolution``; ``None``
        without ``theta_out`` or when it does not look quantized.
    output_counts_per_rev : float or None
        Output encoder counts per revolution if the log held raw output counts.
    torque_constant : float or None
        Motor torque constant [N m/A] if the log held ``motor_current``.
    resolution_source : str or None
        ``"given"`` (``resolution=`` or ``counts_per_rev``), ``"estimated"`` (from the
        readings' grid) or ``None`` (no resolution: readings on no grid).

    Raises
    ------
    ValueError
        If some runs are driven and others not.
    """

    source: str
    runs: tuple[Run, ...]
    sample_period: float
    resolution: float | None
    counts_per_rev: float | None = None
    output_resolution: float | None = None
    output_counts_per_rev: float | None = None
    torque_constant: float | None = None
    resolution_source: str | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "runs", tuple(self.runs))
        kinds = {run.is_driven for run in self.runs}
        if len(kinds) > 1:
            free = next(run.name for run in self.runs if not run.is_driven)
            driven = next(run.name for run in self.runs if run.is_driven)
            raise ValueError(
                f"run {free!r} is free-motion but run {driven!r} is driven — a log must be "
                "all driven or all free-motion"
            )

    @property
    def is_driven(self) -> bool:
        """Whether every run has a motor torque (a driven log); False for no runs."""
        return bool(self.runs) and all(run.is_driven for run in self.runs)

    @property
    def setups(self) -> tuple[str, ...]:
        """Unique set-up labels, in order of appearance."""
        return tuple(dict.fromkeys(run.setup for run in self.runs))

    @property
    def n_samples(self) -> int:
        """Total number of samples over all runs."""
        return sum(run.n_samples for run in self.runs)


# ------------------------------------------------------------------ resolution


#: Largest divisor of the smallest gap between reading levels tried as the step.
MAX_STEP_DIVISOR = 64


def estimate_resolution(theta: np.ndarray, *, rtol: float = 1e-6) -> float | None:
    """Estimate the quantization step of a quantized signal.

    The distinct levels of `theta` are sorted; the step ``q`` is the largest divisor
    ``g/k`` (``k`` = 1 … ``MAX_STEP_DIVISOR``) of the smallest gap ``g`` between adjacent
    levels of which every gap is an integer multiple within ``rtol`` per step. Only differences of
    values are used, so a constant offset (``offset + k*q``) does not matter.
    The returned step is refined as (highest - lowest level) / (number of steps).

    Parameters
    ----------
    theta : numpy.ndarray
        Signal samples (any shape; non-finite values are ignored).
    rtol : float, default 1e-6
        Tolerance on each gap, as a fraction of the step. The default accepts
        values computed in floating point; raise it (e.g. to 1e-3) for values
        printed with few decimals.

    Returns
    -------
    float or None
        The step, or ``None`` when the signal does not look quantized (gaps not
        commensurate, fewer than two distinct levels, or two levels from only
        two samples).

    Examples
    --------
    >>> q = 2 * np.pi / 4000
    >>> round(estimate_resolution(0.3 + q * np.array([0, 1, 1, 3, 2, 7])) / q, 9)
    1.0
    """
    x = np.asarray(theta, dtype=np.float64).ravel()
    x = x[np.isfinite(x)]
    if x.size < 2:
        return None
    values = np.unique(x)
    # Merge levels that differ only by floating-point rounding.
    merge_below = 1e-9 * max(float(np.max(np.abs(values))), np.finfo(float).tiny)
    gaps = np.diff(values)
    levels = values[np.concatenate(([True], gaps > merge_below))]
    if levels.size < 2 or (levels.size == 2 and x.size < 3):
        return None
    gaps = np.diff(levels)
    # The step is the greatest common divisor of the gaps: the smallest gap divided by
    # 1, 2, … (a short 250 Hz run may show levels 4, 13 and 25 counts apart but never two
    # adjacent counts). Readings on no grid fail every divisor: with many gaps the chance
    # that all lie within rtol of integers is nil.
    g0 = float(gaps.min())
    for k in range(1, MAX_STEP_DIVISOR + 1):
        q0 = g0 / k
        steps = np.rint(gaps / q0)
        if np.all(np.abs(gaps / q0 - steps) <= rtol * np.maximum(steps, 1.0)):
            q = float((levels[-1] - levels[0]) / steps.sum())
            return q if q > 0 and math.isfinite(q) else None
    return None


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


def _sniff(path, err) -> str:
    """Recognise what the file is from its first bytes; return the cell delimiter.

    Spreadsheets renamed ``.csv``, UTF-16 text, other 8-bit encodings and binary
    files get a one-line error naming what the file is. The delimiter is ``;`` (a
    European export, possibly with decimal commas) or a tab when the header line
    has one of those and no comma; else ``,``. Errors opening the file are left to
    the reader, whose messages already name them.
    """
    try:
        with open(path, "rb") as fh:
            head = fh.read(_SNIFF_BYTES)
    except (OSError, ValueError):
        return ","
    if head.startswith(b"PK\x03\x04") or head.startswith(b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1"):
        raise err(
            "this is a spreadsheet (Excel/OpenDocument) file, not CSV text — in the "
            "spreadsheet program use 'Save as' CSV (comma-separated)"
        )
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or (
        len(head) >= 4 and head[1::2].count(0) > len(head) // 4 and head[0::2].count(0) == 0
    ) or (len(head) >= 4 and head[0::2].count(0) > len(head) // 4 and head[1::2].count(0) == 0):
        raise err("this is UTF-16 text — save the log as a UTF-8 CSV file (comma-separated)")
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
    header = next((line for line in text.splitlines() if line.strip()), "")
    if "," not in header:
        if ";" in header:
            return ";"
        if "\t" in header:
            return "\t"
    return ","


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


def _load_csv(path: str | os.PathLike[str]) -> _Table:
    source = os.fspath(path)
    err = lambda message, **kw: LogError(message, path=path, **kw)  # noqa: E731
    suffix = Path(source).suffix.lower()
    if suffix in {".xlsx", ".xlsm", ".xls", ".ods"}:
        raise err("this is a spreadsheet, not a CSV file — export it as CSV (comma-separated)")
    sep = _sniff(source, err)
    try:
        # header=None: the header line is handled here, so that names are not
        # mangled by pandas and frame row i is exactly file line i + 1.
        frame = pd.read_csv(
            source,
            header=None,
            sep=sep,
            dtype=object,
            keep_default_na=False,
            na_filter=False,
            skip_blank_lines=False,
            encoding="utf-8-sig",
            engine="c",
        )
    except FileNotFoundError:
        raise err("file not found — check the path") from None
    except IsADirectoryError:
        raise err("is a directory, not a CSV file — give the path of the log file") from None
    except PermissionError:
        raise err("cannot read the file (permission denied) — check its permissions") from None
    except UnicodeDecodeError:
        raise err(
            "not a text CSV file (cannot decode it as UTF-8) — export the log as a "
            "UTF-8 CSV file with a header line"
        ) from None
    except pd.errors.EmptyDataError:
        raise err(
            "file is empty — expected a CSV file with a header line such as 'time,theta'"
        ) from None
    except pd.errors.ParserError as exc:
        raise _parser_error(exc, path) from None
    except OSError as exc:
        raise err(f"cannot read the file ({exc.strerror or exc}) — check the path") from None
    except Exception as exc:  # pandas may raise assorted errors on garbage input
        raise err(
            f"cannot parse the file as CSV ({type(exc).__name__}: {_show(exc, 80)}) — "
            "check that it is a comma-separated text file with a header line"
        ) from None

    raw = [frame[col].to_numpy(dtype=object) for col in frame.columns]
    if sep != ",":
        raw = [_decimal_commas(values) for values in raw]
    blank = np.ones(len(frame), dtype=bool)
    for values in raw:
        blank &= values == ""
    nonblank = np.flatnonzero(~blank)
    if nonblank.size == 0:
        raise err("file holds only blank lines — expected a header line such as 'time,theta'")
    header_at = int(nonblank[0])
    names = [str(values[header_at]).strip() for values in raw]
    keep = nonblank[1:]
    lines = keep.astype(np.int64) + 1
    return _Table(source, path, names, [values[keep] for values in raw], lines)


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


def _load_frame(frame: pd.DataFrame) -> _Table:
    names = [str(c).strip() for c in frame.columns]
    columns = [frame.iloc[:, i] for i in range(frame.shape[1])]
    lines = np.arange(2, len(frame) + 2, dtype=np.int64)
    return _Table("<DataFrame>", None, names, columns, lines)


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


# ----------------------------------------------------------------------- reading


def _positive_arg(path, value, what: str, hint: str) -> float | None:
    """``float(value)`` if it is a positive finite number, None for None, else a LogError."""
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        number = float("nan")
    if isinstance(value, bool) or not (math.isfinite(number) and number > 0):
        raise LogError(f"{what} must be a positive number, got {value!r} — {hint}", path=path)
    return number


def _check_args(path, counts_per_rev, period_tolerance, min_samples_per_run) -> float | None:
    if counts_per_rev is not None:
        try:
            cpr = float(counts_per_rev)
        except (TypeError, ValueError):
            cpr = float("nan")
        if not (math.isfinite(cpr) and cpr > 0):
            raise LogError(
                f"counts per revolution must be a positive number, got {counts_per_rev!r} — "
                f"{_COUNTS_HINT}",
                path=path,
            )
        counts_per_rev = cpr
    try:
        tol = float(period_tolerance)
    except (TypeError, ValueError):
        tol = float("nan")
    if not (math.isfinite(tol) and 0 < tol < 1):
        raise LogError(
            f"period tolerance must be a fraction in (0, 1), got {period_tolerance!r}", path=path
        )
    if isinstance(min_samples_per_run, bool) or not isinstance(
        min_samples_per_run, int | np.integer
    ) or min_samples_per_run < 2:
        raise LogError(
            f"minimum samples per run must be an integer >= 2, got {min_samples_per_run!r}",
            path=path,
        )
    return counts_per_rev


def _find_columns(
    table: _Table,
    counts_per_rev: float | None,
    output_counts_per_rev: float | None = None,
    torque_constant: float | None = None,
) -> dict[str, int]:
    """Map canonical names to column indices, or raise a LogError.

    The motor-torque column (``motor_torque``, or ``motor_current`` with a torque
    constant) is mapped under ``_MOTOR``; ``output_counts`` (with
    ``output_counts_per_rev``) under ``_THETA_OUT``.
    """
    path = table.path
    index: dict[str, int] = {}
    for i, name in enumerate(table.names):
        key = _units.split(name)[0].lower()
        if key not in _KNOWN_COLUMNS:
            continue
        if key in index:
            raise LogError(
                f"column appears twice (columns {index[key] + 1} and {i + 1}) — rename or "
                "drop one of them",
                path=path,
                column=name,
            )
        index[key] = i
    if _THETA in index and _COUNTS in index and counts_per_rev is not None:
        raise LogError(
            "both 'theta' and 'counts' columns are present — keep only one",
            path=path,
            column=table.names[index[_COUNTS]],
        )
    if _THETA not in index and _COUNTS in index:
        if counts_per_rev is None:
            raise LogError(
                f"looks like raw encoder counts; {_COUNTS_HINT}",
                path=path,
                column=table.names[index[_COUNTS]],
            )
        index[_THETA] = index[_COUNTS]
    _find_driven_columns(table, index, output_counts_per_rev, torque_constant)
    missing = [name for name in (_TIME, _THETA) if name not in index]
    if missing:
        found = ", ".join(_show(n, 30) for n in table.names) or "none"
        if path is None:
            hint = " — rename the DataFrame columns (names are case-insensitive)"
        elif any(sep in n for n in table.names for sep in (";", "\t", "|")):
            hint = " — the file seems not to be comma-separated; save it as CSV with ',' between cells"
        elif table.names and all(_looks_numeric(n) for n in table.names if n):
            hint = " — the first line looks like data; add a header line such as 'time,theta'"
        else:
            hint = " — rename the columns (names are case-insensitive)"
        raise LogError(
            f"missing column{'s' if len(missing) > 1 else ''} "
            f"{' and '.join(repr(m) for m in missing)}: found columns "
            f"[{found}], expected {_EXPECTED_COLUMNS}{hint}",
            path=path,
        )
    return index


def _column_scales(table: _Table, cols: dict[str, int]) -> dict[str, float]:
    """Per canonical key, the factor from its header's unit (``time [ms]``) to hdid's units
    (:mod:`hdid._units`; 1 without a unit), or a LogError naming an unknown unit."""
    out = {}
    for key, i in cols.items():
        header = table.names[i]
        base, unit = _units.split(header)
        f = _units.scale(base.lower(), unit)
        if f is None:
            raise LogError(
                f"unknown unit {unit!r} for {base.lower()!r}: use one of "
                f"{_units.known(base.lower())}, or drop the unit from the header and give the "
                f"column in {_units.SI.get(base.lower(), 'consistent units')}",
                path=table.path, column=header,
            )
        out[key] = f
    return out


def _find_driven_columns(
    table: _Table,
    index: dict[str, int],
    output_counts_per_rev: float | None,
    torque_constant: float | None,
) -> None:
    """Resolve the driven-log columns in `index` (in place), or raise a LogError.

    A log without any driven column is a free-motion log: `output_counts_per_rev` and
    `torque_constant` are ignored there, so that one set of arguments reads both logs of
    a joint (free-motion + driven) fit.
    """
    path = table.path
    driven_keys = (_MOTOR_TORQUE, _MOTOR_CURRENT, _THETA_OUT, _OUTPUT_COUNTS, _LOAD_TORQUE)
    if not any(key in index for key in driven_keys):
        return

    def fail(message: str, key: str | None = None) -> LogError:
        return LogError(message, path=path, column=None if key is None else table.names[index[key]])

    # -- motor torque: 'motor_torque' [N m] or 'motor_current' [A] * torque_constant
    if _MOTOR_TORQUE in index and _MOTOR_CURRENT in index:
        raise fail(
            "both 'motor_torque' and 'motor_current' columns are present — keep only one",
            _MOTOR_CURRENT,
        )
    if _MOTOR_CURRENT in index:
        if torque_constant is None:
            raise fail(
                "motor current [A] needs the motor's torque constant — pass "
                "torque_constant=KT (N m/A), or give 'motor_torque' [N m] instead",
                _MOTOR_CURRENT,
            )
        index[_MOTOR] = index[_MOTOR_CURRENT]
    elif torque_constant is not None:
        if _MOTOR_TORQUE in index:
            raise fail(
                "torque_constant is given but the log holds 'motor_torque' in N m already — "
                "drop torque_constant",
                _MOTOR_TORQUE,
            )
        raise fail(
            "torque_constant is given but the log has no 'motor_current' column — drop "
            "torque_constant or add the column"
        )
    elif _MOTOR_TORQUE in index:
        index[_MOTOR] = index[_MOTOR_TORQUE]

    # -- output angle: 'theta_out' [rad] or raw counts with output_counts_per_rev
    if _THETA_OUT in index and _OUTPUT_COUNTS in index and output_counts_per_rev is not None:
        raise fail(
            "both 'theta_out' and 'output_counts' columns are present — keep only one",
            _OUTPUT_COUNTS,
        )
    if _THETA_OUT not in index and _OUTPUT_COUNTS in index:
        if output_counts_per_rev is None:
            raise fail(
                f"looks like raw output encoder counts; {_OUTPUT_COUNTS_HINT}", _OUTPUT_COUNTS
            )
        index[_THETA_OUT] = index[_OUTPUT_COUNTS]
    if output_counts_per_rev is not None and _THETA_OUT not in index:
        raise fail(
            "output_counts_per_rev is given but the log has no 'theta_out' or "
            "'output_counts' column — drop output_counts_per_rev or add the column"
        )

    # -- what needs a motor torque
    if _MOTOR not in index:
        for key, what in ((_THETA_OUT, "an output angle"), (_LOAD_TORQUE, "a load torque")):
            if key in index:
                raise fail(
                    f"{what} is given but no motor torque — {_MOTOR_HINT}; drop this column "
                    "for a free-motion log",
                    key,
                )


def _missing_cells(column) -> np.ndarray:
    """Mask of cells that are empty or hold a missing-value token (e.g. 'nan', 'NA')."""
    if isinstance(column, pd.Series) and pd.api.types.is_numeric_dtype(column.dtype):
        return column.isna().to_numpy()
    raw = np.asarray(column, dtype=object)
    codes, uniques = pd.factorize(raw, use_na_sentinel=False)
    text = [_cell_text(u).lower() for u in uniques]
    flags = np.array([t == "" or t in _NA_TOKENS for t in text], dtype=bool)
    return flags[codes] if flags.size else np.zeros(raw.shape, dtype=bool)


def _looks_numeric(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _to_radians(values, cpr, fail, column: str, encoder: str, option: str, hint: str):
    """Raw counts (with ``cpr``) to radians and the resolution; radians pass through.

    Non-integer counts, or radians that look like raw counts, raise ``fail(...)``.
    """
    integral = np.abs(values - np.rint(values)) <= _INTEGER_TOL * np.maximum(1.0, np.abs(values))
    if cpr is not None:
        pos = _first(~integral)
        if pos is not None:
            raise fail(
                f"value {values[pos]:.9g} is not a whole number of {encoder} counts — drop "
                f"{option} if {column} is already in radians",
                column,
                pos,
            )
        resolution = 2.0 * math.pi / cpr
        return np.rint(values) * resolution, resolution
    if integral.all() and float(np.max(np.abs(values))) > _COUNTS_LOOKING_MAX:
        raise fail(f"looks like raw {encoder} counts; {hint}", column)
    return values, None


def _first(mask: np.ndarray) -> int | None:
    """Index of the first True in `mask`, or None."""
    if mask.size and mask.any():
        return int(np.argmax(mask))
    return None


def read_log(
    source: str | os.PathLike[str] | pd.DataFrame,
    *,
    counts_per_rev: float | None = None,
    period_tolerance: float = 0.02,
    min_samples_per_run: int = 8,
    output_counts_per_rev: float | None = None,
    torque_constant: float | None = None,
    resolution: float | None = None,
) -> Log:
    """Read and validate a free-motion or driven log.

    Parameters
    ----------
    source : str, os.PathLike or pandas.DataFrame
        Path of a CSV file with a header line, or a table with the same columns.
        For a DataFrame, row numbers in messages are those the table would have
        as a CSV file (first row is row 2) and the source is ``<DataFrame>``.
    counts_per_rev : float, optional
        Encoder counts per revolution. When given, ``theta`` (or ``counts``)
        holds raw integer counts and is converted to radians with
        ``2*pi/counts_per_rev``, which is also the resolution.
    period_tolerance : float, default 0.02
        Allowed relative deviation of every time step from the log's median
        step.
    min_samples_per_run : int, default 8
        Fewest samples a run may have (at least 2).
    output_counts_per_rev : float, optional
        Output encoder counts per revolution (driven logs). When given,
        ``theta_out`` (or ``output_counts``) holds raw integer counts and is
        converted to radians with ``2*pi/output_counts_per_rev``, which is also
        the output resolution.
    torque_constant : float, optional
        Motor torque constant [N m/A]; required with a ``motor_current`` column
        (``motor_torque = torque_constant * current``) and an error for a driven
        log without one. ``output_counts_per_rev`` and ``torque_constant`` are
        ignored for a free-motion log (no driven column), so that one set of
        arguments reads both logs of a joint fit.
    resolution : float, optional
        Encoder step (or sensor resolution) of ``theta`` in the log's own units. Without
        it (and without ``counts_per_rev``) the step is estimated from the readings'
        grid; readings on no grid (interpolated, analog) get ``None`` and the fit
        estimates their noise instead.

    Returns
    -------
    Log
        The validated runs with their common sample period and resolution.

    Raises
    ------
    LogError
        For any problem with the file, its contents or the arguments, with a
        one-line message naming the file, column and/or CSV line and the fix.
        The file is never modified.

    Notes
    -----
    Checks, in order: the file can be read as CSV; required columns exist; every
    cell of the used columns is filled and numeric/finite (first bad cell in the
    file is reported); raw counts vs. ``counts_per_rev`` consistency;
    ``added_inertia >= 0``; runs are contiguous; ``setup`` and
    ``added_inertia`` are constant within a run; time strictly increases within
    a run; each run has enough samples; the sampling is uniform and shared by
    all runs; each run shows motion (at least 2 encoder steps, or 1e-9 rad when
    the resolution is unknown). Fully blank lines are skipped.

    Driven logs (a ``motor_torque`` or ``motor_current`` column) are checked
    further: the torque / counts arguments match the columns; no run lacks the
    motor torque while others have it; every driven cell is filled and finite;
    raw output counts are whole numbers. The motion check is skipped for driven
    logs (a driven run may stay stuck).
    """
    if isinstance(source, pd.DataFrame):
        path = None
    elif isinstance(source, str | os.PathLike):
        path = source
    else:
        raise TypeError(
            f"read_log expects a path or a pandas DataFrame, got {type(source).__name__}"
        )
    cpr = _check_args(path, counts_per_rev, period_tolerance, min_samples_per_run)
    given_step = _positive_arg(
        path, resolution, "resolution", "pass the encoder step in the log's units, e.g. "
        "--resolution 0.00157 (or --counts-per-rev N)"
    )
    if given_step is not None and cpr is not None:
        raise LogError(
            "give either the resolution or the counts per revolution, not both "
            "(--counts-per-rev N implies a step of 2*pi/N)", path=path,
        )
    out_cpr = _positive_arg(
        path, output_counts_per_rev, "output counts per revolution", _OUTPUT_COUNTS_HINT
    )
    kt = _positive_arg(
        path, torque_constant, "torque constant", "pass the motor's torque constant in N m/A"
    )
    table = _load_frame(source) if path is None else _load_csv(path)
    cols = _find_columns(table, cpr, out_cpr, kt)
    unit_scale = _column_scales(table, cols)
    if given_step is not None:  # in theta's units, as the header gives them
        given_step *= unit_scale[_THETA]
    driven = _MOTOR in cols
    if not driven:  # a free-motion log: the driven-only arguments do not apply
        out_cpr = kt = None
    n = int(table.lines.size)
    if n == 0:
        raise LogError(
            "no data rows below the header — the log must hold the samples of at least one run",
            path=path,
        )

    def name(key: str) -> str:
        return table.names[cols[key]]

    def fail(message: str, key: str | None = None, pos: int | None = None) -> LogError:
        return LogError(
            message,
            path=path,
            column=None if key is None else name(key),
            row=None if pos is None else int(table.lines[pos]),
        )

    # -- cells -------------------------------------------------------------
    cells = _Cells(table)
    run_labels = cells.labels(cols[_RUN]) if _RUN in cols else None
    setups = cells.labels(cols[_SETUP]) if _SETUP in cols else None
    time = cells.numbers(cols[_TIME])
    theta = cells.numbers(cols[_THETA])
    inertia = cells.numbers(cols[_INERTIA]) if _INERTIA in cols else None
    motor = cells.numbers(cols[_MOTOR]) if driven else None
    theta_out = cells.numbers(cols[_THETA_OUT]) if _THETA_OUT in cols else None
    load = cells.numbers(cols[_LOAD_TORQUE]) if _LOAD_TORQUE in cols else None
    if driven and run_labels is not None:
        _check_not_mixed(table, cols[_MOTOR], run_labels)
    cells.raise_first()
    time, theta = time * unit_scale[_TIME], theta * unit_scale[_THETA]
    if inertia is not None:
        inertia = inertia * unit_scale[_INERTIA]
    if motor is not None:
        motor = motor * unit_scale[_MOTOR]
    if theta_out is not None:
        theta_out = theta_out * unit_scale[_THETA_OUT]
    if load is not None:
        load = load * unit_scale[_LOAD_TORQUE]
    if motor is not None and kt is not None:
        motor = motor * kt

    # -- counts vs. radians ------------------------------------------------
    theta, resolution = _to_radians(
        theta, cpr, fail, _THETA, "encoder", "--counts-per-rev", _COUNTS_HINT
    )
    if given_step is not None:
        resolution = given_step
    resolution_source = "given" if resolution is not None else None
    output_resolution: float | None = None
    if theta_out is not None:
        theta_out, output_resolution = _to_radians(
            theta_out, out_cpr, fail, _THETA_OUT, "output encoder",
            "output_counts_per_rev", _OUTPUT_COUNTS_HINT,
        )

    if inertia is not None:
        pos = _first(inertia < 0)
        if pos is not None:
            raise fail(
                f"added inertia {inertia[pos]:.6g} is negative — it must be >= 0 kg m^2",
                _INERTIA,
                pos,
            )

    # -- runs --------------------------------------------------------------
    if run_labels is None:
        starts = np.array([0], dtype=np.int64)
        names = ["1"]
    else:
        change = np.flatnonzero(run_labels[1:] != run_labels[:-1]) + 1
        starts = np.concatenate(([0], change)).astype(np.int64)
        block_labels = run_labels[starts]
        codes, uniques = pd.factorize(pd.Series(block_labels, dtype=object))
        if len(uniques) != len(block_labels):
            seen = np.zeros(len(uniques), dtype=bool)
            for b, c in enumerate(codes):
                if seen[c]:
                    raise fail(
                        f"run {_show(block_labels[b])} appears again after other runs — the rows "
                        "of a run must be contiguous; sort the rows by run or relabel this block",
                        _RUN,
                        int(starts[b]),
                    )
                seen[c] = True
        names = [str(v) for v in block_labels]
    ends = np.append(starts[1:], n)
    new_run = np.zeros(n, dtype=bool)
    new_run[starts] = True
    within = ~new_run[1:]  # step i -> i+1 stays inside one run

    problems: list[tuple[int, int, LogError]] = []
    if setups is not None:
        pos = _first((setups[1:] != setups[:-1]) & within)
        if pos is not None:
            problems.append(
                (
                    pos + 1,
                    0,
                    fail(
                        f"setup changes from {_show(setups[pos])} to {_show(setups[pos + 1])} "
                        "within one run — a run must have one setup; check the labels or add a "
                        "'run' column",
                        _SETUP,
                        pos + 1,
                    ),
                )
            )
    if inertia is not None:
        pos = _first((inertia[1:] != inertia[:-1]) & within)
        if pos is not None:
            problems.append(
                (
                    pos + 1,
                    1,
                    fail(
                        f"added inertia changes from {inertia[pos]:.6g} to {inertia[pos + 1]:.6g} "
                        "within one run — it must be constant within a run",
                        _INERTIA,
                        pos + 1,
                    ),
                )
            )
    steps = np.diff(time)
    pos = _first((steps <= 0) & within)
    if pos is not None:
        if steps[pos] == 0:
            msg = (
                f"time {time[pos + 1]:.9g} repeats the previous row — remove the duplicated row"
            )
        else:
            msg = (
                f"time {time[pos + 1]:.9g} is not after the previous {time[pos]:.9g} — time must "
                "increase strictly within a run; sort the rows, or add a 'run' column if a new "
                "release starts here"
            )
        problems.append((pos + 1, 2, fail(msg, _TIME, pos + 1)))
    if problems:
        raise min(problems, key=lambda p: p[:2])[2]

    lengths = ends - starts
    short = _first(lengths < min_samples_per_run)
    if short is not None:
        raise fail(
            f"run {_show(names[short])} has only {int(lengths[short])} sample(s), at least "
            f"{min_samples_per_run} are needed — drop the run or log it longer",
            _RUN if _RUN in cols else None,
            int(starts[short]),
        )

    # -- sampling ----------------------------------------------------------
    inner_steps = steps[within]
    period = float(np.median(inner_steps))
    if not math.isfinite(period):
        raise fail("time values are too large to take differences — write time in seconds", _TIME)
    tol = float(period_tolerance)
    pos = _first((np.abs(steps - period) > tol * period) & within)
    if pos is not None:
        r = int(np.searchsorted(starts, pos, side="right") - 1)
        run_period = float(np.median(np.diff(time[starts[r] : ends[r]])))
        if abs(run_period - period) > tol * period:
            raise fail(
                f"run {_show(names[r])} is sampled every {run_period:.6g} s but the log's period "
                f"is {period:.6g} s — all runs must share one sample rate (within "
                f"{100 * tol:g}%); resample the run or read it separately",
                _TIME,
                int(starts[r]),
            )
        raise fail(
            f"run {_show(names[r])}: time step {steps[pos]:.6g} s differs from the log's sample "
            f"period {period:.6g} s by more than {100 * tol:g}% — resample the log to a "
            "uniform rate or split it into runs at this row",
            _TIME,
            pos + 1,
        )

    # -- resolution and motion ---------------------------------------------
    if resolution is None:
        offsets = np.repeat(theta[starts], lengths)
        resolution = estimate_resolution(theta - offsets)
        resolution_source = "estimated" if resolution is not None else None
    if theta_out is not None and output_resolution is None:
        offsets = np.repeat(theta_out[starts], lengths)
        output_resolution = estimate_resolution(theta_out - offsets)
    spans = np.maximum.reduceat(theta, starts) - np.minimum.reduceat(theta, starts)
    if resolution is not None:
        still = spans < (2.0 - 1e-6) * resolution
        why = f"less than 2 encoder steps of {resolution:.6g} rad"
    else:
        still = spans < _MIN_MOTION_UNQUANTIZED
        why = f"less than {_MIN_MOTION_UNQUANTIZED:g} rad"
    r = None if driven else _first(still)
    if r is not None:
        raise fail(
            f"run {_show(names[r])} shows no motion (theta spans {spans[r]:.6g} rad, {why}) — "
            "check that the drive was twisted and released, or drop the run",
            _THETA,
            int(starts[r]),
        )

    def part(values: np.ndarray | None, k: int) -> np.ndarray | None:
        return None if values is None else values[starts[k] : ends[k]]

    runs = tuple(
        Run(
            name=names[k],
            time=time[starts[k] : ends[k]],
            theta=theta[starts[k] : ends[k]],
            setup="1" if setups is None else str(setups[starts[k]]),
            added_inertia=0.0 if inertia is None else float(inertia[starts[k]]),
            first_row=int(table.lines[starts[k]]),
            motor_torque=part(motor, k),
            theta_out=part(theta_out, k),
            load_torque=part(load, k),
        )
        for k in range(len(starts))
    )
    return Log(
        source=table.source,
        runs=runs,
        sample_period=period,
        resolution=resolution,
        resolution_source=resolution_source,
        counts_per_rev=cpr,
        output_resolution=output_resolution,
        output_counts_per_rev=out_cpr,
        torque_constant=kt,
    )


def _check_not_mixed(table: _Table, col: int, run_labels: np.ndarray) -> None:
    """Raise a LogError if some runs have no motor torque at all and others have it."""
    missing = _missing_cells(table.columns[col])
    if not missing.any() or missing.all():
        return
    starts = np.concatenate(([0], np.flatnonzero(run_labels[1:] != run_labels[:-1]) + 1))
    empty = np.logical_and.reduceat(missing, starts)
    full = ~np.logical_or.reduceat(missing, starts)
    if empty.any() and (full | ~empty).any():
        b = int(np.argmax(empty))
        other = int(np.argmax(~empty))
        raise LogError(
            f"run {_show(run_labels[starts[b]])} has no motor torque but run "
            f"{_show(run_labels[starts[other]])} has — a log must be all driven or all "
            "free-motion; split it into two files",
            path=table.path,
            column=table.names[col],
            row=int(table.lines[starts[b]]),
        )


# ----------------------------------------------------------------------- writing


def write_log(
    path: str | os.PathLike[str],
    runs: Sequence[Run] | Log,
    *,
    counts_per_rev: float | None = None,
    overwrite: bool = False,
    output_counts_per_rev: float | None = None,
) -> None:
    """Write runs as a CSV log readable by :func:`read_log`.

    The columns are ``run,setup,time,theta`` plus ``added_inertia`` when any
    run has a nonzero added inertia, and for driven runs ``motor_torque``,
    ``load_torque`` (when any run has one; a run without it gets zeros) and
    ``theta_out`` (when the runs have it). Floats are written with full
    (round-trip) precision.

    Parameters
    ----------
    path : str or os.PathLike
        Output CSV file.
    runs : sequence of Run, or Log
        The runs to write; their names must be distinct.
    counts_per_rev : float, optional
        When given, ``theta`` is written as integer encoder counts,
        ``round(theta / (2*pi/counts_per_rev))`` (this quantizes theta); read the
        file back with the same ``counts_per_rev``.
    overwrite : bool, default False
        Replace an existing file. Otherwise an existing file is an error.
    output_counts_per_rev : float, optional
        Likewise for ``theta_out``: written as integer output encoder counts;
        read back with the same ``output_counts_per_rev``.

    Raises
    ------
    LogError
        If the file exists (and `overwrite` is false), cannot be written, or the
        runs are not writable (no runs, empty or non-finite arrays, repeated or
        empty run names, labels with line breaks, bad `counts_per_rev`, driven
        and free-motion runs mixed, ``theta_out`` in some runs only).
    """
    if isinstance(runs, Log):
        runs = runs.runs
    runs = tuple(runs)
    err = lambda message, **kw: LogError(message, path=path, **kw)  # noqa: E731
    if not runs:
        raise err("no runs to write — pass at least one Run")
    for what, value in (("", counts_per_rev), ("output ", output_counts_per_rev)):
        if value is not None:
            cpr = float(value)
            if not (math.isfinite(cpr) and cpr > 0):
                raise err(f"{what}counts per revolution must be a positive number, got {value!r}")
    seen: set[str] = set()
    for run in runs:
        if not isinstance(run, Run):
            raise TypeError(f"write_log expects Run objects, got {type(run).__name__}")
        label = f"run {_show(run.name)}"
        for text in (run.name, run.setup):
            if text.strip() == "" or text != text.strip() or any(c in text for c in "\r\n"):
                raise err(
                    f"{label}: label {_show(text)} is empty, padded or has a line break — use a "
                    "plain label"
                )
        if run.name in seen:
            raise err(f"{label} is given twice — run names must be distinct")
        seen.add(run.name)
        if run.n_samples == 0:
            raise err(f"{label} has no samples")
        if not (np.all(np.isfinite(run.time)) and np.all(np.isfinite(run.theta))):
            raise err(f"{label} has non-finite time or theta values")
        if not (math.isfinite(run.added_inertia) and run.added_inertia >= 0):
            raise err(f"{label} has an invalid added inertia {run.added_inertia!r}")
        for key in ("motor_torque", "theta_out", "load_torque"):
            value = getattr(run, key)
            if value is not None and not np.all(np.isfinite(value)):
                raise err(f"{label} has non-finite {key} values")
    for key, what in (("motor_torque", "driven and free-motion runs"), ("theta_out", "theta_out")):
        have = [getattr(r, key) is not None for r in runs]
        if any(have) and not all(have):
            lacking = runs[have.index(False)].name
            raise err(
                f"run {_show(lacking)} has no {key} but other runs have — cannot write "
                f"{what} in one log; write them to separate files"
            )

    columns: dict[str, object] = {
        _RUN: np.concatenate([np.full(r.n_samples, r.name, dtype=object) for r in runs]),
        _SETUP: np.concatenate([np.full(r.n_samples, r.setup, dtype=object) for r in runs]),
        _TIME: np.concatenate([r.time for r in runs]),
    }
    theta = np.concatenate([r.theta for r in runs])
    if counts_per_rev is not None:
        columns[_THETA] = np.rint(theta / (2.0 * math.pi / float(counts_per_rev))).astype(np.int64)
    else:
        columns[_THETA] = theta
    if any(r.added_inertia != 0.0 for r in runs):
        columns[_INERTIA] = np.concatenate(
            [np.full(r.n_samples, r.added_inertia, dtype=np.float64) for r in runs]
        )
    if runs[0].motor_torque is not None:
        columns[_MOTOR_TORQUE] = np.concatenate([r.motor_torque for r in runs])
        if any(r.load_torque is not None for r in runs):
            columns[_LOAD_TORQUE] = np.concatenate(
                [np.zeros(r.n_samples) if r.load_torque is None else r.load_torque for r in runs]
            )
        if runs[0].theta_out is not None:
            out = np.concatenate([r.theta_out for r in runs])
            if output_counts_per_rev is not None:
                step = 2.0 * math.pi / float(output_counts_per_rev)
                columns[_THETA_OUT] = np.rint(out / step).astype(np.int64)
            else:
                columns[_THETA_OUT] = out
    text = pd.DataFrame(columns).to_csv(index=False, lineterminator="\n")
    try:
        with open(path, "w" if overwrite else "x", encoding="utf-8", newline="") as fh:
            fh.write(text)
    except FileExistsError:
        raise err("file already exists — choose another name or pass overwrite=True") from None
    except OSError as exc:
        raise err(f"cannot write the file ({exc.strerror or exc}) — check the path") from None
