"""The encoder step, found in the reading levels of a log as they are printed.

A logger prints every reading with a finite precision: a fixed number of decimals
(``%.4f``: the *print unit* is 1e-4), a fixed number of significant digits (``%g``,
``1.5708e-03``) or whole counts. A printed reading is the encoder level rounded to that
unit, so it lies within half a print unit of ``offset + k·q`` (``q`` the encoder step,
``offset`` the set-up's reading at the spring zero, which need not be a multiple of
``q``). Within one run the offset is common, so the difference of two of its printed
levels lies within one print unit (half of each) of a multiple of ``q``.

:func:`find_step` looks for the largest grid ``q`` for which that holds for every level
of every run, and decides whether the log *tells* it: a grid ``q`` that is not the
encoder's passes one level's test by chance with probability ``≈ 2t/q`` (``t`` the level's
tolerance), so the log tells the grid when the chance that every level passes for a wrong
grid, ``Π 2t/q`` over the levels the grid places, times the number of grids tried, is
below :data:`FALSE_GRID_CHANCE`. The print unit itself explains every printed level
exactly; it is never the step (it fails that test: ``2t/q ≥ 1``). Nor is a grid less than
:data:`MIN_STEP_PER_PRINT_UNIT` print units: a grid no wider than a level difference's
window (two half units) holds every printed level (and the search starts 5 % above it,
where a wrong grid still fails a level with a chance of ~1/20). A printed level is a
multiple of its print unit, so the chance a wrong grid passes it is the share of that
lattice the window holds, not ``2t/q`` (:mod:`._lattice`: at ``q = 3p`` every level
difference passes). Between 1.1 and ~7 print units a step the readings' rounding to the
print unit adds about ``p²/12`` to the quantization variance ``q²/12`` (1/4 of it at 2
units, 12 % on the floor ``q/√12``; 1/15, 3 %, at 3.83): the fit measures it on the
lattice of ``Log.resolution`` printed to ``Log.print_unit``
(:mod:`hdid._simulation._print_rounding`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ._fine_grid import fine_step
from ._grid_outliers import coarser_grid
from ._print_precision import PrintPrecision as PrintPrecision, print_precision  # (re-exported)
from ._lattice import mixed_offsets, shares
from ._step_scan import Budget, offset_chance, resolved, steps_in


# ------------------------------------------------------------------ the step


#: Largest divisor of the smallest gap between reading levels tried as the step.
MAX_STEP_DIVISOR = 64
#: ... and for a log of few levels (at most :data:`SPARSE_LEVELS` differences): a fine
#: encoder sampled slowly (2^17 counts/rev at 250 Hz, a swing of six samples) never
#: shows two levels a few counts apart, its closest hundreds of counts apart; finely
#: printed, its levels still tell the grid (the chance test counts the grids tried).
MAX_SPARSE_DIVISOR = 4096
SPARSE_LEVELS = 2000
#: The log tells a grid when a wrong grid passes every level by chance less often than this.
FALSE_GRID_CHANCE = 1e-6
#: Tests (a level difference against a candidate interval of the step) the bisection
#: (._step_scan) may spend on one log before it is said not to tell its grid: ~0.1 s.
SCAN_BUDGET = 1e7
#: Smallest encoder step, in print units, reported as found (see the module notes).
MIN_STEP_PER_PRINT_UNIT = 2.0
#: The step search starts this factor above the widest window of a level difference.
_WINDOW_MARGIN = 1.05
#: Readings closer than this fraction of the largest |reading| are one level (floating
#: point: values computed as ``offset + k*q`` in float64).
MERGE_REL = 1e-9


@dataclass(frozen=True)
class StepFinding:
    """What :func:`find_step` found: the step (``None`` when the log does not tell it), the
    print unit it was found under (``None`` for unprinted numbers) and, without a step,
    why (one clause for a report)."""

    step: float | None
    print_unit: float | None
    note: str | None = None
    #: Readings (positions in the array searched) off the step's grid, which nearly all
    #: others lie on (:mod:`._grid_outliers`), how far off [steps], and the bound on the
    #: chance that a log on a finer grid looks like that.
    off_grid: tuple[int, ...] = ()
    off_by: tuple[float, ...] = ()
    off_grid_log10_chance: float | None = None


def _levels(x: np.ndarray, p: np.ndarray, merge: float):
    """Distinct levels of one run, the tolerance of each (half its print unit, plus the
    floating-point merge width) and its print unit."""
    order = np.argsort(x, kind="stable")
    xs, ps = x[order], p[order]
    new = np.concatenate(([True], np.diff(xs) > merge))
    idx = np.flatnonzero(new)
    levels = xs[idx]
    unit = np.maximum.reduceat(ps, idx)
    return levels, unit / 2.0 + merge, unit


def _place(d: np.ndarray, t: np.ndarray, qlo: float, qhi: float):
    """Narrow ``[qlo, qhi]`` so that every difference ``d`` (> 0, tolerance ``t``) is within
    ``t`` of a multiple of ``q``: a difference with one possible multiple fixes it and cuts
    the interval; repeat until nothing changes. Returns ``(qlo, qhi, m)`` (``m = -1`` where
    the multiple stays ambiguous — consistent with the interval but not placed) or
    ``None`` when some difference fits no multiple."""
    m = np.full(d.size, -1, dtype=np.int64)
    for _ in range(200):
        lo = np.ceil((d - t) / qhi - 1e-12)
        hi = np.floor((d + t) / qlo + 1e-12)
        lo = np.maximum(lo, 0.0)
        if np.any(hi < lo):
            return None
        one = (hi == lo) & (lo >= 1)
        m[one] = lo[one].astype(np.int64)
        placed = m >= 1
        if not placed.any():
            return qlo, qhi, m
        new_lo = max(qlo, float(np.max((d[placed] - t[placed]) / m[placed])))
        new_hi = min(qhi, float(np.min((d[placed] + t[placed]) / m[placed])))
        if new_lo > new_hi:
            return None
        if new_lo == qlo and new_hi == qhi:
            return qlo, qhi, m
        qlo, qhi = new_lo, new_hi
    return qlo, qhi, m


def find_step(theta, print_unit=None, starts=None, *, unit_name: str = "rad") -> StepFinding:
    """The encoder step of a log's readings, from their levels and printing precision.

    Parameters
    ----------
    theta : numpy.ndarray
        Readings (any offset per run; non-finite values are ignored).
    print_unit : float or numpy.ndarray, optional
        Print unit of every reading (or one for all) in the readings' units; ``None`` for
        numbers that were never printed (a DataFrame): then only floating-point rounding
        (:data:`MERGE_REL` of the largest reading) separates a level from the grid.
    starts : sequence of int, optional
        First sample of every run (each run may have its own offset); one run by default.
    unit_name : str
        Unit of the readings, for the notes.

    Returns
    -------
    StepFinding
        The largest step ``q`` such that, within every run, every printed level lies
        within its print unit (half of it on each of two readings) of a multiple of ``q``
        from the run's middle level — or no step and the reason.
    """
    x = np.asarray(theta, dtype=np.float64).ravel()
    p = (np.zeros_like(x) if print_unit is None
         else np.broadcast_to(np.asarray(print_unit, dtype=np.float64), x.shape).copy())
    starts = np.array([0] if starts is None or len(starts) == 0 else starts, dtype=np.int64)
    bounds = list(zip(starts, np.append(starts[1:], x.size)))
    ok = np.isfinite(x)
    if ok.sum() < 2:
        return StepFinding(None, None, "too few readings to find a grid")
    merge = MERGE_REL * max(float(np.max(np.abs(x[ok]))), np.finfo(float).tiny)
    found = _by_differences(x, p, bounds, ok, merge, print_unit is not None, unit_name)
    if found.step is not None or not found.print_unit or np.ptp(p[ok]) > 0.0:
        return found
    # one print unit throughout: a grid of one to a few units by its empty lattice points
    fine = fine_step(x, found.print_unit, bounds, merge, FALSE_GRID_CHANCE)
    if fine is None:
        return found
    q, _, rival = fine
    if mixed_offsets(q, [(a, b, np.unique(x[a:b][ok[a:b]])) for a, b in bounds],
                     FALSE_GRID_CHANCE):
        return found
    note = None if rival is None else (
        f"the readings fit an encoder step of {q:.4g} {unit_name} and one of {rival:.4g} "
        f"{unit_name} ({q / found.print_unit:.4g} and {rival / found.print_unit:.4g} print "
        f"units) about equally: {q:.4g} is taken; the quantization floor may be off by "
        f"{abs(rival / q - 1.0):.1%}")
    return StepFinding(q, found.print_unit, note)


def _by_differences(x, p, bounds, ok, merge: float, printed: bool,
                    unit_name: str) -> StepFinding:
    """:func:`find_step` by the differences of each run's levels (module notes)."""
    unit = float(np.max(p[ok])) if printed else None
    d_all, t_all, u_all, gaps, run_levels, signed = [], [], [], [], [], []
    n_levels = 0
    for a, b in bounds:
        keep = ok[a:b]
        if keep.sum() == 0:
            continue
        lv, tl, pu = _levels(x[a:b][keep], p[a:b][keep], merge)
        n_levels += lv.size
        run_levels.append((int(a), int(b), lv))
        if lv.size < 2:
            continue
        g = np.diff(lv)
        gaps.append((g, tl[1:] + tl[:-1]))
        ref = lv.size // 2  # the middle level keeps the multiples small
        others = np.arange(lv.size) != ref
        d_all.append(np.abs(lv[others] - lv[ref]))
        t_all.append(tl[others] + tl[ref])
        u_all.append(np.minimum(pu[others], pu[ref]))  # a difference's print lattice
        signed.append((lv, tl, others, np.sign(lv[others] - lv[ref]), pu))
    if not gaps or (n_levels <= 2 and ok.sum() < 3):
        return StepFinding(None, unit, "fewer than two reading levels: no grid to find")
    d, t, du = np.concatenate(d_all), np.concatenate(t_all), np.concatenate(u_all)
    g = np.concatenate([gg for gg, _ in gaps])
    gt = np.concatenate([tt for _, tt in gaps])
    t_max = float(np.max(t))
    i0 = int(np.argmin(g))
    g0, t0 = float(g[i0]), float(gt[i0])
    coarse, untold, budget = False, None, Budget(SCAN_BUDGET)
    k_max = MAX_SPARSE_DIVISOR if d.size <= SPARSE_LEVELS else MAX_STEP_DIVISOR
    for k in range(1, k_max + 1):
        # (a grid no wider than a difference's window, 2t, admits every difference: not
        # searched, or the bisection below never narrows there)
        qlo, qhi = max((g0 - t0) / k, _WINDOW_MARGIN * 2.0 * t_max), (g0 + t0) / k
        if qhi < MIN_STEP_PER_PRINT_UNIT * float(np.median(t)) or qlo >= qhi:
            coarse = True  # finer grids only get closer to the print unit
            break
        # the gaps between neighbouring levels narrow the interval first: a swing's
        # levels lie far (tens of steps) from the middle one, beyond what the closest
        # gap's interval places, while neighbours often lie a few steps apart. Only
        # the differences from the middle level count in the chance below.
        narrowed = _place(g, gt, qlo, qhi)
        if narrowed is None:
            continue
        placed = _place(d, t, narrowed[0], narrowed[1])
        if placed is None:
            continue
        qlo, qhi, m = placed
        used = m >= 1
        q = float(np.sum(m[used] * d[used]) / np.sum(m[used] ** 2.0)) if used.any() else g0 / k
        q = min(max(q, qlo), qhi)
        if unit is not None and unit > 0 and q < MIN_STEP_PER_PRINT_UNIT * unit:
            coarse = True
            break
        # chance that a wrong grid places every level: Π 2t/q over the placed levels,
        # times the grids tried (divisors k, and the interval's width in steps of the
        # largest multiple's precision); printed levels are a lattice (._lattice)
        trials = max(k, MAX_STEP_DIVISOR) * max(float(m.max()), 1.0)
        told = _chance(d[used], t[used], du[used], q) + math.log10(trials) < math.log10(
            FALSE_GRID_CHANCE)
        if not told:
            # every multiple resolved by bisection, one offset per run (._step_scan)
            by_offsets = _by_offsets(signed, d, t, (g, gt), qlo, qhi, k, budget)
            untold = untold or _untold(n_levels, q, unit, unit_name)
            if by_offsets == "none":
                continue  # no grid in this interval after all: try a finer one
            if (isinstance(by_offsets, float)
                    and by_offsets >= MIN_STEP_PER_PRINT_UNIT * (unit or 0.0)):
                q, told = by_offsets, True
        if told:
            # a few readings off a coarser grid that all others lie on (._grid_outliers)
            coarse_grid = coarser_grid(q, x, run_levels, merge, MAX_STEP_DIVISOR,
                                       FALSE_GRID_CHANCE)
            if coarse_grid is None:
                if mixed_offsets(q, run_levels, FALSE_GRID_CHANCE):
                    return _untold(n_levels, q, unit, unit_name)
                return StepFinding(q, unit, None)
            return StepFinding(q * coarse_grid.factor, unit, None,
                               tuple(int(i) for i in coarse_grid.off),
                               tuple(float(v) for v in coarse_grid.off_by),
                               coarse_grid.log10_chance)
        return untold or _untold(n_levels, q, unit, unit_name)
    if untold is not None:  # the first interval that fit, though not every level
        return untold
    if coarse and unit:
        return StepFinding(
            None, unit,
            f"the closest reading levels are {g0:.3g} {unit_name} apart, {g0 / unit:.3g} "
            f"print units of {unit:.3g} {unit_name} (fewer than {MIN_STEP_PER_PRINT_UNIT:g}): "
            "no encoder grid can be told from the printing",
        )
    return StepFinding(None, unit, "the readings lie on no grid")


