"""Levenberg–Marquardt fits one start at a time through one stored program per model
structure (:mod:`hdid._problems._programs`): the starts and the limit checks of
:func:`hdid.fit` (:mod:`hdid._fitting._limits`, whose limits are prior rows on the fit's
own problem, so they share its program) and the refits of :func:`hdid.diagnose` — the
multi-start driver of both (:func:`_local_fits`, :class:`hdid._fitting._lm._Schedule`)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from .. import _config  # noqa: F401
from .._problems import _programs
from .._problems._problem import Problem
from ._lm import LMState, _lm_lanes, _Schedule, lanes_vmap


def _solve_lanes(problem: Problem, U0, active, max_steps, state: LMState):
    """:func:`hdid._fitting._lm._solve_lanes` (the same program), run through the program store."""
    return _lm_lanes(
        lanes_vmap(problem.residuals), lanes_vmap(problem.residuals_and_jacobian), U0, active,
        max_steps, state,
    )


def _stored_solve(problem: Problem, U, active, k, state):
    return _programs.call("solve_lanes", _solve_lanes, problem, U, active, k, state)


#: Lanes of every Levenberg–Marquardt program here: one. The stick-exact simulator takes
#: its event branch (a ``lax.cond``) only in the substeps that need it; under ``vmap`` the
#: branch becomes a select that runs every branch in every substep. Measured on the
#: shipped 1 kHz log (base model, 6 grid starts, one core): 0.19 s for the whole
#: multi-start fit one start at a time, 2.8 s as 3-lane programs. One lane also means
#: one program per model structure whatever the number of starts.
LANES = 1


#: ``jnp.asarray(k)`` of the iteration budgets seen (a weakly typed integer, as the
#: program's key has it): a conversion costs ~50 µs, a fit makes tens of calls.
_BUDGETS: dict = {}


def _call_args(U, on, k, state: LMState):
    """The arguments of one :func:`_stored_solve` call (their types decide the program's
    key): ``U`` and ``on`` as float64 and bool NumPy arrays (the program takes them as
    ``jnp.asarray`` would give them, without a conversion of ours), ``k`` a JAX integer."""
    if type(k) is int:  # (a NumPy integer converts to a strongly typed one: not cached)
        kk = _BUDGETS.get(k)
        if kk is None:
            kk = _BUDGETS.setdefault(k, jnp.asarray(k))
    else:
        kk = jnp.asarray(k)
    return np.asarray(U, dtype=float), np.asarray(on, dtype=bool), kk, state


def _local_fits(problem: Problem, U0, max_steps: int, lanes: int = LANES, solve=None,
                group: int | None = None, stop_below: float = -np.inf,
                verdict_line: float = np.inf):
    """:func:`hdid._fitting._lm._local_fits` (the same schedule, :class:`hdid._fitting._lm._Schedule`,
    and, lanes not interacting, the same iterates for every start up to rounding: a
    vmapped simulator selects where a one-lane one branches) run as calls of one
    ``lanes``-wide program from :mod:`hdid._problems._programs`: the starts a call advances are
    taken ``lanes`` at a time, a short group padded with inactive copies. (``solve``:
    another program with :func:`_solve_lanes`'s signature, for tests.)

    ``group``: the rows are scheduled ``group`` at a time, each group with a schedule of
    its own, a short group padded with copies of its first row — what a ``group``-lane
    vmapped call of :func:`hdid._fitting._lm._local_fits` did (the limit checks of
    :func:`hdid.fit` keep that schedule); default: one schedule for all rows. Rows whose
    unknowns and state are identical (such copies) are computed once: a one-lane program
    gives them identical results.

    ``stop_below``, ``verdict_line``: the schedule's (:class:`hdid._fitting._lm._Schedule`).

    Returns ``(U, costs, ok, steps, residuals)``, the residuals at each row of ``U`` (NaN
    where none were computed)."""
    U0 = np.asarray(U0, dtype=float)
    if group is not None and len(U0) > 0:
        outs = []
        for i in range(0, len(U0), group):
            rows = U0[i:i + group]
            pad = np.concatenate([rows, np.repeat(rows[:1], group - len(rows), axis=0)])
            outs.append([np.asarray(x)[:len(rows)]
                         for x in _local_fits(problem, pad, max_steps, lanes, solve,
                                              stop_below=stop_below, verdict_line=verdict_line)])
        return tuple(np.concatenate(parts) for parts in zip(*outs))
    solve = _stored_solve if solve is None else solve
    if lanes == 1:
        return _one_at_a_time(problem, U0, max_steps, solve, stop_below, verdict_line)
    U = np.array(U0, dtype=float)
    N, n = U.shape
    sched = _Schedule(N, max_steps, stop_below, verdict_line)
    m = int(np.prod(problem.times.shape)) + problem.n_physical
    state = [np.asarray(f) for f in LMState.empty(N, m, n)]
    while (task := sched.next()) is not None:
        active, k, fresh = task
        costs, done, steps = np.full(N, np.inf), np.zeros(N, dtype=bool), np.zeros(N, dtype=int)
        idx = np.flatnonzero(active)
        if lanes == 1:  # identical rows (padding copies) once: identical results
            first: dict = {}
            twins = {}
            for r in idx:
                key = (U[r].tobytes(), *(f[r].tobytes() for f in state))
                if key in first:
                    twins[r] = first[key]
                else:
                    first[key] = r
            idx = np.array(list(first.values()), dtype=int)
        else:
            twins = {}
        for g in range(0, len(idx), lanes):
            rows = idx[g:g + lanes]
            take = np.concatenate([rows, np.repeat(rows[:1], lanes - len(rows))])
            on = np.arange(lanes) < len(rows)
            st = LMState(*(f[take] for f in state))
            st = st._replace(fresh=np.where(on, fresh, st.fresh))
            U2, c2, d2, s2, st2 = solve(problem, *_call_args(U[take], on, k, st))
            h = len(rows)
            U[rows] = np.asarray(U2)[:h]
            costs[rows], done[rows], steps[rows] = (np.asarray(c2)[:h], np.asarray(d2)[:h],
                                                    np.asarray(s2)[:h])
            for f, new in zip(state, st2):
                f[rows] = np.asarray(new)[:h]
        for r, o in twins.items():
            U[r], costs[r], done[r], steps[r] = U[o], costs[o], done[o], steps[o]
            for f in state:
                f[r] = f[o]
        sched.update(costs, done, steps)
    return U, sched.costs, sched.ok, sched.steps, np.where(state[2][:, None], state[0], np.nan)


def _one_at_a_time(problem: Problem, U0, max_steps: int, solve, stop_below: float,
                   verdict_line: float = np.inf):
    """:func:`_local_fits` with one lane a call: each row's LM state stays as the program
    returned it (device arrays, its Jacobian never copied to the host between calls), and
    rows with the same unknowns and the same state object — a short group's padding
    copies, which stay twins while the schedule treats them alike — are computed once.
    The same calls on the same numbers as the general path, in the same order."""
    U = np.array(U0, dtype=float)
    N, n = U.shape
    sched = _Schedule(N, max_steps, stop_below, verdict_line)
    m = int(np.prod(problem.times.shape)) + problem.n_physical
    empty = LMState(*(np.asarray(f) for f in LMState.empty(1, m, n)))
    state = [empty] * N
    on = np.ones(1, dtype=bool)
    while (task := sched.next()) is not None:
        active, k, fresh = task
        costs, done, steps = np.full(N, np.inf), np.zeros(N, dtype=bool), np.zeros(N, dtype=int)
        first: dict = {}
        for r in np.flatnonzero(active):
            key = (U[r].tobytes(), id(state[r]))
            if key in first:  # a twin: the result of its first copy
                o = first[key]
                U[r], costs[r], done[r], steps[r] = U[o], costs[o], done[o], steps[o]
                state[r] = state[o]
                continue
            first[key] = r
            st = state[r]._replace(fresh=np.full(1, fresh, dtype=bool))
            U2, c2, d2, s2, st2 = solve(problem, *_call_args(U[r:r + 1], on, k, st))
            U[r] = np.asarray(U2)[0]
            costs[r], done[r], steps[r] = np.asarray(c2)[0], np.asarray(d2)[0], np.asarray(s2)[0]
            state[r] = LMState(*st2)
        sched.update(costs, done, steps)
    R = np.stack([np.asarray(st.R)[0] for st in state])
    have = np.array([bool(np.asarray(st.have)[0]) for st in state])
    return U, sched.costs, sched.ok, sched.steps, np.where(have[:, None], R, np.nan)


def solve_fresh(problem: Problem, U0, active, max_steps: int):
    """:func:`hdid._fitting._lm.solve_fresh` (every row a fresh Levenberg–Marquardt of at
    most ``max_steps`` iterations; ``max_steps`` 0 evaluates the cost only) row by row
    through the stored one-lane program of :func:`hdid.fit`: no vmapped program of its
    own to trace, and the simulator's event branch stays a branch. A drop-in for the
    posterior's mode search and limit fits (``_posterior/lanes.py``, with one lane per
    call). Inactive rows: unchanged, cost inf, not done, 0 iterations. Returns ``(U, cost,
    done, iterations)`` as NumPy arrays."""
    from ._lm import residual_rows

    U = np.array(U0, dtype=float)
    on = np.broadcast_to(np.asarray(active, dtype=bool), (len(U),))
    cost, done, k = np.full(len(U), np.inf), np.zeros(len(U), bool), np.zeros(len(U), int)
    if not on.any():
        return U, cost, done, k
    m, n = residual_rows(problem, jnp.asarray(U[0])), U.shape[1]
    empty = [np.asarray(f) for f in LMState.empty(1, m, n)]
    for i in np.flatnonzero(on):
        u2, c2, d2, k2, _ = _stored_solve(problem, *_call_args(U[i:i + 1], on[i:i + 1],
                                                               max_steps, LMState(*empty)))
        U[i], cost[i], done[i], k[i] = (np.asarray(u2)[0], np.asarray(c2)[0],
                                        np.asarray(d2)[0], np.asarray(k2)[0])
    return U, cost, done, k
