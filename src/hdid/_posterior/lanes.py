"""The fit's Levenberg–Marquardt program over rows of starts, for the mode search and the
limit fits (:mod:`.modes`, :mod:`.limits`)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .._fitting._one_lane import solve_fresh  # noqa: E402,F401 (the fit's engine, re-exported)


#: Rows per call of the mode search's Levenberg–Marquardt. ``solve_fresh`` is the fit's
#: one-lane engine (:mod:`hdid._fitting._one_lane`): it runs the rows of a call one at a
#: time through the program ``hdid.fit`` stored, so the search compiles nothing of its own
#: whatever its number of candidates (a program per candidate count cost 27–32 s in a fresh
#: process, docs/decisions/mode-search-programs.md); the block size only bounds the
#: padding (padded rows are inactive and not run).
MODE_LANES = 6


def _solve_in_lanes(solve_fresh, prob, U, active, steps, lanes: int | None = None):
    """``solve_fresh`` over the rows of ``U`` in calls of ``lanes`` rows (the last padded
    with inactive copies; ``lanes`` 0: one call of every row); calls whose rows are all
    inactive are skipped. Returns
    ``(U, cost, done)`` as NumPy arrays (inactive rows: unchanged, cost inf, not done)."""
    U = np.array(U, dtype=float)
    active = np.asarray(active, dtype=bool)
    n = len(U)
    lanes = MODE_LANES if lanes is None else int(lanes)
    lanes = n if lanes <= 0 else lanes  # 0: every row in one call
    U_out, cost, done = U.copy(), np.full(n, np.inf), np.zeros(n, dtype=bool)
    for i in range(0, n, lanes):
        a = active[i : i + lanes]
        if not a.any():
            continue
        blk, k = U[i : i + lanes], len(a)
        if k < lanes:
            blk = np.concatenate([blk, np.repeat(blk[:1], lanes - k, axis=0)])
            a = np.concatenate([a, np.zeros(lanes - k, dtype=bool)])
        u2, c2, d2, _ = map(np.asarray, solve_fresh(prob, jnp.asarray(blk), jnp.asarray(a), steps))
        U_out[i : i + k], cost[i : i + k], done[i : i + k] = u2[:k], c2[:k], d2[:k]
    return U_out, cost, done
