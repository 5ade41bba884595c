"""Never sample around a poorer basin: the fit's residual against its noise floor.

A posterior is a statement about the neighbourhood of an optimum. When the least-squares
fit has not reached the quantization floor, its optimum may be a poorer basin of the
cost (a clean 1 kHz log of an independent simulator ended at 3.55× the floor, and the
posterior around it put the true ``tau_c`` 20 % outside its interval), or the model may
lack an effect the log shows; either way the intervals would describe the wrong place.

Before any sampling (:func:`basin_check`), a fit whose RMS residual is above
``BASIN_FACTOR`` × the floor (``step/√12``, or the readings' scatter where the gear rests
if larger: :func:`noise_floor`) is first refitted at the RK4 substep its own fitted swing
asks for, when that is finer than the one it ran at (:func:`substep_wanted`: the fit picks
its substep from the log's turning points, which alias a swing above the log's Nyquist
frequency), then goes through the fit's own limit and restart
checks (:mod:`hdid._fitting._limits`: Coulomb friction, no dry friction, the linear
spring; each limit fitted, the full model restarted next to its optimum, the best kept).
A fit at its floor is refitted finer too when its substep clearly under-resolves its
fitted swing (``h·ω`` above :data:`AT_FLOOR_HW`): the sampler simulates at the fit's
substep, and there the simulation is off the dynamics it models.
A fit that already went through them (``fit.limits`` names every limit of its model) is
at its best known optimum and is reused as it is. If the residual is still above
``BASIN_FACTOR`` × the floor, :func:`basin_check` returns one line saying that the
intervals would describe the wrong basin; the sampler then prints it before sampling and
carries it first in the result's warnings and at the top of its report.

A check that was needed (above the floor, or a substep the fitted swing does not resolve)
but could not refit for want of the log (a fit of a DataFrame has no file to reread, and
no ``log=`` was given) leaves the result untrustworthy: :func:`basin_check` then also
returns a ``BASIN NOT CHECKED`` line naming the fix, which the result carries in its
warnings (after the statement, if any).

Why sample anyway rather than refuse: above the floor for lack of an effect the
posterior is still the model's (conditional on it), and a step that does not describe the
readings (a wrong ``--resolution``) puts every fit above the floor; a refusal would leave
the user with nothing, the statement keeps the intervals from being read as the data's.
"""

from __future__ import annotations

import dataclasses
import math
import sys
from dataclasses import dataclass
from pathlib import Path

# the substep the fitted swing asks for: the fit's own rule, in one place (``hdid.fit``
# refits by it where its substep clearly under-resolves the swing, ``at_floor``; above the
# floor this check asks it plainly)
from .._fitting._substep import AT_FLOOR_HW, substep_wanted  # noqa: F401

#: Residual, as a multiple of the quantization floor, above which the fit has not reached
#: its best basin: exact models on clean logs leave 0.4–1.0× the floor (less where the gear
#: sticks); the fit's own floor test (``_limits.above_floor``) is 1.2–1.4× for 35–500
#: effective samples; 1.5× leaves room for the χ² scatter of short logs.
BASIN_FACTOR = 1.5
#: Residual (multiple of the floor) beyond which the statement also suspects the step: 5
#: steps RMS, where the posterior's noise prior stops trusting the step
#: (``density.SIGMA_BOUNDS[1] / NOISE_BOUND_OVER_RMS``).
STEP_SUSPECT = 5.0 * math.sqrt(12.0)


@dataclass
class BasinCheck:
    """What :func:`basin_check` found: ``rms_over_floor`` before and after the checks,
    which checks ran (``checks``), the limit the fit was restarted from, the statement
    (``None``: the fit is at the floor) and ``unchecked``: the warning when a check was
    needed but could not refit for want of the log (``None``: every needed check ran)."""

    rms_over_floor_before: float
    rms_over_floor: float
    checks: str
    restarted_from: str | None
    statement: str | None
    unchecked: str | None = None

    def to_dict(self) -> dict:
        return {"rms_over_floor_before": _num(self.rms_over_floor_before),
                "rms_over_floor": _num(self.rms_over_floor),
                "factor": BASIN_FACTOR, "checks": self.checks,
                "restarted_from": self.restarted_from, "statement": self.statement}