def _chance(d: np.ndarray, t: np.ndarray, units: np.ndarray, q: float) -> float:
    """log10 of the chance that levels on no grid lie at differences ``d`` within ``t`` of
    multiples of ``q``: ``Π 2t/q``, or the share of the print lattice such a window holds
    where that is larger (:mod:`._lattice`)."""
    if d.size == 0:
        return 0.0
    per = np.minimum(2.0 * t / q, 1.0)
    if np.sum(np.log10(per)) >= math.log10(FALSE_GRID_CHANCE) or not np.any(units > 0):
        return float(np.sum(np.log10(per)))  # not told anyway, or never printed
    return float(np.sum(np.log10(shares(q, units, 2.0 * t, float(d.max())))))


def _untold(n_levels: int, q: float, unit, unit_name: str) -> StepFinding:
    """No step: the levels fit a grid ``q`` but do not tell it from chance."""
    return StepFinding(
        None, unit,
        f"the readings' {n_levels} levels fit a grid of {q:.4g} {unit_name} but do not "
        "tell it from chance" + (f" at a print unit of {unit:.3g} {unit_name}" if unit else ""),
    )


def _by_offsets(signed, d: np.ndarray, t: np.ndarray, gaps, qlo: float, qhi: float, k: int,
                budget: Budget):
    """The step in ``[qlo, qhi]`` told with every level's multiple resolved
    (:func:`._step_scan.steps_in`) and one offset per run (:func:`._step_scan.offset_chance`),
    ``"none"`` where no grid in the interval fits every level, or ``None`` where one fits
    but is not told from chance (or too many fit)."""
    threshold = math.log10(FALSE_GRID_CHANCE)
    # the best a grid here can do: every level placed at the coarsest step, the fewest trials
    best = sum(math.log10(lv.size) + float(np.sum(np.log10(np.minimum(2.0 * tl / qhi, 1.0)))
                                           - np.log10(np.minimum(2.0 * tl / qhi, 1.0)).max())
               for lv, tl, _, _, _ in signed)
    trials = max(k, MAX_STEP_DIVISOR) * max(float(d.max()) / qhi, 1.0)
    if best + math.log10(trials) >= threshold:
        return None
    # the neighbouring levels' gaps first: their multiples are small, so they rule out a
    # log on no grid at a coarse bisection (the differences from the middle level, many
    # steps, only once it is fine: an analog log printed to a few units a gap spent the
    # whole budget there); every grid that fits must fit them too
    if steps_in(gaps[0], gaps[1], qlo, qhi, budget) == []:
        return "none"
    intervals = steps_in(d, t, qlo, qhi, budget)
    if intervals is None:
        return None
    if not intervals:
        return "none"
    narrowed = resolved(intervals, d, t, [s[:4] for s in signed], budget)
    if narrowed is None:
        return None
    found = None
    for qlo_m, qhi_m, m in narrowed:
        at = 0
        levels, tols, multiples, units = [], [], [], []
        for lv, tl, others, sign, pu in signed:
            mult = np.zeros(lv.size)
            mult[others] = sign * m[at:at + sign.size]
            at += sign.size
            levels.append(lv)
            tols.append(tl)
            multiples.append(mult)
            units.append(pu)
        fit = offset_chance(levels, tols, multiples, qlo_m, qhi_m, units)
        if fit is None:
            continue
        q, log_chance = fit
        log_chance += math.log10(max(k, MAX_STEP_DIVISOR) * float(m.max()))
        if found is None or log_chance < found[1]:
            found = (q, log_chance)
    if found is None:
        return "none"
    return found[0] if found[1] < threshold else None


