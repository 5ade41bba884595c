"""Finding a log's columns (free-motion and driven), their units and scales."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from .. import _units
from .._errors import LogError
from ._headers import by_alias, header_key
from ._names import (
    _COUNTS, _COUNTS_HINT, _COUNTS_LOOKING_MAX, _EXPECTED_COLUMNS, _INTEGER_TOL,
    _KNOWN_COLUMNS, _LOAD_TORQUE, _MOTOR, _MOTOR_CURRENT, _MOTOR_HINT, _MOTOR_TORQUE,
    _NA_TOKENS, _OUTPUT_COUNTS, _OUTPUT_COUNTS_HINT, _THETA, _THETA_OUT, _TIME,
)
from ._table import _Table, _cell_text, _show


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
        key = header_key(name)[0]
        if key not in _KNOWN_COLUMNS:
            continue
        if key in index and by_alias(name) != by_alias(table.names[index[key]]):
            if key == _TIME:  # ``time`` and ``timestamp [ms]``: say which one is read
                other = table.names[index[key]]
                used, unused = (other, name) if by_alias(name) else (name, other)
                table.notes = list(table.notes) + [
                    f"two time columns: the time is read from {_show(used, 30)}, not from "
                    f"{_show(unused, 30)}"]
            if by_alias(name):  # ``theta`` and ``position``: the canonical name wins
                continue
        elif key in index and by_alias(name) and key in (_THETA, _THETA_OUT):
            raise LogError(  # ``Angle`` and ``Encoder``: which one the fit reads is unclear
                f"two angle columns ({_show(table.names[index[key]], 30)}, column "
                f"{index[key] + 1}, and column {i + 1}) — rename the one to fit 'theta' "
                "(or prefix them 'motor' and 'load')",
                path=path,
                column=name,
            )
        elif key in index:
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
    if (_THETA_OUT in index and by_alias(table.names[index[_THETA_OUT]])
            and _MOTOR_TORQUE not in index and _MOTOR_CURRENT not in index):
        # a motor-and-output set-up's second encoder (``load_pos``) in a free-motion log:
        # the fit reads the motor's angle; the output's is not used
        table.notes = list(table.notes) + [
            f"column {_show(table.names[index.pop(_THETA_OUT)], 30)} (the output's angle) is "
            "not used in a free-motion log: the fit reads the motor's angle"]
    _find_driven_columns(table, index, output_counts_per_rev, torque_constant)
    missing = [name for name in (_TIME, _THETA) if name not in index]
    if missing:
        found = ", ".join(_show(n, 30) for n in table.names) or "none"
        if path is None:
            hint = " — rename the DataFrame columns (names are case-insensitive)"
        elif any(sep in n for n in table.names for sep in (";", "\t", "|")):
            hint = " — the file seems not to be comma-separated; save it as CSV with ',' between cells"
        elif table.names and all(_looks_numeric(n) for n in table.names if n):
            hint = f" — the first line looks like data; add a header line {_header_for(table)}"
        else:
            hint = " — rename the columns (names are case-insensitive)"
        raise LogError(
            f"missing column{'s' if len(missing) > 1 else ''} "
            f"{' and '.join(repr(m) for m in missing)}: found columns "
            f"[{found}], expected {_EXPECTED_COLUMNS}{hint}",
            path=path,
        )
    return index


def _column_scales(table: _Table, cols: dict[str, int], counts_per_rev: float | None = None,
                   output_counts_per_rev: float | None = None) -> dict[str, float]:
    """Per canonical key, the factor from its header's unit (``time [ms]``) to hdid's units
    (:mod:`hdid._units`; 1 without a unit), or a LogError naming an unknown unit. An angle
    in counts (``theta [counts]``) is raw counts: it needs its counts per revolution."""
    out = {}
    cprs = {_THETA: (counts_per_rev, _COUNTS_HINT),
            _THETA_OUT: (output_counts_per_rev, _OUTPUT_COUNTS_HINT)}
    for key, i in cols.items():
        header = table.names[i]
        base, unit = header_key(header)
        f = _units.scale(base, unit)
        if f is None and base in cprs and _units.scale(_COUNTS, unit) is not None:
            cpr, hint = cprs[base]
            if cpr is None:
                raise LogError(f"the header gives the angle in encoder counts; {hint}",
                               path=table.path, column=header)
            f = 1.0
        if f is None:
            raise LogError(
                f"unknown unit {unit!r} for {base!r}: use one of "
                f"{_units.known(base)}, or drop the unit from the header and give the "
                f"column in {_units.SI.get(base, 'consistent units')}",
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


#: Slowest sampling [Hz] the time's unit may imply: the fit warns below 5 Hz (a log in ms
#: read as s); a header-less log's time unit is the largest that samples at least this fast.
_MIN_RATE_HZ = 5.0
#: Time units for a header-less log's suggested header, largest first, in seconds.
_TIME_UNITS = (("s", 1.0), ("ms", 1e-3), ("us", 1e-6), ("ns", 1e-9))


def _header_for(table: _Table) -> str:
    """The header line a header-less log needs, with the units its first row and columns
    suggest: time in the largest unit that samples at >= 5 Hz, the angle in rad (or raw
    counts when whole numbers beyond radians), e.g. ``'time [ms],theta [rad]'``."""
    if len(table.names) < 2:
        return "such as 'time,theta'"

    def numbers(i: int) -> np.ndarray:
        cells = [table.names[i], *np.asarray(table.columns[i], dtype=object)[:2000]]
        values = pd.to_numeric(pd.Series([_cell_text(c) for c in cells]), errors="coerce")
        values = values.to_numpy(dtype=np.float64)
        return values[np.isfinite(values)]

    steps = np.diff(numbers(0))
    steps = steps[steps > 0]
    time, why = "time", ""
    if steps.size:
        step = float(np.median(steps))
        unit, per = next(((u, f) for u, f in _TIME_UNITS if step * f <= 1.0 / _MIN_RATE_HZ),
                         _TIME_UNITS[-1])
        time, why = f"time [{unit}]", (f"steps of {step:.4g} in the first column: "
                                       f"{1.0 / (step * per):.4g} Hz in {unit}; ")
    a = numbers(1)
    top = float(np.max(np.abs(a))) if a.size else 0.0
    whole = np.all(np.abs(a - np.rint(a)) <= _INTEGER_TOL * np.maximum(1.0, np.abs(a)))
    if top <= _COUNTS_LOOKING_MAX:
        line, angle = f"'{time},theta [rad]'", "radians"
    elif whole:
        line, angle = f"'{time},counts'", f"whole numbers up to {top:.6g}: counts; {_COUNTS_HINT}"
    else:
        line, angle = (f"'{time},theta [UNIT]'",
                       f"up to {top:.6g}, beyond radians: UNIT is its unit (deg, mrad, …)")
    more = len(table.names) - 2
    if more:
        line = f"{line[:-1]},…' (… a name for each of the other {more} columns, e.g. 'run'; "
    else:
        line += " ("
    return f"{line}{why}second column {angle})"


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
            v = float(values[pos]) * 1000.0
            grouped = (f", or write the counts without digit grouping if {values[pos]:.9g} is "
                       f"{v:.0f} (a ',' between thousands in a file without decimal points "
                       "reads as a decimal comma)" if abs(v - round(v)) < 1e-6 else "")
            raise fail(
                f"value {values[pos]:.9g} is not a whole number of {encoder} counts — drop "
                f"{option} if {column} is already in radians{grouped}",
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
