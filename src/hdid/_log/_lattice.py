"""The chance that a printed reading falls on a wrong grid: printed numbers are a lattice.

:func:`~hdid._log._resolution.find_step` tells an encoder grid ``q`` from chance by the
probability that a level of a log on *no* grid lies within its tolerance ``t`` of the grid
anyway. For a level at a random real value that probability is ``2t/q`` (a window of
width ``2t`` on the circle of circumference ``q``). A printed level is not a random real
value: it is a multiple ``k·p`` of its print unit ``p``. Its residue ``k·p mod q`` takes
only the values of that lattice, and where ``q/p`` is near a ratio ``a/b`` of small
integers the residues bunch onto ``a`` points ``p/b`` apart. A closed window of width
``2t = p`` (a level's own half unit either side) then holds ``b + 1`` of the ``a`` points,
not ``a·p/q = b``: at ``q = 3p`` a window of width ``2p`` about a multiple of ``q`` (the
difference of two printed levels, half a unit each) holds every residue, and at
``q = 2p`` a window of width ``p`` does — an analog log printed to ``p`` lies on a grid
of two or three print units whatever it reads. The bias is a factor ``1 + 1/b`` per level:
small for a grid of many print units, decisive for one of two to four.

:func:`lattice_share` measures it: the largest share of the printed values over the span
a run's levels cover whose residues fall in one closed window of the given width. That
share, never below ``2t/q``, is the per-level chance the search uses.
"""

from __future__ import annotations

import math

import numpy as np

#: Printed values examined: every multiple of the print unit over the span, or this many
#: drawn at random from it (a fixed seed; the share's sampling error, ~0.5 % of a share
#: of 0.3, is then an upward bias of a few per cent at most: the search's side).
MAX_POINTS = 16384


def lattice_share(q: float, unit: float, width: float, span: float) -> float:
    """Largest share of the printed values ``k·unit`` (``k = 0 … K``, ``K`` the span in
    print units; :data:`MAX_POINTS` of them drawn at random where there are more) whose
    residues modulo ``q`` lie in one closed window of ``width`` (same units as ``q``);
    0 for numbers never printed (``unit`` 0: no lattice)."""
    if not (unit > 0.0 and q > 0.0 and math.isfinite(unit) and math.isfinite(q)):
        return 0.0
    if width >= q:
        return 1.0
    top = max(span, 0.0) / unit
    if top < 1.0:
        return 1.0
    if top < MAX_POINTS:
        k = np.arange(int(top) + 1, dtype=np.float64)
    else:  # (integers below 2^53: k·unit is the printed value's float)
        k = np.random.default_rng(0).integers(0, int(min(top, 2.0**53)) + 1, MAX_POINTS)
        k = k.astype(np.float64)
    n = k.size
    r = np.sort(np.mod(k * unit, q))
    ext = np.concatenate((r, r + q))
    # values on a window's edge count (the tolerance is closed); float slack of 1e-9
    ends = np.searchsorted(ext, r + width * (1.0 + 1e-9) + 1e-12 * q, side="right")
    return float(np.max(ends - np.arange(n))) / n


def shares(q: float, units: np.ndarray, widths: np.ndarray, span: float) -> np.ndarray:
    """:func:`lattice_share` of every (``units``, ``widths``) pair at one ``q`` and span,
    at least ``widths/q`` (the share of random real values), at most 1."""
    units = np.asarray(units, dtype=float)
    widths = np.asarray(widths, dtype=float)
    out = np.minimum(widths / q, 1.0)
    pairs, inverse = np.unique(np.stack((units, widths)), axis=1, return_inverse=True)
    each = np.array([lattice_share(q, u, w, span) for u, w in pairs.T])
    return np.maximum(out, each[np.ravel(inverse)])


def mixed_offsets(q: float, run_levels, chance: float, most: int = 16) -> bool:
    """Whether some run's levels fill at most half the residues modulo ``n`` steps
    (``n`` = 2 … ``most``) where a swing over the grid ``q`` fills all: ``r`` of ``n``
    residues hold ``L`` levels at random with chance ``C(n, r)·(r/n)^L``, taken as
    impossible below ``chance`` (the search's false-grid chance). Such levels lie on a coarser grid
    ``n·q`` with several offsets (two releases under one run label): ``q`` only fits
    their offsets' difference, one coincidence, not every level. (A few readings half
    a step off a coarse grid fill more than half: the finer grid that explains them,
    :mod:`._grid_outliers`, is kept.)"""
    for _, _, lv in run_levels:
        if lv.size < 8:
            continue
        m = np.rint((lv - lv[lv.size // 2]) / q).astype(np.int64)
        for n in range(2, most + 1):
            r = int(np.unique(np.mod(m, n)).size)
            if 2 * r <= n and (math.log10(math.comb(n, r)) + lv.size * math.log10(r / n)
                          < math.log10(chance)):
                return True
    return False
