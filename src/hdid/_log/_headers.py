"""A header cell to its canonical column and unit: ``Theta (deg)``, ``time [ms]``,
``time_ms``, ``t[s]``, ``Motor Torque [mNm]``.

Loggers, spreadsheets and controllers name their columns in their own way. A header is
read as a known column name (case-insensitive; spaces and hyphens count as ``_``, and a
bare ``t`` is ``time``) followed by an optional unit: in brackets or parentheses
(``theta [deg]``, ``t(s)``), after a slash (``t/s``, ``Theta / deg``) or, when the name alone is not a known column, as a
``_unit`` suffix (``time_ms``, ``theta_deg``) where the suffix is a unit the column knows
(:mod:`hdid._units`). A ``timestamp`` with its unit (``timestamp [ms]``, ``Timestamp (s)``,
``timestamp_us``) is the time. Anything else is not one of hdid's columns and is ignored.
"""

from __future__ import annotations

import re

from .. import _units
from ._names import _KNOWN_COLUMNS, _THETA, _THETA_OUT, _TIME

#: Angle columns, which may be given in encoder counts (``theta_cts``).
_ANGLES = (_THETA, _THETA_OUT)
#: Other names loggers give a known column: a bare ``t``, LabVIEW's ``X_Value`` (the
#: time of an ``.lvm`` file), a drive's ``Position`` or ``pos``, a rig's ``Angle`` or
#: ``Encoder`` (raw counts when integers: the count rules of :mod:`._columns` apply), the
#: two encoders of a motor-and-output set-up (``motor_pos``, ``load_pos``). A column named
#: by its canonical name wins over one named by an alias; two angle columns named by
#: aliases (``Angle`` and ``Encoder``) are ambiguous and refused.
_ALIASES = {"t": _TIME, "x_value": _TIME, "pos": _THETA, "position": _THETA,
            "angle": _THETA, "encoder": _THETA,
            # a motor-and-output layout's two encoders
            **dict.fromkeys(("motor_pos", "motor_position", "motor_angle", "theta_motor"),
                            _THETA),
            **dict.fromkeys(("load_pos", "load_position", "load_angle", "theta_load",
                             "output_pos", "output_position", "output_angle", "out_pos"),
                            _THETA_OUT)}


#: Names that carry their unit: an Arduino sketch's ``millis()`` and ``micros()``.
_WITH_UNIT = {"millis": (_TIME, "ms"), "micros": (_TIME, "us")}
#: Names that are a known column only with their unit written (``timestamp [ms]``,
#: ``timestamp (s)``, ``timestamp_us``): a bare ``timestamp`` is a tool's convention
#: (PX4's µs since boot, ROS's ns since 1970: :mod:`._tools`, which also takes a bare one
#: of date-times).
_WITH_UNIT_ONLY = {"timestamp": _TIME, "time_stamp": _TIME}


def _canonical(base: str) -> str:
    """``Motor Torque`` → ``motor_torque``; aliases (``t``) to their column."""
    key = re.sub(r"[\s\-]+", "_", base.strip().lower())
    return _ALIASES.get(key, key)


def header_key(name: str) -> tuple[str, str | None]:
    """``(key, unit)`` of a header cell: ``key`` is a canonical column name when the
    header names one (else the lower-cased header), ``unit`` the unit written with it
    (``None`` when none is)."""
    base, unit = _units.split(name)
    if unit is None and "/" in base:  # ``t/s``, ``Theta / deg`` (quantity / unit)
        head, _, tail = base.rpartition("/")
        if _canonical(head) in _KNOWN_COLUMNS or _canonical(head) in _ALIASES:
            base, unit = head, tail.strip()
    key = _canonical(base)
    if unit is None and key in _WITH_UNIT:
        return _WITH_UNIT[key]
    if unit is not None and key in _WITH_UNIT_ONLY:
        return _WITH_UNIT_ONLY[key], unit
    if key in _KNOWN_COLUMNS or unit is not None:
        return key, unit
    head, sep, tail = key.rpartition("_")
    if sep and head:
        head = _ALIASES.get(head, _WITH_UNIT_ONLY.get(head, head))
        counts = head in _ANGLES and tail.isalpha() and _units.scale("counts", tail) is not None
        if head in _KNOWN_COLUMNS and (_units.scale(head, tail) is not None or counts):
            return head, tail
    return key, None


def is_known(name: str) -> bool:
    """Whether a header cell names one of hdid's columns."""
    return header_key(name)[0] in _KNOWN_COLUMNS


def by_alias(name: str) -> bool:
    """Whether a header cell names its column by an alias (``Position [deg]``), not by its
    canonical name."""
    base, unit = _units.split(name)
    key = re.sub(r"[\s\-]+", "_", base.strip().lower())
    head = key.rpartition("_")[0]
    return (key in _ALIASES or (unit is None and head in _ALIASES)
            or key in _WITH_UNIT_ONLY or (unit is None and head in _WITH_UNIT_ONLY))
