"""Is a fit plausible? The log's numbers for the declared units (time in s, angles in rad),
its sampling against the fitted swing, and the residual against its floor: what the sensor
alone leaves, the rounding of a quantized sensor (RMS = step/√12, exact: a uniform error) or
the readings' noise σ estimated from their still stretches (a noise model's resolution is
σ·√12)."""

from __future__ import annotations

import math

import numpy as np
from scipy.special import chdtrc

from .._log._resolution import step_against_readings
from .._simulation._aliasing import aliasing_warning, swing_hz
from .._simulation._phase_error import BIAS_SHARE, frequency_bias, substep_for_error
from .._simulation._prepare import Prepared
from .._simulation._simulate import substeps_for
from ._limits import FLOOR_TAIL, _chi2_ppf

#: An adequate model leaves the rounding of a quantized sensor: RMS ≈ step/√12 (uniform
#: error; less with stuck stretches — 0.6–0.9× measured at the truth of 4-run paper logs).
#: Above 3× the fit has not described the log: in 200 generator paper logs three
#: multistart fits ended in poorer basins at 4.2×, 4.3× and 11.9× while their truths
#: scored 0.6–0.9×; detectable missing effects in the hidden-effect suites sit at 1.3–32×.
RESIDUAL_FLOOR_FACTOR = 3.0


def floor_test(n_effective: float, rms_over_floor: float, n_unknowns: float = 0
               ) -> tuple[float, float, float, float]:
    """``(chi2, nu, p, bound)``: the χ² test of a residual against an exactly known floor.
    At the floor the residuals are the rounding alone, so ``chi2 = n·(RMS/floor)²`` over the
    ``n`` effective readings is χ²-distributed with ``nu = n − n_unknowns`` degrees of
    freedom (Gaussian errors; uniform rounding scatters less, kurtosis 1.8 against 3, so a
    small ``p`` is conservative); ``p`` its upper tail and ``bound`` the RMS multiple of the
    floor at ``p = FLOOR_TAIL``: √(χ²_ν(1 − FLOOR_TAIL)/n). No allowance for the simulator:
    its integrator error is refitted at a finer substep where it matters
    (:func:`hdid._fitting._substep.for_precision`) and named by :func:`integrator_warning`
    (HV7 world log07, 2^17 counts: 1.36× the floor, χ² 1260 on ν 660, z +16.5, silent under
    the 3.06× that an allowance of 1e-4 of the swing gave, which the 3× warning overtook)."""
    n = max(float(n_effective), 1.0)
    nu = max(n - max(float(n_unknowns), 0.0), 1.0)
    chi2 = n * float(rms_over_floor) ** 2
    return chi2, nu, float(chdtrc(nu, chi2)), math.sqrt(_chi2_ppf(1.0 - FLOOR_TAIL, nu) / n)


def residual_warnings(prep: Prepared, rms: float, n_unknowns: int = 0) -> list[str]:
    """What the RMS residual ``rms`` [log units] of a fit says: a step that does not match
    the readings, a model that does not describe the log (above
    :data:`RESIDUAL_FLOOR_FACTOR`× the floor) or, on a quantized sensor, a fit that has not
    reached the floor (:func:`floor_test`: χ² of the log's effective readings on their
    degrees of freedom after the fit's ``n_unknowns``, upper tail below
    :data:`~hdid._fitting._limits.FLOOR_TAIL`); none at the floor."""
    # (the floor: the step's rounding, the readings' print rounding where the print unit is
    # within a few steps, and the time stamps' where they are rounded instants)
    out, floor = [], float(getattr(prep, "floor", prep.resolution / math.sqrt(12)))
    parts = ["step"] + (["print"] if getattr(prep, "print_rms", 0.0) else []) + (
        ["time stamps"] if getattr(prep, "time_scale", None) is not None else [])
    timed = len(parts) > 1
    rounding = ", ".join(parts[:-1]) + f" and {parts[-1]}"
    whose = {"step": "the encoder's", "print": "the readings' print",
             "time stamps": "the time stamps'"}
    whose = ", ".join(whose[k] for k in parts[:-1]) + f" and {whose[parts[-1]]}"
    if wrong_step := (step_against_readings(prep.theta, prep.lengths, prep.resolution, rms,
                                            RESIDUAL_FLOOR_FACTOR) if prep.quantized else None):
        out.append(wrong_step)
    elif math.isfinite(rms) and rms > RESIDUAL_FLOOR_FACTOR * floor:
        out.append(  # (a noise model's resolution is σ·√12, σ from the still readings)
            f"the RMS residual is {rms / floor:.3g}× the "
            + ((f"floor of {whose} rounding" if timed else
                "quantization floor") if prep.quantized else "readings' noise")
            + ": the model does not describe this log, and the standard "
            "errors (which assume it does) are not trustworthy — a poorer basin (more "
            "--starts, or a warm --start), a missing effect (try `hdid diagnose`), wrong units, "
            "a wrong resolution or noise beyond the sensor's step"
        )
    elif prep.quantized and math.isfinite(rms) and (
            test := floor_test(prep.n_effective, rms / floor, n_unknowns))[2] < FLOOR_TAIL:
        chi2, nu, p, above = test
        out.append(
            f"the RMS residual is {rms / floor:.3g}× the "
            f"{f'rounding ({rounding})' if timed else 'quantization'} floor, above the "
            f"{above:.3g}× that rounding alone leaves: χ² {chi2:.4g} on ν {nu:.0f} "
            f"({prep.n_effective:.0f} effective readings, {n_unknowns} unknowns), p {p:.2g} "
            f"(tail {FLOOR_TAIL:g}): the fit has not reached the floor — a poorer basin (more "
            "--starts, or a warm --start), a missing effect (try `hdid diagnose`), the RK4 "
            "substep (refit with a smaller max_substep) or the time stamps (jitter or a "
            "drifting clock beyond their rounding); the standard errors are scaled up by the "
            "residual but still assume the model"
        )
    # (readings on no grid: their floor σ is itself estimated from the still stretches, so
    # a χ² against it is no exact test; they keep the 3× "does not describe" rule alone)
    return out


