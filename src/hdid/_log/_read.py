""":func:`read_log`: a CSV file or DataFrame to a validated :class:`~hdid.Log` (the table
is read by :mod:`._table`, its columns found by :mod:`._columns`, its rows checked by
:mod:`._validate`)."""

from __future__ import annotations

import math
import os

import numpy as np
import pandas as pd

from .._errors import LogError
from ._names import (
    _COUNTS_HINT, _INERTIA, _LOAD_TORQUE, _MOTOR, _OUTPUT_COUNTS_HINT, _RUN, _SETUP, _THETA,
    _THETA_OUT, _TIME,
)
from ._dropouts import find_dropouts
from ._gaps import drop_missing_readings, wide_to_long
from ._layout import runs_of_repeated_headers
from ._revolutions import REVOLUTION, unwrap_revolutions
from ._rollover import unwrap_rollover
from ._time_order import (
    group_interleaved, repeated_rows, repeated_rows_note, runs_at_restarts, take_rows,
)
from ._timer import largest_time_print_unit, time_print_unit, unwrap_timer, uniform_stamps
from ._timestamps import timestamp_seconds
from ._tools import tool_columns
from ._types import Log, Run
from ._resolution import column_print_units, find_step
from ._table import _Cells, _Table, _load_csv, _load_frame, _show
from ._columns import (
    _check_args, _column_scales, _find_columns, _first, _missing_cells, _positive_arg,
    _to_radians,
)
from ._validate import (
    check_lengths, check_motion, check_shared_zero, check_within_runs, run_blocks,
    sample_period, split_at_breaks,
)


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
        Kept for compatibility; it no longer refuses a log. Jittered or gapped time
        steps are data (the model is evaluated at the logged times); a run is split only
        at a break, a step longer than ``BREAK_PERIODS`` (5) of its median step, and
        the log's ``notes`` say so.
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
    a run; each run has enough samples; some run shows motion (at least 2 encoder
    steps, or 1e-9 rad when the resolution is unknown: a run that never moves is
    kept, a rest point inside the stick band, and named in ``Log.notes``; one held
    beyond a turning point another run of its set-up slid on from was never released:
    left out, named in ``Log.notes``, :mod:`._unreleased`). The
    sample period is the median time step; the steps may vary (jitter, dropped
    samples) and a run is split at a break (a step over 5 of its median steps, the
    gear moving on both sides), named in ``Log.notes``; without a ``run`` column, a
    timer restarted near its register's end (a forward jump of over half the register)
    or a pause of over 1000 median steps starts a new run, moving or not. A one-sample read dropout (a reading ten times farther from
    both neighbours than any change the run shows, while they agree) is dropped before
    the step is sought and named in ``Log.notes`` (more than 1 % of a run's rows is an
    error); a few readings off the encoder grid that all others lie on are kept and
    named. Fully blank lines are skipped, and so are a preamble above the header, ``#``
    comments, a units row (read into the names), repeated headers (each block a run when
    there is no run column), a footer of words and a last line cut mid-write (noted).
    Raw counts from a 16-, 24- or 32-bit register that rolls over are unwrapped (noted),
    and so is a single-turn angle that wraps at one revolution (:mod:`._revolutions`).
    A row that repeats the one above exactly is dropped; without a ``run`` column, time
    that drops back starts a new run (:mod:`._time_order`; both noted). A logger's 16- or
    32-bit timer that rolls over is unwrapped, and stamps coarser than a fixed-rate
    logger's sampling (4 kHz stamped to 1 ms) are rebuilt as uniform steps where every
    stamp lies within one print unit of them (:mod:`._timer`). Runs interleaved row by row
    are grouped by their labels; one angle column per run (``theta_1``, ``theta_2``) is
    read as runs, and a lone reading the logger missed (an empty or NaN cell with its
    time, free-motion logs) is a dropped sample (:mod:`._gaps`); all noted.
    Two held runs of one set-up at one reading that move off in opposite directions (a
    counter zeroed at each release) are an error.

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
    # a ROS topic dump or a PX4 flight-log export: the tool's names and units (._tools)
    table.notes = list(table.notes) + tool_columns(table)
    # one angle column per run, a reading the logger missed (hdid._log._gaps)
    table, gap_notes = wide_to_long(table, _missing_cells)
    cols = _find_columns(table, cpr, out_cpr, kt)
    note = []
    if _MOTOR not in cols:  # a driven row's torque acts until the next row: never dropped
        table, note = drop_missing_readings(table, cols[_THETA], cols[_TIME], _missing_cells)
    table.notes = list(table.notes) + gap_notes + note
    unit_scale = _column_scales(table, cols, cpr, out_cpr)
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
    # logs written one after another, each with its header (hdid._log._layout)
    run_labels, header_notes = runs_of_repeated_headers(table.header_repeats, table.block,
                                                        run_labels)
    setups = cells.labels(cols[_SETUP]) if _SETUP in cols else None
    # date-times (ISO 8601) in the time column are seconds after the first row
    # (hdid._log._timestamps)
    time = timestamp_seconds(table.columns[cols[_TIME]],
                             lambda m, pos: fail(m, _TIME, pos))
    stamped = time is not None
    if time is None:
        time = cells.numbers(cols[_TIME])
    else:
        unit_scale[_TIME] = 1.0
    theta = cells.numbers(cols[_THETA])
    inertia = cells.numbers(cols[_INERTIA]) if _INERTIA in cols else None
    motor = cells.numbers(cols[_MOTOR]) if driven else None
    theta_out = cells.numbers(cols[_THETA_OUT]) if _THETA_OUT in cols else None
    load = cells.numbers(cols[_LOAD_TORQUE]) if _LOAD_TORQUE in cols else None
    if driven and run_labels is not None:
        _check_not_mixed(table, cols[_MOTOR], run_labels)
    cells.raise_first()
    # a logger's timer register that rolls over (hdid._log._timer), in its own ticks
    time, timer_note, timer_restarts = unwrap_timer(time, table.lines, name(_TIME))
    jumps = np.zeros(n, dtype=bool)  # rows at which the timer was restarted near its end
    jumps[timer_restarts] = True
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

    # -- rows written twice, a clock that restarts (hdid._log._time_order) --------
    order_notes = [timer_note] if timer_note else []
    # runs written interleaved row by row, each row with its run label
    order, note = group_interleaved(run_labels, time, table.lines)
    if order is not None:
        order_notes.append(note)
        run_labels, setups, time, theta, inertia, motor, theta_out, load = (
            None if v is None else v[order]
            for v in (run_labels, setups, time, theta, inertia, motor, theta_out, load))
        take_rows(table, order)
        jumps = jumps[order]
    # stamps coarser than a fixed-rate logger's sampling (hdid._log._timer): before the
    # rows written twice, which a held reading stamped twice would look like
    time, rebuilt = _uniform_stamps(time, run_labels, table, cols, unit_scale, stamped,
                                    order_notes)
    twice = repeated_rows([run_labels, setups, time, theta, inertia, motor, theta_out, load])
    if twice.size:
        order_notes.append(repeated_rows_note(table.lines, twice))
        keep = np.setdiff1d(np.arange(n), twice)
        run_labels, setups, time, theta, inertia, motor, theta_out, load = (
            None if v is None else v[keep]
            for v in (run_labels, setups, time, theta, inertia, motor, theta_out, load))
        take_rows(table, keep)
        jumps = jumps[keep]
        n = int(keep.size)
    # (a labelled run splits at a forward jump only: hdid._log._time_order)
    run_labels, restart_notes = runs_at_restarts(time, run_labels, table.lines,
                                                 min_samples_per_run, np.flatnonzero(jumps),
                                                 labelled=_RUN in cols)
    order_notes += restart_notes
    if restart_notes or _RUN not in cols:
        time, again = _uniform_stamps(time, run_labels, table, cols, unit_scale, stamped,
                                      order_notes)
        rebuilt = rebuilt or again

    # -- counts vs. radians (a count register that rolls over is unwrapped first) ------
    rollover_notes = []
    if cpr is not None:
        theta, note = unwrap_rollover(theta, table.lines, name(_THETA))
        rollover_notes += [note] if note else []
    if theta_out is not None and out_cpr is not None:
        theta_out, note = unwrap_rollover(theta_out, table.lines, name(_THETA_OUT))
        rollover_notes += [note] if note else []
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

    # -- runs, sampling, motion (hdid._log._validate) ------------------------
    starts, names = run_blocks(run_labels, n, fail)
    ends = np.append(starts[1:], n)
    # a single-turn angle that wraps at one revolution (hdid._log._revolutions)
    theta, wrap_notes = unwrap_revolutions(
        theta, starts, ends, names, setups, table.lines, name(_THETA),
        cpr if cpr is not None else REVOLUTION / unit_scale[_THETA])
    if theta_out is not None:
        theta_out, note = unwrap_revolutions(
            theta_out, starts, ends, names, setups, table.lines, name(_THETA_OUT),
            out_cpr if out_cpr is not None else REVOLUTION / unit_scale[_THETA_OUT])
        wrap_notes += note
    new_run = np.zeros(n, dtype=bool)
    new_run[starts] = True
    within = ~new_run[1:]  # step i -> i+1 stays inside one run
    check_within_runs(setups, inertia, time, within, fail)
    lengths = ends - starts
    check_lengths(lengths, starts, names, min_samples_per_run, _RUN in cols, fail)
    period = sample_period(time, within, fail)
    starts, ends, names, notes = split_at_breaks(time, theta, starts, ends, names,
                                                 min_samples_per_run)
    notes = (list(table.notes) + header_notes + order_notes + rollover_notes + wrap_notes
             + notes)
    # one-sample read dropouts (a bus servo's -pi) leave before the step is sought
    # (hdid._log._dropouts)
    dropped, dropout_notes = find_dropouts(time, theta, starts, ends, names, table.lines, fail)
    notes += dropout_notes
    rows = [np.setdiff1d(np.arange(a, b), dropped, assume_unique=True)
            for a, b in zip(starts, ends)]
    lengths = np.array([r.size for r in rows], dtype=np.int64)
    kept = np.concatenate(rows)
    if not driven:  # a driven run's motor may push either way from any angle
        check_shared_zero(theta, rows, names, setups, fail)
    # the step from the readings' levels, within their printing precision (per run: any
    # offset); hdid._log._resolution
    run_starts = np.concatenate(([0], np.cumsum(lengths)[:-1]))
    printed = column_print_units(table.columns[cols[_THETA]], unit_scale[_THETA], cpr)
    print_unit = None if printed is None else float(np.max(printed[kept]))
    # the time column's printing (a stamp is the instant cut to it): none where the
    # times are date-times or were rebuilt as uniform steps
    time_unit = None if stamped or rebuilt else largest_time_print_unit(
        table.columns[cols[_TIME]], unit_scale[_TIME], kept, time)
    resolution_note = None
    if resolution is None:
        found = find_step(theta[kept], None if printed is None else printed[kept], run_starts)
        resolution, resolution_note = found.step, found.note
        resolution_source = "estimated" if resolution is not None else None
        if resolution is not None and found.note:  # a step another one rivals
            notes.append(f"column '{name(_THETA)}': {found.note}")
        if found.off_grid:
            notes.append(_off_grid_note(found, kept, time, theta, table.lines, names,
                                        run_starts))
    if theta_out is not None and output_resolution is None:
        printed_out = column_print_units(table.columns[cols[_THETA_OUT]],
                                         unit_scale[_THETA_OUT], None)
        output_resolution = find_step(
            theta_out[kept], None if printed_out is None else printed_out[kept], run_starts
        ).step
    left_out: list[int] = []  # still runs never released (hdid._log._unreleased)
    if not driven:  # a driven run may stay stuck
        motion_notes, left_out = check_motion(
            theta[kept], run_starts, run_starts + lengths, names, resolution,
            lambda m, key=None, pos=None: fail(m, key, None if pos is None else int(kept[pos])),
            None if setups is None else [str(setups[a]) for a in starts])
        notes += motion_notes

    def part(values: np.ndarray | None, k: int) -> np.ndarray | None:
        return None if values is None else values[rows[k]]

    runs = tuple(
        Run(
            name=names[k],
            time=time[rows[k]],
            theta=theta[rows[k]],
            setup="1" if setups is None else str(setups[starts[k]]),
            added_inertia=0.0 if inertia is None else float(inertia[starts[k]]),
            first_row=int(table.lines[starts[k]]),
            motor_torque=part(motor, k),
            theta_out=part(theta_out, k),
            load_torque=part(load, k),
        )
        for k in range(len(starts)) if k not in left_out
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
        notes=tuple(notes),
        print_unit=print_unit,
        resolution_note=resolution_note,
        time_print_unit=time_unit,
    )


