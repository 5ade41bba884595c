"""An encoder grid whose levels lie many steps apart: a bisection over the step, and the
chance that a wrong grid fits with one offset per run.

:func:`~hdid._log._resolution.find_step` narrows an interval ``[qlo, qhi]`` for the step
from the level differences whose multiple the interval allows only once. A fine encoder
sampled slowly, printed with a few more decimals than it resolves (a 2^19-count encoder,
0.00069°, printed to 0.0001°: 7 print units a step), shows levels tens to thousands of
steps apart. No difference then has one multiple in ``[qlo, qhi]`` (``qhi − qlo`` is
about a print unit, a seventh of the step; a difference of 50 steps allows 8 multiples),
nothing narrows the interval, and a grid the readings tell went unseen.

:func:`steps_in` bisects the interval instead: a sub-interval ``[a, b]`` survives while
every difference ``d`` (tolerance ``t``) admits a multiple, ``⌈(d − t)/b⌉ ≤ ⌊(d + t)/a⌋``
(the true step's sub-interval always does), and is split until each difference admits
one; the survivors are the candidate grids. A wrong grid survives a difference with
multiple ``m`` once the sub-interval is narrower than ``q/m`` only with chance ``≈ 2t/q``,
so the survivors stay few (bounded by :data:`MAX_ALIVE`, beyond which the log does not
tell its grid).

:func:`offset_chance` is the chance that levels of a log on no grid fit a grid ``q``
*with one offset per run*: each level within its own half print unit ``t_i`` of
``offset + m_i·q``. ``n`` levels at random phases lie in one arc of width ``w`` of the
circle ``q`` with probability ``n (w/q)^(n−1)`` (``w ≤ q/2``); with one print unit ``p``
every level's arc is ``w = p``. Measuring each level from the run's middle level instead
(what ``find_step`` first tests) doubles the arc to ``2p`` — the middle level's rounding
adds to each — and costs a factor ``2^(n−1)/n``: 15 levels at 13.7 print units a step
(a 2^18 encoder, 0.0014°, printed to 0.0001°) reach 10^−11.7 that way, 10^−14.7 this way.
"""

from __future__ import annotations

import math

import numpy as np

from ._lattice import shares

#: The bisection gives up (the log does not tell its grid) beyond this many sub-intervals.
MAX_ALIVE = 1 << 15
#: What one test call costs beyond its elements (numpy's overhead), in element tests.
_CALL_COST = 20_000
#: Elements (sub-intervals × differences) tested at once.
_CHUNK = 1 << 22