def estimate_resolution(theta: np.ndarray, *, print_unit=None, starts=None) -> float | None:
    """Estimate the quantization step of a quantized signal (:func:`find_step`'s step).

    The distinct levels of `theta` are sorted; the step ``q`` is the largest divisor
    ``g/k`` (``k`` = 1 … ``MAX_STEP_DIVISOR``) of the smallest gap ``g`` between adjacent
    levels of which every level is a multiple, within the printing precision (or
    floating-point rounding for numbers never printed). Only differences of values within
    a run are used, so an offset (``offset + k*q``) does not matter.

    Returns
    -------
    float or None
        The step, or ``None`` when the signal does not tell a grid (gaps not
        commensurate, fewer than two distinct levels, or printed too coarsely).

    Examples
    --------
    >>> q = 2 * np.pi / 4000
    >>> round(estimate_resolution(0.3 + q * np.array([0, 1, 1, 3, 2, 7])) / q, 9)
    1.0
    """
    return find_step(theta, print_unit, starts).step


def column_print_units(cells, scale: float = 1.0, counts_per_rev: float | None = None):
    """Print unit of every cell of a column, in hdid's units (``scale``: the header
    unit's factor; raw counts with ``counts_per_rev`` are converted like the readings),
    or ``None`` for numbers that were never text."""
    found = print_precision(cells)
    if found is None:
        return None
    factor = scale * (2.0 * math.pi / counts_per_rev if counts_per_rev else 1.0)
    return found.per_cell * factor


