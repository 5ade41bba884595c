"""The readings' print rounding as angle noise: an encoder step of a few print units.

A logger that prints each encoder level ``O + m·q`` (``q`` the step, ``O`` the run's offset)
to a print unit ``p`` writes ``n·p = p·round((O + m·q)/p)``. A reading's error against the
true angle ``θ`` is then the encoder's rounding, ``O + m·q − θ`` (uniform on ``±q/2`` while
the gear passes through the cell, mean 0 whatever ``m``), plus the level's print error
``e(m) = n·p − (O + m·q)``, which is fixed once ``m`` and ``O`` are: the two are
uncorrelated (``E[enc·e] = Σ_m P(m)·e(m)·E[enc | m] = 0``) and their variances add.

How large ``e(m)`` is over the levels is read from the lattice, not assumed to be
``p²/12``: a step of a whole number of print units prints every level with the same error
(a constant the set-up's offset takes up: nothing is added), one of ``N/D`` units cycles
through ``D`` errors ``p/D`` apart, and an incommensurate one fills ``±p/2`` evenly
(``p²/12``). Each run's levels lie within ``p/2`` of its lattice, so their phases
``x/q mod 1`` lie in one arc of width ``1/Q`` (``Q = q/p``) about ``O/q``: the arc's middle
gives ``O``, each reading's multiple and its print error. The variance is those errors'
mean square about each set-up's mean (the offset), weighted as the fit weights the
readings (a hold or stuck tail is one observation).

On an encoder printed far finer than its step the term is at most ``3/Q²`` of the step's
``q²/12`` (every error at ``p/2``) and is left out below :data:`NEGLIGIBLE_PRINT`: the
floor of logs printed with many decimals is unchanged. At ``Q = 1.92`` (2^15 counts printed
to 0.1 mrad) it is ``1/Q²``: the floor ``√(q² + p²)/√12`` is 1.13× the step's alone.
Beside rounded time stamps (:mod:`._timing`: reading ``i``'s error ``s_i·q/√12``) the
term adds ``v`` to every reading's variance, and what it moves is the floor the fit's
weights (``1/s_i²``) reach: ``12·v/q²·Σ(w²/s⁴)/Σ(w²/s²)`` of its square, the fast readings'
share damped by their large ``s``. It is left out where that is below
:data:`NEGLIGIBLE_PRINT` (the floor within 1 %), as without stamps (``s = 1``).
"""

from __future__ import annotations

import numpy as np

#: Largest ``12·v/q²`` left out (``v`` the print errors' variance): the readings' error then
#: lies within 1 % of ``q/√12`` (as :data:`._timing.NEGLIGIBLE_TIMING`).
NEGLIGIBLE_PRINT = 0.0201
#: Slack on the arc of a run's phases beyond ``1/Q`` (floating point, and a step found to
#: within its own interval) before the levels are said not to be this lattice printed.
ARC_SLACK = 1e-3


def _arc_centre(phase: np.ndarray) -> tuple[float, float]:
    """``(middle, width)`` of the shortest arc of the unit circle holding every ``phase``
    (the complement of the widest gap between neighbouring phases)."""
    ph = np.sort(np.mod(phase, 1.0))
    gaps = np.diff(np.append(ph, ph[0] + 1.0))
    i = int(np.argmax(gaps))
    width = 1.0 - float(gaps[i])
    return float(ph[(i + 1) % ph.size] + width / 2.0), width


def print_errors(theta: list[np.ndarray], step: float, unit: float) -> list[np.ndarray] | None:
    """Each reading's print error ``x − (O + m·q)`` [log units] of runs that share one
    offset ``O`` (``theta``: their readings printed to ``unit``; ``step`` the encoder's),
    ``O`` the middle of the arc holding the levels' phases; ``None`` where they hold no
    arc of ``unit/step`` (not one lattice printed to that unit)."""
    xs = [np.asarray(t, dtype=float) for t in theta]
    if not all(np.all(np.isfinite(x)) for x in xs) or not any(x.size for x in xs):
        return None
    ref = float(np.median(np.concatenate(xs)))  # (a level: no offset's digits in the phase)
    rel = [(x - ref) / step for x in xs]
    centre, width = _arc_centre(np.unique(np.concatenate(rel)))
    if width > unit / step + ARC_SLACK:
        return None
    return [(r - centre - np.rint(r - centre)) * step for r in rel]


def print_variance(runs, step: float, unit: float | None, weight: np.ndarray,
                   setup_index: np.ndarray, time_scale: np.ndarray | None = None) -> float:
    """Variance [log units²] the print rounding adds to every reading's error (module
    notes): the readings' print errors' mean square about their set-up's mean, weighted by
    ``weight²`` (``(R, T)``, the fit's weights before any timing scale); 0 where it is
    below :data:`NEGLIGIBLE_PRINT` of ``step²/12`` or the readings are not the lattice
    printed to ``unit``. A set-up's runs share one offset (one encoder, one zero) where
    their levels allow it (a run that never moves then has its print error too), else
    each run has its own (an encoder homed again between runs). ``time_scale`` (``(R, T)``,
    :func:`._timing.time_scales`): the stamps' scale on each reading's error, where the
    term counts if it moves the floor the weights reach by 1 % (module notes)."""
    if not unit or not np.isfinite(unit) or unit <= 0.0 or not step > 0.0:
        return 0.0
    if 3.0 * (unit / step) ** 2 < NEGLIGIBLE_PRINT:  # even every error at p/2 is negligible
        return 0.0
    total, norm = 0.0, 0.0
    for s in np.unique(setup_index):
        mine = np.flatnonzero(setup_index == s)
        theta = [runs[i].theta for i in mine]
        errs = print_errors(theta, step, unit)
        if errs is None:
            errs = [print_errors([t], step, unit) for t in theta]
            if any(e is None for e in errs):
                return 0.0
            errs = [e[0] for e in errs]
        e = np.concatenate(errs)
        w = np.concatenate([np.asarray(weight[i, : len(t)], dtype=float) ** 2
                            for i, t in zip(mine, theta)])
        if float(np.sum(w)) <= 0.0:
            continue
        mean = float(np.sum(w * e) / np.sum(w))
        total += float(np.sum(w * (e - mean) ** 2))
        norm += float(np.sum(w))
    if norm <= 0.0:
        return 0.0
    v = total / norm
    return v if 12.0 * v / step**2 * _damping(weight, time_scale) >= NEGLIGIBLE_PRINT else 0.0


def _damping(weight: np.ndarray, time_scale: np.ndarray | None) -> float:
    """``Σ(w²/s⁴)/Σ(w²/s²)``: the share of a variance added to every reading that reaches the
    floor of readings of error scales ``s`` weighted ``w/s`` (1 without stamps)."""
    if time_scale is None:
        return 1.0
    w2 = np.asarray(weight, dtype=float) ** 2
    s2 = np.asarray(time_scale, dtype=float) ** 2
    den = float(np.sum(w2 / s2))
    return float(np.sum(w2 / s2**2)) / den if den > 0.0 else 1.0
