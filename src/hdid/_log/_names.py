"""Column names, their aliases and the hints that error messages give."""

from __future__ import annotations

import re


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

#: An angle column labelled with its run: ``theta_1``, ``theta run 2``, ``position_run_a``
#: (a number, or a label after ``run``: ``pos_cmd`` and ``pos_act`` are no runs).
_RUN_COLUMN = re.compile(r"^(?:theta|pos|position)_?(?:run_?([0-9a-z]+)|([0-9]+))$")