def _admits(a: np.ndarray, b: np.ndarray, d: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Count of multiples each difference admits in each sub-interval ``(len(a), len(d))``
    (``≤ 0``: none)."""
    lo = np.maximum(np.ceil((d - t)[None, :] / b[:, None] - 1e-12), 0.0)
    hi = np.floor((d + t)[None, :] / a[:, None] + 1e-12)
    return hi - lo + 1.0


class Budget:
    """Tests of one difference against one sub-interval that one log may spend (an analog
    log has no grid to find, and each divisor of its closest gap is searched in turn)."""

    def __init__(self, tests: float) -> None:
        self.left = tests


def steps_in(d: np.ndarray, t: np.ndarray, qlo: float, qhi: float,
             budget: Budget | None = None) -> list[tuple[float, float]] | None:
    """Sub-intervals of ``[qlo, qhi]`` in which every difference ``d`` (> 0, tolerance
    ``t``) admits exactly one multiple of the step; ``None`` when more than
    :data:`MAX_ALIVE` sub-intervals stay possible or the ``budget`` is spent (the log
    does not tell its grid)."""
    order = np.argsort(d, kind="stable")  # small multiples prune first
    d, t = d[order], t[order]
    a, b = np.array([qlo]), np.array([qhi])
    done: list[tuple[float, float]] = []
    for _ in range(200):
        if a.size == 0:
            break
        keep = np.ones(a.size, dtype=bool)
        single = np.ones(a.size, dtype=bool)
        j, size = 0, 64  # the small differences first: they drop most sub-intervals
        while j < d.size:
            alive = np.flatnonzero(keep)
            if alive.size == 0:
                break
            size = min(size, max(1, _CHUNK // alive.size))
            n = _admits(a[alive], b[alive], d[j:j + size], t[j:j + size])
            if budget is not None:
                budget.left -= n.size + _CALL_COST
                if budget.left < 0:
                    return None
            keep[alive] = np.all(n >= 1.0, axis=1)
            single[alive] &= np.all(n <= 1.0, axis=1)
            j, size = j + size, 4 * size
        single &= keep
        done += list(zip(a[single].tolist(), b[single].tolist()))
        split = keep & ~single
        a, b = a[split], b[split]
        mid = 0.5 * (a + b)
        a, b = np.concatenate((a, mid)), np.concatenate((mid, b))
        if a.size > MAX_ALIVE:
            return None
    return done


def offset_chance(levels: list[np.ndarray], tols: list[np.ndarray],
                  multiples: list[np.ndarray], qlo: float, qhi: float,
                  units: list[np.ndarray] | None = None) -> tuple[float, float] | None:
    """``(step, log10 chance)`` for levels of each run that lie within their tolerances of
    ``offset_r + multiples·q`` for one ``q`` in ``[qlo, qhi]`` and one offset per run, or
    ``None`` where no such ``q`` exists. The step is the one that leaves most room
    (the largest least margin, a Chebyshev fit); the chance is
    ``Σ_r [log10 n_r + Σ_i log10 c_i − max_i log10 c_i]`` with ``c_i = 2 t_i/q`` (module
    notes), or, for levels printed to ``units``, the share of that print lattice a window
    of ``2 t_i`` holds where that is larger (:mod:`._lattice`)."""

    def spare(q: float) -> float:
        # the least room any run leaves for its offset at step q (< 0: none)
        worst = math.inf
        for lv, tl, m in zip(levels, tols, multiples):
            r = lv - m * q
            worst = min(worst, float(np.min(r + tl) - np.max(r - tl)))
        return worst

    lo, hi = qlo, qhi  # spare(q) is concave: a golden-section search for its maximum
    g = (math.sqrt(5.0) - 1.0) / 2.0
    x1, x2 = hi - g * (hi - lo), lo + g * (hi - lo)
    f1, f2 = spare(x1), spare(x2)
    for _ in range(120):
        if f1 < f2:
            lo, x1, f1 = x1, x2, f2
            x2 = lo + g * (hi - lo)
            f2 = spare(x2)
        else:
            hi, x2, f2 = x2, x1, f1
            x1 = hi - g * (hi - lo)
            f1 = spare(x1)
    q, room = (x1, f1) if f1 >= f2 else (x2, f2)
    if room < 0.0:
        return None
    log_chance = 0.0
    for r, tl in enumerate(tols):
        if units is not None and np.any(units[r] > 0):
            per = np.log10(shares(q, units[r], 2.0 * tl, float(np.ptp(levels[r]))))
        else:
            per = np.log10(np.minimum(2.0 * tl / q, 1.0))
        log_chance += math.log10(tl.size) + float(per.sum() - per.max())
    return q, log_chance



def resolved(intervals: list[tuple[float, float]], d: np.ndarray, t: np.ndarray, runs,
             budget: Budget | None = None):
    """The intervals of :func:`steps_in` narrowed to what their multiples allow, with the
    multiples, where every two neighbouring levels of a run agree with them too.

    In an interval of :func:`steps_in` every difference ``d`` (from a run's middle level)
    admits one multiple ``m``; ``q`` then lies in ``[max (d − t)/m, min (d + t)/m]``.
    Neighbouring levels ``i, j`` of a run (sorted) must also lie within ``t_i + t_j`` of
    their multiples' difference, ``|Δlevel − Δm·q| ≤ t_i + t_j`` — a necessary condition of
    :func:`offset_chance`'s fit that most intervals left by the bisection fail. All
    intervals are tested at once. ``runs``: per run ``(levels, tols, others, sign)``, the
    differences ``d`` being ``|levels[others] − middle|`` run after run. Yields
    ``(lo, hi, m)``; ``None`` (instead of a list) when the ``budget`` is spent."""
    a_all = np.array([a for a, _ in intervals])
    b_all = np.array([b for _, b in intervals])
    out = []
    size = max(1, _CHUNK // max(d.size, 1))
    for c in range(0, a_all.size, size):
        a, b = a_all[c:c + size], b_all[c:c + size]
        if budget is not None:
            budget.left -= 4 * a.size * d.size + _CALL_COST
            if budget.left < 0:
                return None
        m = np.maximum(np.ceil((d - t)[None, :] / b[:, None] - 1e-12), 0.0)
        ok = np.all(m >= 1.0, axis=1)
        safe = np.where(m >= 1.0, m, 1.0)
        lo = np.maximum(a, np.max((d - t)[None, :] / safe, axis=1))
        hi = np.minimum(b, np.min((d + t)[None, :] / safe, axis=1))
        ok &= lo <= hi
        nlo, nhi, at = lo.copy(), hi.copy(), 0
        for lv, tl, others, sign in runs:
            n = sign.size
            mult = np.zeros((a.size, lv.size))
            mult[:, others] = sign[None, :] * m[:, at:at + n]
            at += n
            if lv.size < 2:
                continue
            dl = np.diff(lv)[None, :]  # > 0: the levels are sorted
            dm = np.diff(mult, axis=1)
            tt = (tl[1:] + tl[:-1])[None, :]
            ok &= ~np.any((dm == 0) & (dl > tt), axis=1)
            pos = np.where(dm > 0, dm, np.nan)
            neg = np.where(dm < 0, -dm, np.nan)
            with np.errstate(all="ignore"):
                nlo = np.fmax(nlo, np.nanmax(np.where(dm > 0, (dl - tt) / pos, -np.inf), axis=1))
                nhi = np.fmin(nhi, np.nanmin(np.where(dm > 0, (dl + tt) / pos, np.inf), axis=1))
                nhi = np.fmin(nhi, np.nanmin(np.where(dm < 0, (tt - dl) / neg, np.inf), axis=1))
        ok &= nlo <= nhi + 1e-12 * b  # (slack for rounding: never stricter than the fit)
        for i in np.flatnonzero(ok):
            out.append((float(lo[i]), float(hi[i]), m[i].astype(np.int64)))
    return out