def step_against_readings(theta, lengths, step: float, rms: float,
                          floor_factor: float) -> str | None:
    """A warning when a fit's residual is far above the floor of ``step`` but within the
    floor of the spacing the readings actually show — the step, not the model, is wrong.

    ``theta``: readings per run ``(R, T)`` (padded), ``lengths`` their counts; ``rms`` the
    fit's RMS residual. The readings' level spacing ``g`` is the smallest gap between two
    distinct levels of one run. Where ``g`` is at least 4 steps (the log never shows two
    readings closer than that; an encoder's creep to rest and flicker show adjacent
    counts), and the residual is within ``floor_factor`` of ``g/√12`` (a fit that tracks
    every run to the readings' own grid), the residual says the step is wrong. ``None``
    otherwise (the residual is the model's, or the step is plausible).
    """
    floor = step / math.sqrt(12.0)
    if not (math.isfinite(rms) and step > 0 and rms > floor_factor * floor):
        return None
    g = readings_spacing(theta, lengths)
    if g is None or g < 4.0 * step or rms > floor_factor * g / math.sqrt(12.0):
        return None
    return (
        f"the RMS residual is {rms / floor:.3g}× the quantization floor of the encoder step "
        f"{step:.3g} rad, but the readings are never closer than {g:.4g} rad "
        f"({g / step:.3g} steps) and the fit tracks them to {rms / (g / math.sqrt(12.0)):.2f}× "
        f"that spacing's floor: the step looks wrong, not the model — pass the encoder's "
        f"step (--resolution {g:.4g} if that spacing is it) and refit; until then the "
        "standard errors, which assume the step's noise, are too small"
    )


def readings_spacing(theta, lengths) -> float | None:
    """The smallest gap between two distinct reading levels of one run [readings' units]:
    ``theta`` per run ``(R, T)`` (padded), ``lengths`` the runs' sample counts; ``None``
    when no run has two levels."""
    theta = np.atleast_2d(np.asarray(theta, dtype=float))
    gaps = []
    for row, n in zip(theta, np.asarray(lengths, dtype=int)):
        lv = np.unique(row[:n][np.isfinite(row[:n])])
        g = np.diff(lv)
        g = g[g > MERGE_REL * max(float(np.max(np.abs(lv))) if lv.size else 0.0, 1e-300)]
        if g.size:
            gaps.append(float(g.min()))
    return min(gaps) if gaps else None
