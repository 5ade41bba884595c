"""Units written in a log's column headers: ``time [ms]``, ``theta (deg)``, ``motor_torque [mNm]``.

A header may carry its column's unit in square or round brackets after the name. The
reader converts such a column to the units hdid computes in (s, rad — or m for a linear
axis logged in lengths —, N m, A, kg m²), so that the parameters come out in those units.
A column without a unit is taken as it is: in consistent units of the user's choice.
"""

from __future__ import annotations

import math
import re

#: ``name [unit]`` or ``name (unit)`` (spaces around either part are ignored).
_WITH_UNIT = re.compile(r"^\s*(?P<name>[^\[\(]*?)\s*[\[\(]\s*(?P<unit>[^\]\)]*?)\s*[\]\)]\s*$")

_TIME = {"s": 1.0, "sec": 1.0, "second": 1.0, "seconds": 1.0, "ms": 1e-3, "msec": 1e-3,
         "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "min": 60.0}
_ANGLE = {"rad": 1.0, "mrad": 1e-3, "urad": 1e-6, "µrad": 1e-6, "μrad": 1e-6,
          "deg": math.pi / 180.0, "°": math.pi / 180.0, "degree": math.pi / 180.0,
          "degrees": math.pi / 180.0, "arcmin": math.pi / 10800.0,
          "arcsec": math.pi / 648000.0, "rev": 2.0 * math.pi, "turn": 2.0 * math.pi,
          "turns": 2.0 * math.pi,
          # a linear axis logs a position: lengths convert to metres
          "m": 1.0, "mm": 1e-3, "um": 1e-6, "µm": 1e-6, "μm": 1e-6}
_TORQUE = {"nm": 1.0, "mnm": 1e-3, "nmm": 1e-3, "unm": 1e-6, "µnm": 1e-6,
           # a linear axis is driven by a force: newtons stay newtons
           "n": 1.0, "kn": 1e3, "mn": 1e-3}
_CURRENT = {"a": 1.0, "ma": 1e-3}
_INERTIA = {"kgm2": 1.0, "kgm^2": 1.0, "kgm²": 1.0, "gcm2": 1e-7, "gcm^2": 1e-7,
            "gcm²": 1e-7, "kgmm2": 1e-6, "kgmm^2": 1e-6, "kgmm²": 1e-6,
            "kgcm2": 1e-4, "kgcm^2": 1e-4, "kgcm²": 1e-4, "kg": 1.0}
_COUNTS = {"counts": 1.0, "count": 1.0, "cts": 1.0, "-": 1.0, "1": 1.0}

#: The unit table of each canonical column (columns not listed take no unit).
UNITS = {
    "time": _TIME, "theta": _ANGLE, "theta_out": _ANGLE, "counts": _COUNTS,
    "output_counts": _COUNTS, "motor_torque": _TORQUE, "load_torque": _TORQUE,
    "motor_current": _CURRENT, "added_inertia": _INERTIA,
}
#: What a unitless column is read as (for the messages).
SI = {"time": "s", "theta": "rad", "theta_out": "rad", "motor_torque": "N m",
      "load_torque": "N m", "motor_current": "A", "added_inertia": "kg m^2"}


def split(header: str) -> tuple[str, str | None]:
    """``(name, unit)`` of a header; ``unit`` is ``None`` when it gives none."""
    m = _WITH_UNIT.match(str(header))
    if m is None or not m.group("name"):
        return str(header).strip(), None
    return m.group("name"), m.group("unit")


def _normal(unit: str) -> str:
    """Case and separators dropped: ``N·m``, ``N m``, ``N*m``, ``N.m`` → ``nm``."""
    u = unit.strip().lower()
    return u if u in ("-",) else re.sub(r"[\s·*.⋅]", "", u)


def scale(key: str, unit: str | None) -> float | None:
    """Factor that converts column ``key`` from ``unit`` to hdid's units; ``None`` for a
    unit the column does not know (the caller says which ones it does)."""
    if unit is None:
        return 1.0
    table = UNITS.get(key)
    if table is None:
        return None
    return table.get(_normal(unit), table.get(unit.strip()))


def known(key: str) -> str:
    """The units column ``key`` accepts, for an error message."""
    table = UNITS.get(key)
    if not table:
        return "none (remove the unit from the header)"
    shown = [u for u in table if u.isascii() and u not in ("1", "-")]
    return ", ".join(shown)