def _num(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


#: Readings at rest a run needs for its scatter to count in :func:`noise_floor` (fewer: the
#: run's scatter is not estimated; at 5, a pooled sd over 4 runs is good to ±17 %).
MIN_REST_READINGS = 5


def noise_floor(fit) -> float:
    """The residual a fit at its best basin leaves [rad]: the quantization floor
    (``step/√12``), or the scatter of the readings where the gear rests, if larger — the
    trailing stretch of each run that the log's preparation weights as one observation
    (within the flicker of its last reading), about its own mean, pooled over the runs.
    There the angle is constant, so the scatter is the sensor's noise whatever the fit
    says; on a noiseless encoder it is 0 and the quantization floor stands. Without it a
    log with noise before rounding (0.5 step: 1.9× the quantization floor) was stated to be
    in the wrong basin at its own noise level."""
    import numpy as np

    floor = float(fit.quantization_floor_rad)
    prob = getattr(fit, "problem", None)
    if prob is None:
        return floor
    theta, weight = np.asarray(prob.theta, dtype=float), np.asarray(prob.weight, dtype=float)
    ss, dof = 0.0, 0
    for th, w in zip(theta, weight):
        on = np.flatnonzero(w > 0)
        if on.size == 0:
            continue
        k = on[-1]
        while k >= 0 and 0 < w[k] < 1:
            k -= 1
        rest = th[k + 1 : on[-1] + 1]
        if rest.size >= MIN_REST_READINGS:
            ss += float(np.sum((rest - rest.mean()) ** 2))
            dof += rest.size - 1
    return max(floor, math.sqrt(ss / dof)) if dof > 0 else floor


def rms_over_floor(fit) -> float:
    """The fit's RMS residual as a multiple of its floor (:func:`noise_floor`)."""
    floor = noise_floor(fit)
    rms = float(fit.rms_residual_rad)
    return rms / floor if floor > 0 and math.isfinite(rms) else math.inf


def _fixed(fit) -> set[str]:
    return {n for n, p in fit.parameters.items() if p.fixed}


def basin_check(fit, log=None, *, echo: bool = True):
    """``(fit, BasinCheck)``: ``fit`` or, when it is above ``BASIN_FACTOR`` × the floor,
    the fit refitted at the substep its fitted swing needs (when finer than its own:
    :func:`substep_wanted`) and after its limit and restart checks when its limits were not
    all checked (both run on ``log``, else on ``fit.source`` when that is a file; the
    substep is asked again after the limit checks, which may find the true swing); the
    statement when it is still above. ``echo``: print the statement to standard error at
    once (before sampling)."""
    from .._fitting import _limits

    before = rms_over_floor(fit)
    h0 = float(getattr(getattr(fit, "problem", None), "max_substep", math.nan))
    ran: list[str] = []
    if before <= BASIN_FACTOR:  # at the floor: refined only where the swing is under-resolved
        # (twice at most: on an aliased log the refit may settle on a faster alias, whose
        # swing asks for a finer substep again)
        while len(ran) < 2 and (h := substep_wanted(fit, at_floor=True)) is not None:
            fit, what = _refit_finer(fit, log, h)
            ran.append(what)
            if rms_over_floor(fit) > BASIN_FACTOR or what.startswith("no refit"):
                break
        if (after := rms_over_floor(fit)) <= BASIN_FACTOR:
            return fit, BasinCheck(before, after, "; ".join(ran) or "none needed (at the floor)",
                                   getattr(fit, "restarted_from", None), None,
                                   _unchecked(ran, after, h0))
    for _ in range(2):  # the limit checks may find the true swing: its substep is asked again
        if (h := substep_wanted(fit)) is not None:
            fit, what = _refit_finer(fit, log, h)
            ran.append(what)
            if rms_over_floor(fit) <= BASIN_FACTOR:
                break
        limits = _limits.limits_of(fit.model, _fixed(fit))
        done = {r.get("limit") for r in (getattr(fit, "limits", None) or [])}
        if not limits:
            ran.append("no limit of this model to restart from")
        elif {lim.key for lim in limits} <= done:
            if not ran:
                ran.append("the fit's own limit and restart checks (its best known optimum, "
                           "reused)")
        else:
            fit, what = _rerun_limits(fit, log)
            ran.append(what)
        if substep_wanted(fit) is None:
            break
    checks = "; ".join(dict.fromkeys(ran))
    after = rms_over_floor(fit)
    statement = None
    if after > BASIN_FACTOR:
        statement = (
            f"WRONG BASIN: the fit's residual is {after:.2f}× the noise floor (above "
            f"{BASIN_FACTOR:g}×) after {checks}, so the intervals below would describe the "
            "wrong basin (a poorer optimum, or a model that lacks an effect the log shows), "
            "not the data's best fit — run `hdid diagnose` on the log (hdid.diagnose), add "
            "the effect it names (--add / model=) or refit from other starts (--start; in "
            "Python start_from_model=True), then sample again"
            + (f"; at {after / math.sqrt(12):.3g} encoder steps RMS the step itself may be "
               "wrong: pass the encoder's step (--resolution / resolution=)"
               if after > STEP_SUSPECT else ""))
        if echo:
            print(f"hdid: {statement}", file=sys.stderr, flush=True)
    return fit, BasinCheck(before, after, checks, getattr(fit, "restarted_from", None),
                           statement, _unchecked(ran, after, h0))


#: What :func:`_refit_finer` and :func:`_rerun_limits` say when they had no log to refit.
NO_LOG = "the log is not at hand: pass log= to sample_posterior"


def _unchecked(ran: list[str], after: float, h: float) -> str | None:
    """The warning line when a needed check (``ran``: what the basin check did) could not
    refit for want of the log; ``after``: the residual over the floor it left, ``h`` [s]:
    the fit's substep. ``None`` when every needed check ran."""
    missing = [what.split(" (", 1)[0] for what in ran if NO_LOG in what]
    if not missing:
        return None
    why = (f"its residual is {after:.2f}× the noise floor (above {BASIN_FACTOR:g}×)"
           if after > BASIN_FACTOR else
           f"its {1e3 * h:.4g} ms RK4 substep does not resolve its fitted swing")
    return (f"BASIN NOT CHECKED: {why}, but the basin check could not refit ("
            f"{'; '.join(dict.fromkeys(missing))}) for want of the log (no log= given and no file "
            "the fit read: a fit of a DataFrame), so the intervals may describe a poorer basin or a "
            "simulation off the dynamics it models — pass log= (the DataFrame) to "
            "sample_posterior")


def _log_at_hand(fit, log):
    """``log``, else the file the fit read (``fit.source``), else ``None``."""
    if log is None and isinstance(fit.source, str) and Path(fit.source).is_file():
        return fit.source
    return log


def _refit_finer(fit, log, h: float):
    """The fit redone at the substep ``h`` [s] (:func:`substep_wanted`): ``hdid.fit`` on
    ``log`` (or the file ``fit.source``) with the fit's model, fixed parameters and free
    inertia, started also from its optimum (``start_from_model``), its limit checks as the
    fit's own (``nested="auto"``: every limit while above the floor); ``(fit, what ran)``.
    The finer fit is kept whatever its residual: the coarser one's optimum belongs to a
    simulation that is off the dynamics it models, and so would its posterior."""
    from .._errors import HdidError
    from .._fitting import _fit

    old = float(fit.problem.max_substep)
    what = (f"a refit at the RK4 substep its fitted swing needs ({1e3 * h:.4g} ms; the fit "
            f"ran at {1e3 * old:.4g} ms) with its own limit and restart checks")
    if (log := _log_at_hand(fit, log)) is None:
        return fit, (f"no refit at the {1e3 * h:.4g} ms substep its fitted swing needs "
                     f"({NO_LOG})")
    try:
        new = _fit.fit(log, fit.model, fix=sorted(_fixed(fit)) or None,
                       free_inertia="inertia" in fit.problem.free, max_substep=h,
                       start_from_model=True)
    except (HdidError, ValueError, KeyError, OSError) as exc:
        return fit, f"no refit at the {1e3 * h:.4g} ms substep ({str(exc).splitlines()[0]})"
    if (new.problem.free, new.problem.n_unknowns, new.problem.release_free) != (
            fit.problem.free, fit.problem.n_unknowns, fit.problem.release_free):
        return fit, (f"no refit at the {1e3 * h:.4g} ms substep (the log does not rebuild the "
                     "fit's problem)")
    return new, what


def _rerun_limits(fit, log):
    """The fit's limit and restart checks, run now on ``log`` (or the file ``fit.source``)
    with every limit of its model (``nested=True``); ``(fit, what ran)``."""
    from .._errors import HdidError
    from .._fitting import _fit

    prob = fit.problem
    log = _log_at_hand(fit, log)
    if log is None:
        return fit, f"no limit checks ({NO_LOG}, or fit with nested=True)"
    if not prob.release_free:
        return fit, "no limit checks (the fit's release instants are fixed)"
    try:
        if getattr(fit, "first_reading_held", ()):  # the fit's story of its first readings
            from .._log import Log, read_log

            log = dataclasses.replace(log if isinstance(log, Log) else read_log(log),
                                      first_reading_held=tuple(fit.first_reading_held))
        setup = _fit._setup(log, fit.model, fix=sorted(_fixed(fit)),
                            free_inertia="inertia" in prob.free,
                            max_substep=float(prob.max_substep))
        if setup.problem.n_unknowns != len(fit.u) or setup.problem.free != prob.free:
            return fit, "no limit checks (the log does not rebuild the fit's problem)"
        new = _fit.nested_check(fit, log, setup, nested=True)
    except (HdidError, ValueError, KeyError, OSError) as exc:
        return fit, f"no limit checks ({str(exc).splitlines()[0]})"
    return new, "the limit and restart checks run now"
