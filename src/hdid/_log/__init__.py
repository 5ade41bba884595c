"""Reading, validating and writing encoder logs: free-motion and driven.

A free-motion test twists the wave generator (the motor side of the harmonic
drive) by about ±0.157 rad, releases it and logs its encoder (~250 Hz) while
it springs back and sticks. A *log* is a CSV file with a header line and the
columns

``time``
    Sample time [s]; strictly increasing within a run (it may restart at each
    run). The steps may vary (logger jitter, dropped samples): the model is
    evaluated at the logged times. A step longer than 5 of the run's median steps
    is a break: the run is split there and ``Log.notes`` says so.
``theta``
    Wave-generator angle [rad], or raw encoder counts when ``counts_per_rev`` is
    given (``counts`` is accepted as an alias in that case).
``run`` (optional)
    Label of the release the row belongs to; the rows of one run must be
    contiguous. Without it the whole file is one run named ``"1"``, or, where time
    drops back (a clock restarted at each release), one run per stretch
    (``"1"``, ``"2"``, …; noted).
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

Column names are matched case-insensitively after stripping whitespace, with a unit
in brackets, after a slash or as a suffix (``time [ms]``, ``t/s``, ``theta_deg``;
:mod:`._headers`); other columns are ignored. What loggers write around the table — a
preamble, ``#`` comments, a units row, a repeated header, a footer, a last line cut
mid-write — is found by :mod:`._layout`; a count register that rolls over is unwrapped
(:mod:`._rollover`); date-times are seconds (:mod:`._timestamps`); a logger's timer that
rolls over and stamps coarser than its sampling are read by :mod:`._timer`; one angle
column per run and a reading the logger missed by :mod:`._gaps`; a MATLAB ``.mat``
file's vectors are its columns (:mod:`._mat`). :func:`read_log` checks everything and raises
:class:`~hdid._errors.LogError` with a one-line message naming the file, the
column and/or the CSV line and the fix. The file is only ever read.

This module must stay light: it imports numpy and pandas only (no JAX).
"""

from __future__ import annotations

from ._read import read_log
from ._resolution import estimate_resolution
from ._types import Log, Run
from ._write import write_log

__all__ = ["Log", "Run", "estimate_resolution", "read_log", "write_log"]