def _uniform_stamps(time, run_labels, table, cols, unit_scale, stamped, notes):
    """:func:`._timer.uniform_stamps` over the runs as labelled so far (notes appended),
    and whether it rebuilt any time."""
    if stamped:
        return time, False
    block_start = np.zeros(time.size, dtype=bool)
    block_start[:1] = True
    if run_labels is not None:
        block_start[1:] = run_labels[1:] != run_labels[:-1]
    block_start[1:] |= np.diff(time) < 0  # a clock restarted, before the runs are split
    time, stamp_notes = uniform_stamps(
        time, block_start, lambda: time_print_unit(table.columns[cols[_TIME]], unit_scale[_TIME]),
        table.lines, run_labels)
    notes += stamp_notes
    return time, bool(stamp_notes)


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


def _off_grid_note(found, kept, time, theta, lines, names, run_starts) -> str:
    """One line naming the readings off the encoder grid that every other reading lies
    on (:mod:`._grid_outliers`): kept as read."""
    shown = []
    for i, by in list(zip(found.off_grid, found.off_by))[:5]:
        row = int(kept[i])
        run = names[int(np.searchsorted(run_starts, i, side="right")) - 1]
        shown.append(f"run {_show(run)} row {int(lines[row])} (t = {time[row]:.6g} s, "
                     f"{theta[row]:.6f} rad, {by:.2f} step off)")
    more = len(found.off_grid) - len(shown)
    return (
        f"{len(found.off_grid)} reading(s) lie off the encoder grid of {found.step:.4g} rad "
        f"that all the others lie on: {'; '.join(shown)}{f'; and {more} more' if more else ''}"
        f" — a logger's glitch, not a finer encoder (a finer grid would put this many "
        f"levels on one coarse grid with chance < 1e{math.ceil(found.off_grid_log10_chance)}); "
        "kept as read"
    )
