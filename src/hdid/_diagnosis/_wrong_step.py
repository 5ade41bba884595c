"""Diagnose's guard against a wrong encoder step: a base fit judged against a step far
finer than the readings' own spacing would call a clean log "unexplained"."""

from __future__ import annotations

import dataclasses

from .._log._resolution import readings_spacing, step_against_readings


def readings_step(log, model, fit_options, base_setup, base_grid, current, say, grid_starts):
    """A base fit whose residual is far above its step's floor but within the floor of the
    readings' own spacing (:func:`hdid._log._resolution.step_against_readings`) was given a
    wrong step: judged against it, a clean log would be "unexplained". The base is refitted
    with the readings' spacing as the step, and a warning says so. Returns the (new) set-up,
    grid, fit and the warning (``None`` when the step is consistent)."""
    from .._fitting import _refit  # lazily, as diagnose itself does
    from .._fitting._identifiability import RESIDUAL_FLOOR_FACTOR

    prep = base_setup.prep
    if not prep.quantized:
        return base_setup, base_grid, current, None
    wrong = step_against_readings(prep.theta, prep.lengths, prep.resolution,
                                  current.rms_rad(), RESIDUAL_FLOOR_FACTOR)
    if wrong is None:
        return base_setup, base_grid, current, None
    g = readings_spacing(prep.theta, prep.lengths)
    if not on_grid(prep.theta, prep.lengths, g):
        return base_setup, base_grid, current, None
    say(f"refitting the base model with the readings' spacing {g:.4g} as the step")
    log = dataclasses.replace(log, resolution=g, resolution_source="estimated")
    base_setup = _refit.setup(log, model, fit_options)
    base_grid = _refit.grid(base_setup, grid_starts)
    current = _refit.run("base", base_setup, [("grid", u) for u in base_grid])
    return base_setup, base_grid, current, (
        f"{wrong.split(': the step looks wrong')[0]}: the step {prep.resolution:.4g} looks "
        f"wrong, so this diagnosis takes the readings' spacing {g:.4g} as the step (pass "
        "the encoder's step with --resolution)"
    )


#: A spacing ``g`` can be the step only if every reading level of a run lies on the grid
#: of ``g`` through the run's first level: within this fraction of ``g`` (an encoder's
#: levels sit on its grid to the print precision, far below a quarter step).
GRID_TOL = 0.25


def on_grid(theta, lengths, g: float | None) -> bool:
    """Whether every run's reading levels lie on a grid of spacing ``g`` (``GRID_TOL``).
    A fine encoder read at a low rate may never show two adjacent counts (a run that
    stops between samples, no flicker): its smallest gap is then many steps, but its
    levels are no multiples of that gap. On the backlash–soft_windup experiment (paper
    design, 64 000 counts/rev at 250 Hz) the gap was 15–37 given steps on 3 of 5 logs
    checked; taken as the step, it turned the misfit into "adequate"."""
    import numpy as np

    if g is None or not g > 0:
        return False
    theta = np.atleast_2d(np.asarray(theta, dtype=float))
    for row, n in zip(theta, np.asarray(lengths, dtype=int)):
        lv = np.unique(row[:n][np.isfinite(row[:n])])
        if lv.size < 2:
            continue
        x = (lv - lv[0]) / g
        if np.max(np.abs(x - np.round(x))) > GRID_TOL:
            return False
    return True

