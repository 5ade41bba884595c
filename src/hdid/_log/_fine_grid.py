"""An encoder step of one to a few print units: the print lattice's empty points.

:func:`~hdid._log._resolution.find_step` tells a grid by the differences of a run's levels:
each lies within two half print units of a multiple of the step ``q``. Below two print
units a step that says nothing (every difference lies within one unit of some multiple),
so a 2^15-count encoder printed to 0.1 mrad (``q`` = 1.92 print units) went without a step
and its fit took the print unit's floor, half the readings' (2.2× "the floor", silently).

A common offset still tells such a grid. In print units (``Q = q/p``, offset ``O``) a run's
printed levels are the integers ``n = round(O + m·Q)``: within half a unit of the grid, so
every level's phase ``n/Q mod 1`` lies in one arc of width ``1/Q`` (centred on ``O/Q``).
With ``q`` between ``p`` and ``2p`` neighbouring encoder levels print one or two units
apart, and a fixed share ``1 − 1/Q`` of the lattice between them stays empty in a fixed
pattern (a Beatty sequence); the levels of an analog log fill it at random. The arc is a
peak of the levels' Rayleigh power ``|Σ exp(2πi·n·f)|²`` at ``f = 1/Q`` (the integers
cannot tell ``f`` from ``1 − f``: both are tried, and a multiple of the grid found): an
FFT of each run's occupancy finds it, the multiples follow from the peak's phase, and
:func:`~hdid._log._step_scan.offset_chance` fits ``q`` and one offset per run and gives
the chance that levels on no grid fit it (``1/Q`` a level, or the print lattice's share:
:mod:`._lattice`), counted against the frequencies searched. Below one print unit every
lattice point can be printed: nothing to find.
"""

from __future__ import annotations

import math

import numpy as np

from ._step_scan import offset_chance

#: Grids searched, in print units a step (below ~1.1 a level passes a wrong grid with a
#: chance of 0.9: hundreds of levels would not tell it).
Q_MIN, Q_MAX = 1.1, 4.0
#: Zero padding of the FFT (frequency bins a peak's width), and the largest FFT: a run
#: spanning more print units is searched in its window of that span holding most levels.
PAD = 4
MAX_FFT = 1 << 19
#: Peaks of the Rayleigh power examined (each with its alias ``1 − f``).
PEAKS = 6
#: Decades of likelihood by which a coarser grid must beat a finer one that also fits.
CHOICE_MARGIN = 2.0
#: A window of this many print units holds at most ``W/Q + 1`` levels of a grid ``Q``:
#: a run with more is on no grid of ``Q_MIN`` or more (an analog log's dense stretch).
_WINDOW = 32


