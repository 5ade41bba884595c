"""Has a fit reached its floor? The residual against what the sensor alone leaves: the
rounding of a quantized sensor (RMS = step/√12, exact: a uniform error) or the readings'
noise σ estimated from their still stretches (a noise model's resolution is σ·√12)."""

from __future__ import annotations

import math

from .._log._resolution import step_against_readings
from .._simulation._prepare import Prepared
from ._limits import FLOOR_TAIL, above_floor

#: An adequate model leaves the rounding of a quantized sensor: RMS ≈ step/√12 (uniform
#: error; less with stuck stretches — 0.6–0.9× measured at the truth of 4-run paper logs).
#: Above 3× the fit has not described the log: in 200 generator paper logs three
#: multistart fits ended in poorer basins at 4.2×, 4.3× and 11.9× while their truths
#: scored 0.6–0.9×; detectable missing effects in the hidden-effect suites sit at 1.3–32×.
RESIDUAL_FLOOR_FACTOR = 3.0


def residual_warnings(prep: Prepared, rms: float) -> list[str]:
    """What the RMS residual ``rms`` [log units] of a fit says: a step that does not match
    the readings, a model that does not describe the log (above
    :data:`RESIDUAL_FLOOR_FACTOR`× the floor) or, on a quantized sensor, a fit that has not
    reached the floor (above the χ² tail test :func:`hdid._fitting._limits.above_floor` for
    the log's effective readings); none at the floor."""
    out = []
    if wrong_step := (step_against_readings(prep.theta, prep.lengths, prep.resolution, rms,
                                            RESIDUAL_FLOOR_FACTOR) if prep.quantized else None):
        out.append(wrong_step)
    elif math.isfinite(rms) and rms > RESIDUAL_FLOOR_FACTOR * prep.resolution / math.sqrt(12):
        out.append(  # (a noise model's resolution is σ·√12, σ from the still readings)
            f"the RMS residual is {rms / (prep.resolution / math.sqrt(12)):.3g}× the "
            + ("quantization floor" if prep.quantized else "readings' noise")
            + ": the model does not describe this log, and the standard "
            "errors (which assume it does) are not trustworthy — a poorer basin (more "
            "--starts, or a warm --start), a missing effect (try `hdid diagnose`), wrong units, "
            "a wrong resolution or noise beyond the sensor's step"
        )
    elif prep.quantized and math.isfinite(rms) and rms > (
            above := above_floor(prep.n_effective)) * prep.resolution / math.sqrt(12):
        out.append(
            f"the RMS residual is {rms / (prep.resolution / math.sqrt(12)):.3g}× the "
            f"quantization floor, above the {above:.3g}× that rounding alone leaves over "
            f"{prep.n_effective:.0f} effective readings (χ² tail {FLOOR_TAIL:g}): the fit has "
            "not reached the floor — a poorer basin (more --starts, or a warm --start) or a "
            "missing effect (try `hdid diagnose`); the standard errors are scaled up by the "
            "residual but still assume the model"
        )
    return out
