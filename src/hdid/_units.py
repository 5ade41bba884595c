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
         "us": 1e-6, "µs": 1e-6, "μs": 1e-6, "ns": 1e-9, "min": 60.0}
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


# ------------------------------------------------------------ plausible units

#: Slowest sample rate [Hz] of a plausible encoder log of a swing: below it, time is
#: probably in ms (or µs) read as seconds.
MIN_SAMPLE_RATE_HZ = 5.0
#: Largest swing at a gear's output [rad] plausible for a spring test of a strain-wave
#: gear (it twists ~1e-3 rad at rated torque; a test reaches a few times that, so 0.05
#: rad is an order of magnitude of headroom).
MAX_GEAR_OUTPUT_SWING = 0.05
#: Fastest plausible speed [rad/s] at the logged axis of a driven log: 20 000 rpm, above
#: the highest rated input speed of strain-wave gears (14 000 rpm, the smallest sizes)
#: and of servo motors. A motor log in degrees read as rad passes it above ~350 rpm.
MAX_SPEED = 2100.0


def implausible_units(*, sample_period: float, swing: float, ratio: float,
                      band_halfwidth: float, step: float | None, geared_spring: bool,
                      speed: float = 0.0) -> str | None:
    """One line naming the unit a log's numbers are implausible in, with the fix, or None.

    ``sample_period`` [s as declared], ``swing`` the largest |start − rest| of a run at
    the logged axis and ``band_halfwidth`` the fitted stick band's half-width [rad as
    declared], ``ratio`` the gear ratio, ``step`` the encoder step, ``geared_spring``
    whether the model is a gear's stiffness without gravity (where the output twists
    little), ``speed`` the largest speed at the logged axis [rad/s as declared] — the
    measure of a driven log, whose motor turns freely (give it ``swing = 0``). A log whose
    numbers are consistent but scaled (ms read as s, degrees read as rad) fits as well as
    the right one: only the absolute sizes tell.
    """
    fs = 1.0 / sample_period if sample_period > 0 else math.inf
    if fs < MIN_SAMPLE_RATE_HZ:
        for unit, f in (("ms", 1e3), ("us", 1e6)):
            if fs * f >= MIN_SAMPLE_RATE_HZ:
                break
        return (
            f"units: the sample rate is {fs:.3g} Hz if time is in seconds — implausibly "
            f"slow; if time is in {unit}, write the header `time [{unit}]` (or convert "
            "time to seconds)"
        )
    output_swing = swing / ratio if ratio > 0 else swing
    too_wide = (geared_spring and ratio > 1 and output_swing > MAX_GEAR_OUTPUT_SWING
                or swing > math.pi or band_halfwidth > math.pi)
    too_fast = speed > MAX_SPEED
    if not (too_wide or too_fast):
        return None
    what = (f"the swing is {swing:.3g} rad at the logged axis ({output_swing:.3g} rad at "
            f"the output, ratio {ratio:g})" if swing > 0 else "")
    if band_halfwidth > math.pi or not what:
        what = f"the stick band's half-width is {band_halfwidth:.3g} rad"
    if too_fast and not too_wide:
        what = (f"the speed reaches {speed:.3g} rad/s ({speed * 30 / math.pi:.3g} rpm) at "
                "the logged axis")
    if step is not None and abs(step - round(step)) < 1e-6 * max(step, 1.0) and step >= 1:
        fix = "theta holds raw counts: pass --counts-per-rev N"
    else:
        deg = math.pi / 180.0
        plausible = (lambda s: (s / ratio if geared_spring and ratio > 1 else 0.0)
                     <= MAX_GEAR_OUTPUT_SWING and s <= math.pi)
        fixes = [f"if theta is in {name}, write the header `theta [{unit}]`"
                 for name, unit, f in (("degrees", "deg", deg), ("mrad", "mrad", 1e-3))
                 if plausible(swing * f) and speed * f <= MAX_SPEED]
        fix = "; ".join(fixes or ["if theta holds raw counts, pass --counts-per-rev N"])
        fix += " (or check --ratio)"
    return f"units: {what} — implausible if theta is in radians; {fix}"