def fine_step(x: np.ndarray, unit: float, bounds, merge: float,
              false_chance: float):
    """``(step, multiples per level, rival)`` of a grid of :data:`Q_MIN`-:data:`Q_MAX` print units
    told by the readings ``x`` (all printed to ``unit``, runs ``bounds``: ``(start, stop)``
    pairs, one offset each), or ``None``: levels not all on the print lattice, on no such
    grid, or not told from chance at ``false_chance`` (the search's bar).
    The multiples are returned per run (a tuple of arrays); ``rival`` is another step
    that fits about as well (within :data:`CHOICE_MARGIN` decades), or ``None``."""
    runs = []
    for a, b in bounds:
        v = x[a:b][np.isfinite(x[a:b])]
        if v.size < 2:
            continue
        k = np.rint(v / unit)
        if np.any(np.abs(v - k * unit) > 1e-6 * unit + merge):
            return None  # not the print lattice (another unit, or numbers never printed)
        n = np.unique(k.astype(np.int64))
        if n.size < 2:
            continue
        n = _window(n - n[0])
        if _too_dense(n):
            return None
        runs.append(n)
    if not runs or sum(n.size for n in runs) < 8:
        return None
    span = max(int(n[-1]) for n in runs)
    size = 1 << max(6, int(math.ceil(math.log2(PAD * (span + 1)))))
    power = np.zeros(size // 2 + 1)
    for n in runs:
        occ = np.zeros(size)
        occ[n] = 1.0
        power += np.abs(np.fft.rfft(occ)) ** 2 / n.size
    lo = int(math.floor(size * (1.0 - 1.0 / Q_MIN)))
    f = np.arange(power.size) / size
    inner = np.arange(max(lo, 1), power.size - 1)
    peak = inner[(power[inner] >= power[inner - 1]) & (power[inner] >= power[inner + 1])]
    peak = peak[np.argsort(power[peak])[::-1][:PEAKS]]
    # the frequencies searched, both aliases: the trials a chance is counted against
    trials = 2.0 * max(power.size - lo, 1) / PAD
    told, fits = [], []
    for j in peak:
        fj = _refine(runs, float(f[j]), 1.0 / size)
        for fr in (fj, 1.0 - fj):
            if not (1.0 / Q_MAX <= fr <= 1.0 / Q_MIN):
                continue
            found = _fit(runs, fr, 1.0 / size, unit)
            if found is not None:
                fits.append(found)
                if found[1] + math.log10(trials) < math.log10(false_chance):
                    told.append(found)
    if not told:
        return None
    # a grid's alias 1/(1 − 1/Q) fits its levels by chance where they miss the thin slice
    # of the arc it lacks (Q near 2: 0.976 a level at 1.98): a coarser grid is taken over
    # a finer one only where it is the likelier by CHOICE_MARGIN decades
    told.sort(key=lambda c: c[0])
    best = told[0]
    for c in told[1:]:
        if c[1] < best[1] - CHOICE_MARGIN:
            best = c
    # another grid that fits within the margin, told from chance or not (the bar is the
    # grid's against an analog log, once one grid passed it): the log does not choose
    # between them (a note). Another grid is one that moves some level to another
    # multiple (a step off by more than half a print unit over the levels' span): a
    # 2.0009-unit grid and its 1.9991 alias are 0.09 % apart but place levels 1.8 units
    # apart over 1000 steps
    span = max(float(np.ptp(m)) for m in best[2])
    rivals = [c[0] for c in fits
              if abs(c[0] - best[0]) * max(span, 1.0) > 0.5 * unit
              and c[1] < best[1] + CHOICE_MARGIN]
    return best[0], best[2], (min(rivals, key=lambda r: abs(r - best[0])) if rivals else None)


#: Frequencies tried across a peak's bin (to 1/32 of a bin).
_ZOOM = 65


def _refine(runs, f0: float, df: float) -> float:
    """The frequency within ``f0 ± df`` (one FFT bin) whose phases ``n·f mod 1`` of every
    run's levels lie in the narrowest arc (against ``f``, the arc's width on the grid
    ``1/f``). A level ``n`` print units from its run's first is placed by its phase: at
    the bin's own frequency the phase drifts by up to ``span·df`` (a quarter cycle at
    the padding's 4) across a run, and a grid of 2.1 units a step over 2200 units had
    its far levels put on wrong multiples (its fit failed, and its alias 1.91 units,
    which fits the levels of any grid of 2-3 units, was taken without a note). The
    Rayleigh power does not place ``f`` that finely: its peak is ``1/span`` wide and,
    with a hundred levels, off the grid's frequency by a good part of that."""
    best, at = np.inf, f0
    for f in f0 + df * np.linspace(-1.0, 1.0, _ZOOM):
        excess = max(_arc_width(np.mod(n * f, 1.0)) for n in runs) - f
        if excess < best:
            best, at = excess, float(f)
    return at


def _arc_width(phase: np.ndarray) -> float:
    """Width of the shortest arc of the circle (circumference 1) holding every ``phase``."""
    ph = np.sort(phase)
    return float(1.0 - np.max(np.diff(np.append(ph, ph[0] + 1.0))))


def _window(n: np.ndarray) -> np.ndarray:
    """The levels (sorted integers from 0) within the window of ``MAX_FFT/PAD`` print
    units holding most of them, shifted to start at 0."""
    width = MAX_FFT // PAD - 1
    if int(n[-1]) <= width:
        return n
    ends = np.searchsorted(n, n + width, side="right")
    i = int(np.argmax(ends - np.arange(n.size)))
    kept = n[i:ends[i]]
    return kept - kept[0]


def _too_dense(n: np.ndarray) -> bool:
    """Whether some window of :data:`_WINDOW` print units holds more levels than a grid of
    :data:`Q_MIN` units can print there (``W/Q + 1``)."""
    ends = np.searchsorted(n, n + _WINDOW - 1, side="right")
    return bool(np.max(ends - np.arange(n.size)) > _WINDOW / Q_MIN + 1.0)


def _arc_centre(phase: np.ndarray) -> float:
    """The middle of the shortest arc of the circle (circumference 1) holding every
    ``phase``: the complement of the widest gap between neighbouring phases."""
    ph = np.sort(phase)
    gaps = np.diff(np.append(ph, ph[0] + 1.0))
    i = int(np.argmax(gaps))
    start = ph[(i + 1) % ph.size]
    return float(start + (1.0 - gaps[i]) / 2.0)


def _fit(runs, fr: float, df: float, unit: float):
    """``(q, log10 chance, multiples)`` of the grid at frequency ``fr`` [1/print unit]
    (bin width ``df``): each level's multiple from its phase about the middle of the
    shortest arc holding its run's phases,
    then :func:`offset_chance` for ``q`` within the bin; ``None`` where no ``q`` there puts
    every level within half a print unit of its multiple."""
    levels, tols, mults, units = [], [], [], []
    for n in runs:
        m = np.rint(n * fr - _arc_centre(np.mod(n * fr, 1.0)))
        if np.any(np.diff(m) <= 0):
            return None  # two printed levels on one grid point (a tie at half a unit)
        levels.append(n * unit)
        tols.append(np.full(n.size, unit / 2.0 * (1.0 + 1e-9)))  # (closed: a tie)
        mults.append(m - m[n.size // 2])
        units.append(np.full(n.size, unit))
    qlo, qhi = unit / (fr + df), unit / max(fr - df, 1e-12)
    # levels on every g-th grid point are on the grid g·q (the largest grid that fits)
    g = 0
    for m in mults:
        g = math.gcd(g, *[int(v) for v in np.abs(m - m[0])])
    g = max(g, 1)
    mults = [m / g for m in mults]
    fit = offset_chance(levels, tols, mults, g * qlo, g * qhi, units)
    if fit is None:
        return None
    return fit[0], fit[1], tuple(mults)
