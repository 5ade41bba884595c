"""A coarser encoder grid that nearly every reading lies on: a few readings off the grid.

:func:`~hdid._log._resolution.find_step` takes the largest grid that explains *every*
reading level. One reading the logger made up — a bus servo's read that failed and was
filled in with the mean of the last two (the Feetech STS3215 logs: −723, −718 counts, then
−720.5, then a −π dropout) — lies half a step off the encoder's grid and forces a grid of
half the step on the whole log: its noise floor, its motion checks and its report would
all be wrong by two. This module asks whether a grid ``j·q`` (``j = 2 …``) holds nearly
every level and the few that miss it are outliers.

The test (false acceptance). If the readings' grid really is ``q`` (the finer one), a
level sits on any one residue of ``j`` by chance: probability ``1/j``, about independently
from level to level (a moving angle crosses the finer grid's levels at no fixed stride,
and a creeping or flickering one visits neighbouring levels, which alternate residues and
make a common residue even less likely than that). Each run has its own offset, so the
residue is chosen per run (``j`` choices). The chance that a finer-grid log shows at
least ``N_r − m_r`` of run ``r``'s ``N_r`` levels on one residue is at most
``j · P(Binomial(N_r, 1/j) ≥ N_r − m_r)``; over independent runs the chances multiply,
and the ``j`` tried multiply the total. The coarser grid is taken when that is below
:data:`~hdid._log._resolution.FALSE_GRID_CHANCE` (the same bar as the step itself) *and*
the readings off it are at most :data:`MAX_OFF_GRID_FRACTION` of the log's readings (a
handful of glitches, not a second population: a log in which more readings than that
miss the coarse grid is on the finer grid, whatever the odds). The largest such ``j``
wins. The readings off the grid are kept as read and named.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
# scipy.special, not scipy.stats: importing scipy.stats costs ~0.5 s CPU of every cold
# command (bdtrc is the binomial survival function, P(X > k))
from scipy.special import bdtrc

#: At most this fraction of a log's readings may lie off a coarser grid that is accepted.
MAX_OFF_GRID_FRACTION = 0.01


@dataclass(frozen=True)
class CoarserGrid:
    """A grid ``factor`` times the finer one, the positions of the readings off it (in
    the array given to :func:`coarser_grid`), how far off each is [steps of the coarse
    grid], and the bound on the chance that a finer-grid log looks like this (its base-10
    logarithm: the bound is often below the smallest float)."""

    factor: int
    off: np.ndarray
    off_by: np.ndarray
    log10_chance: float


def coarser_grid(q: float, x: np.ndarray, runs, merge: float, max_factor: int,
                 threshold: float) -> CoarserGrid | None:
    """The largest grid ``j·q`` (``2 ≤ j ≤ max_factor``) that nearly all levels lie on
    (see the module notes), or ``None``.

    ``x``: the readings; ``runs``: ``(a, b, levels)`` for every run with its slice of
    ``x`` and its distinct levels (on the grid ``q``); ``merge``: readings this close are
    one level; ``threshold``: the false-acceptance bar."""
    per_run = []
    for a, b, lv in runs:
        if lv.size < 2:
            continue
        ref = lv[lv.size // 2]
        per_run.append((a, b, lv, np.rint((lv - ref) / q).astype(np.int64)))
    if not per_run:
        return None
    n_read = int(sum(b - a for a, b, _ in runs))
    best = None
    for j in range(2, max_factor + 1):
        log_chance = math.log10(max_factor)  # the factors tried
        off_levels = []
        for a, b, lv, n in per_run:
            res = np.mod(n, j)
            counts = np.bincount(res, minlength=j)
            c = int(np.argmax(counts))
            on = int(counts[c])
            # P(Binomial(N, 1/j) >= on), times the j residues a run may pick
            sf = float(bdtrc(on - 1, n.size, 1.0 / j))
            tail = (math.log(sf) if sf > 0.0 else -math.inf) / math.log(10.0)
            log_chance += min(0.0, tail + math.log10(j))
            off_levels.append((a, b, lv[res != c]))
        if log_chance >= math.log10(threshold):
            continue
        off = []
        for a, b, levels in off_levels:
            for v in levels:
                off.extend(a + np.flatnonzero(np.abs(x[a:b] - v) <= merge))
        if len(off) > MAX_OFF_GRID_FRACTION * n_read:
            continue
        off = np.array(sorted(off), dtype=np.int64)
        best = (j, off, log_chance)
    if best is None:
        return None
    j, off, chance = best
    off_by = np.empty(off.size)
    for i, k in enumerate(off):  # distance to its run's coarse grid [coarse steps]
        a, b, lv, n = next(r for r in per_run if r[0] <= k < r[1])
        on = lv[np.mod(n, j) == np.bincount(np.mod(n, j), minlength=j).argmax()]
        u = (x[k] - on[0]) / (j * q)
        off_by[i] = abs(u - round(u))
    return CoarserGrid(j, off, off_by, chance)