def plausibility_warnings(prep: Prepared, model, values, rms: float,
                          fitted_hz: float = math.nan, n_unknowns: int = 0) -> list[str]:
    """Warn when the log's numbers are implausible for the declared units (time in s,
    angles in rad), its sampling (the fitted swing ``fitted_hz`` aliased) or the residual
    ``rms`` of a fit of ``n_unknowns`` (:func:`residual_warnings`)."""
    out = []
    fs = 1.0 / prep.sample_period
    if fs < 5.0:
        out.append(
            f"the sample rate is {fs:.3g} Hz: implausibly low for this test if time is in "
            "seconds (a log in milliseconds reads as 1000× slower): convert time to seconds"
        )
    amp = float(np.max(np.abs(prep.hold - prep.rest))) if prep.n_runs else 0.0
    if aliased := aliasing_warning(prep.sample_period, swing_hz(
            fitted_hz, values, amp / model.ratio), prep.frequency_hz):
        out.append(aliased)
    has_gravity = any(e.name == "gravity" for e in model.effects)
    if (not has_gravity and ("k1" in values and model.ratio > 1 and amp / model.ratio > 0.05
                             or amp > math.pi)):
        out.append(
            f"the logged swing {amp:.3g} rad at the input is {amp / model.ratio:.3g} rad at the "
            f"output (ratio {model.ratio:g}): a strain-wave gear twists ~1e-3 rad at rated "
            "torque and a spring test rarely swings over half a turn — is theta in degrees, "
            "mrad or counts (convert to rad, or --counts-per-rev), or is the ratio wrong "
            "(--ratio)?"
        )
    out += residual_warnings(prep, rms, n_unknowns)
    return out


#: Readings in motion a run should have for the warning's suggested rate.
ASK_MOVING_READINGS = 10


def motion_warning(problem, prep: Prepared, moving) -> list[str]:
    """Too few readings in motion for the swing's unknowns. A hold fixes its run's start
    angle and a rest its place in the stick band; the stiffness, the friction law and the
    release instants rest on the readings taken while the gear moves. Fewer of those than
    such unknowns determine none of them (sweep log, an 84 Hz gear released inside 3.3
    stick bands at 250 Hz: each run moves for one reading, every standard error ∞): the
    warning says so and asks for the rate that gives each run's motion
    :data:`ASK_MOVING_READINGS` readings."""
    moving = np.asarray(moving, dtype=int)
    n_swing = problem.n_physical + (problem.n_runs if problem.release_free else 0)
    if moving.size == 0 or int(moving.sum()) >= n_swing:
        return []
    dt = prep.sample_period
    shortest = (int(moving.min()) + 1) * dt  # the motion ends before the next reading
    per_run = ", ".join(str(int(m)) for m in moving)
    return [
        f"the runs move for only {per_run} reading(s) (run by run; {int(moving.sum())} in all, "
        f"against {n_swing} unknowns of the swing: {problem.n_physical} parameters"
        + (f" and {problem.n_runs} release instants" if problem.release_free else "")
        + "; the holds and rests fix only the start angles and the stick band): the data "
        "cannot determine the stiffness and friction — log faster (at least "
        f"{ASK_MOVING_READINGS / shortest:.3g} Hz, {ASK_MOVING_READINGS} readings in a "
        f"run's motion of under {shortest * 1e3:.3g} ms) or release from further outside "
        "the stick band"]


def integrator_warning(problem, prep: Prepared, values: dict, frequency: tuple[float, float]
                       ) -> list[str]:
    """The RK4 substep's phase error (:mod:`hdid._simulation._phase_error`) where it is more
    than :data:`~hdid._simulation._phase_error.BIAS_SHARE` of the fitted frequency's
    standard error (``frequency``: natural frequency [Hz] and its std): the fitted
    frequency and ``k1`` are then biased high by more than the errors say. The swing is
    the natural frequency hardened at the log's largest release (:func:`swing_hz`); the
    substep the one run, the sample period split into whole substeps of at most
    ``max_substep`` (:func:`~hdid._simulation._simulate.substeps_for`)."""
    f0, sd = frequency
    h = float(getattr(problem, "max_substep", math.nan) or math.nan)
    if not (math.isfinite(f0) and f0 > 0 and math.isfinite(sd) and sd > 0 and h > 0):
        return []
    h = prep.sample_period / substeps_for(prep.sample_period, h)  # the substep run
    amp = float(np.max(np.abs(prep.hold - prep.rest))) if prep.n_runs else 0.0
    ratio = float(getattr(problem.base, "ratio", 1.0) or 1.0)
    f = swing_hz(f0, values, amp / ratio)
    bias, rel = frequency_bias(h, f), sd / f0
    if not bias > BIAS_SHARE * rel:
        return []
    return [f"the fitted frequency and k1 rest on the RK4 substep: at {1e3 * h:.4g} ms "
            f"(h·ω {2 * math.pi * f * h:.2g} at the {f:.4g} Hz swing) the simulated swing "
            f"runs slow by (h·ω)⁴/120 = {bias:.2g}, which the fit takes up: the frequency high "
            f"by up to {bias / rel:.2g} of its standard error, k1 (with k2) by up to "
            f"{2e6 * bias:.3g} ppm — "
            f"refit with max_substep={substep_for_error(h, f, rel):.4g} (s)"]
