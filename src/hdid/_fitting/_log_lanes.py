"""The batch with logs as lanes: the logs of one model structure and length bucket fitted
together, for a GPU.

:mod:`hdid._fitting._vfit` fits one log and one start at a time — right on a CPU, where
a vmapped simulator runs its event branch as a select in every substep (one lane: 0.19 s
for the shipped log's starts, three lanes: 2.8 s), and wrong on a GPU, where a call costs
a fixed ≈ 3 ms of kernel launches whatever its width (``benchmarks/results/gpu_path.md``:
100 logs took 130 s on an H100 against 15 s on a CPU). Here the padded problems of a
bucket (:func:`hdid._fitting._vfit.pad_to_bucket`: same tree, same shapes) are stacked and
every call runs ``width`` lanes, each a (log, start) pair with its own problem:

1. the grid: every candidate of every log (:func:`hdid._fitting._starts._grid_candidates`)
   costed in calls of ``width`` lanes, each log's starts then chosen on the host exactly
   as :func:`hdid._fitting._starts._grid_starts` chooses them;
2. Levenberg–Marquardt (:func:`hdid._fitting._lm._lm_lanes`, the same iteration) from
   every start of every log, each log keeping its own :class:`~hdid._fitting._lm._Schedule`
   (phase 1 every start, phase 2 the best to convergence); a round advances the live
   starts of all logs, ``width`` lanes a call, each with its own iteration budget;
3. the restart of an optimum that holds moving runs, as a second schedule for the logs
   that need one;
4. the analysis' JAX parts (data Jacobian, trajectory, derived quantities) at every log's
   best point in calls of ``width`` lanes; the rest of the analysis per log on the host
   (:func:`hdid._fitting._fit._finish`, as the one-lane batch).

Lanes do not interact: :func:`~hdid._fitting._lm._lm_lanes` couples them only in *whether*
a Jacobian is computed in an iteration, never in the values, so a log's iterates are the
one-lane batch's up to rounding (a vmapped simulator selects where a one-lane one
branches). Each call starts its lanes from their points (no carried Levenberg–Marquardt
state: the residuals and Jacobian at a start are recomputed by the same program, the same
numbers), at one extra Jacobian per lane and call. Selected by ``fit_many(lanes="logs")``
(not the default: :func:`default_lanes`).
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._problems._problem import Problem
from ._fit import MOVED_COUNTS, _untrapped
from ._lm import LMState, _lm_lanes, _Schedule
from ._starts import _costs, _grid_candidates, with_drop_starts

#: Lanes per call on a GPU (a call costs about the same from 1 to thousands of lanes) and
#: on a CPU (every lane costs its own arithmetic, and a vmapped simulator pays for the
#: branches it does not take: keep calls narrow) — at most; fewer where a call's
#: Jacobians would pass ``LANE_JACOBIAN_BYTES``.
GPU_WIDTH = 8192
CPU_WIDTH = 32
#: Bytes of one call's Jacobians (lanes × residual rows × unknowns × 8): a Levenberg–
#: Marquardt iteration holds about four such arrays (J, the trial's, the accepted one,
#: the forward-mode tangents). 1 GiB: a 4-run 250 Hz paper log (519 × 17) gets 8192
#: lanes, an 8-run 1 kHz log of 1 s (8008 × 25) 512.
LANE_JACOBIAN_BYTES = 2**30


def default_lanes():
    """``fit_many``'s default ``lanes``: 1 (one start a call, :mod:`hdid._fitting._one_lane`)
    on every backend. Logs as lanes (``"logs"``) are for a GPU but not yet measured on
    one (``benchmarks/results/gpu_path.md``), so they are asked for, not the default."""
    from ._one_lane import LANES

    return LANES


def default_width(problem: Problem | None = None) -> int:
    """Lanes per call: :data:`GPU_WIDTH` where JAX's backend is a GPU, else
    :data:`CPU_WIDTH`; for ``problem``'s size at most ``LANE_JACOBIAN_BYTES`` of Jacobians
    a call (a power of two, at least 1)."""
    width = GPU_WIDTH if jax.default_backend() == "gpu" else CPU_WIDTH
    if problem is not None:
        size = 8 * (math.prod(problem.times.shape) + problem.n_physical) * problem.n_unknowns
        width = min(width, 2 ** max(int(math.floor(math.log2(max(LANE_JACOBIAN_BYTES // size, 1)))), 0))
    return width


# ----------------------------------------------------------------------------- programs


def _lane_map(fn):
    """``fn(problem, u)`` mapped over lanes, each with its own problem."""
    return jax.vmap(fn)


@eqx.filter_jit
def _lane_costs(problems: Problem, U):
    """χ² of every lane ``(problem, u)``."""
    return _lane_map(lambda p, u: p.cost(u))(problems, U)


@eqx.filter_jit
def _lane_solve(problems: Problem, U0, active, max_steps, state: LMState):
    """:func:`hdid._fitting._lm._lm_lanes` with a problem per lane; ``max_steps`` per lane."""
    return _lm_lanes(
        lambda U: _lane_map(lambda p, u: p.residuals(u))(problems, U),
        lambda U: _lane_map(lambda p, u: p.residuals_and_jacobian(u))(problems, U),
        U0, active, max_steps, state,
    )


@eqx.filter_jit
def _lane_analysis(problems: Problem, U):
    """:func:`hdid._fitting._fit._stored_analysis`'s parts at every lane: the residuals and
    Jacobian (prior rows included; the caller cuts them), the trajectory on the log's
    samples and the derived quantities with their Jacobian."""

    def one(p, u):
        R, J = p.residuals_and_jacobian(u)
        return R, J, p.simulate(u, p.times, full_output=True), p.derived_and_jacobian(u)

    return _lane_map(one)(problems, U)


@jax.jit
def _gather(stacked, idx):
    """The lanes' problem arrays: one program per bucket size (eager indexing compiled one
    per array)."""
    return [x[idx] for x in stacked]


class _Lanes:
    """A bucket's problems stacked (leading axis: logs) and the calls over ``width`` lanes,
    each lane a row ``(log, u)``; short calls padded with copies of their first row."""

    def __init__(self, problems: list[Problem], width: int):
        leaves = [jax.tree_util.tree_flatten(p)[0] for p in problems]
        self.treedef = jax.tree_util.tree_flatten(problems[0])[1]
        self.stacked = [jnp.asarray(np.stack([np.asarray(x[i]) for x in leaves]))
                        for i in range(len(leaves[0]))]
        self.width = int(width)
        #: residual rows of a lane: the data, then one prior row per physical parameter
        self.rows = int(math.prod(problems[0].times.shape)) + problems[0].n_physical

    def problems(self, logs):
        return jax.tree_util.tree_unflatten(self.treedef, _gather(self.stacked, jnp.asarray(logs)))

    def chunks(self, rows):
        """``(take, h)`` per call: ``width`` row indices (the last padded) and how many
        are real."""
        rows = np.asarray(rows, dtype=int)
        for g in range(0, len(rows), self.width):
            part = rows[g:g + self.width]
            yield np.concatenate([part, np.repeat(part[:1], self.width - len(part))]), len(part)

    def costs(self, log_of, U) -> np.ndarray:
        out = np.empty(len(U))
        for take, h in self.chunks(np.arange(len(U))):
            c = _lane_costs(self.problems(log_of[take]), jnp.asarray(U[take]))
            out[take[:h]] = np.asarray(c)[:h]
        return out

    def analysis(self, logs, U):
        """Per log of ``logs`` (at its row of ``U``): ``(R, J, dense, derived)`` as NumPy."""
        out = [None] * len(logs)
        logs = np.asarray(logs, dtype=int)
        for take, h in self.chunks(np.arange(len(logs))):
            res = jax.tree_util.tree_map(np.asarray, _lane_analysis(
                self.problems(logs[take]), jnp.asarray(U[take])))
            for j in range(h):
                out[take[j]] = jax.tree_util.tree_map(lambda x: x[j], res)
        return out

    def schedules(self, log_of, U, max_steps: int):
        """Levenberg–Marquardt from every row of ``U`` (row ``i`` a start of log
        ``log_of[i]``), each log with its own :class:`_Schedule`, all logs' live rows a
        round. Returns ``(U, costs, ok, steps)`` per row and the lane iterations run."""
        U = np.array(U, dtype=float)
        N, n = U.shape
        groups: dict[int, np.ndarray] = {}
        for i, g in enumerate(log_of):
            groups.setdefault(int(g), []).append(i)
        groups = {g: np.asarray(r) for g, r in groups.items()}
        sched = {g: _Schedule(len(r), max_steps) for g, r in groups.items()}
        m = self.rows  # (the state is empty: every call starts from its points)
        lane_steps = 0
        while True:
            tasks = {g: t for g, s in sched.items() if (t := s.next()) is not None}
            if not tasks:
                break
            rows = np.concatenate([groups[g][t[0]] for g, t in tasks.items()]).astype(int)
            budget = np.zeros(N, dtype=int)
            for g, (active, k, _fresh) in tasks.items():  # (every call starts fresh)
                budget[groups[g][active]] = k
            costs, done, steps = np.full(N, np.inf), np.zeros(N, bool), np.zeros(N, int)
            for take, h in self.chunks(rows):
                probs = self.problems(log_of[take])
                on = np.arange(self.width) < h
                state = LMState(*(jnp.asarray(f) for f in LMState.empty(self.width, m, n)))
                U2, c2, d2, s2, _ = _lane_solve(probs, jnp.asarray(U[take]), jnp.asarray(on),
                                                jnp.asarray(budget[take]), state)
                r = take[:h]
                U[r] = np.asarray(U2)[:h]
                costs[r], done[r], steps[r] = (np.asarray(c2)[:h], np.asarray(d2)[:h],
                                               np.asarray(s2)[:h])
            lane_steps += int(np.sum(steps))
            for g in tasks:
                r = groups[g]
                sched[g].update(costs[r], done[r], steps[r])
        out_c, out_ok, out_s = np.full(N, np.inf), np.zeros(N, bool), np.zeros(N, int)
        for g, r in groups.items():
            out_c[r], out_ok[r], out_s[r] = sched[g].costs, sched[g].ok, sched[g].steps
        return U, out_c, out_ok, out_s, lane_steps


# ----------------------------------------------------------------------------- driver


def fit_bucket(setups, padded: list[Problem], options: dict, width: int, timing, phase):
    """Fit the logs of one bucket (``setups`` and their padded problems, one model
    structure and shape) as lanes. Returns per log ``(U, costs, ok, steps, pre, start,
    n_first)``:
    the local fits of :func:`hdid._fitting._vfit._fit_log`, the analysis' precomputed parts
    on the padded problem (``None`` where every start diverged) and the log's first start
    (the data's release guesses, for the fold-back restart) and its number of grid starts
    (the limit checks' schedule, as :func:`hdid.fit`'s), or the exception that
    stopped that log. ``phase(name)``: a context adding to ``timing``'s phases."""
    n_starts = int(options.get("n_starts", 6))
    max_steps = int(options.get("max_steps", 300))
    from_model = bool(options.get("start_from_model", False))
    L = len(setups)
    lanes = _Lanes(padded, width)
    out: list = [None] * L
    with phase("grid"):
        cands, keys, log_of = [], [], []
        for i, (st, p) in enumerate(zip(setups, padded)):
            try:
                U, k = _grid_candidates(p, st.prep, st.model, from_model)
            except Exception as exc:  # noqa: BLE001 - reported in that log's row
                out[i] = exc
                U, k = np.zeros((0, p.n_unknowns)), np.zeros(0)
            cands.append(U)
            keys.append(k)
            log_of.append(np.full(len(U), i))
        log_of_c = np.concatenate(log_of)
        cost = lanes.costs(log_of_c, np.concatenate(cands)) if len(log_of_c) else np.zeros(0)
        starts, start_log, first, starts_of = [], [], {}, {}
        at = 0
        for i, (st, p) in enumerate(zip(setups, padded)):
            c = cost[at:at + len(cands[i])]
            at += len(cands[i])
            if out[i] is not None:
                continue
            try:
                U0, _ = with_drop_starts(
                    p, st.prep, st.model, cands[i], c, keys[i], n_starts, from_model,
                    lambda Ud, p=p: np.asarray(_costs(p, jnp.asarray(Ud))))
            except Exception as exc:  # noqa: BLE001
                out[i] = exc
                continue
            starts.append(U0)
            first[i] = np.asarray(U0)[0]
            starts_of[i] = U0
            start_log.append(np.full(len(U0), i))
    if not starts:
        return out
    with phase("solve"):
        log_of_s = np.concatenate(start_log)
        U, costs, ok, steps, n_it = lanes.schedules(log_of_s, np.concatenate(starts), max_steps)
        timing.lane_steps += n_it
    with phase("analyse"):
        live = sorted(set(int(g) for g in log_of_s))
        best = {g: _best_row(costs, log_of_s == g) for g in live}
        pre = dict(zip(live, lanes.analysis(live, np.stack([U[best[g]] for g in live]))))
    with phase("solve"):
        retry_rows, retry_log = [], []
        for g in live:
            st = setups[g]
            moved = np.abs(st.prep.rest - st.prep.hold) > MOVED_COUNTS * st.prep.resolution
            omega = pre[g][2][1]
            if np.isfinite(costs[best[g]]) and np.any(moved & (np.max(np.abs(omega), axis=1) == 0.0)):
                r = _untrapped(padded[g], st.prep, U[best[g]])
                if r is not None:
                    retry_rows.append(r)
                    retry_log.append(g)
        if retry_rows:
            rl = np.asarray(retry_log)
            U1, c1, ok1, s1, n1 = lanes.schedules(rl, np.stack(retry_rows), max_steps)
            timing.lane_steps += n1
            U, costs = np.concatenate([U, U1]), np.concatenate([costs, c1])
            ok, steps = np.concatenate([ok, ok1]), np.concatenate([steps, s1])
            log_of_s = np.concatenate([log_of_s, rl])
    with phase("analyse"):
        moved_best = [g for g in retry_log if _best_row(costs, log_of_s == g) != best[g]]
        if moved_best:
            new = lanes.analysis(moved_best, np.stack([U[_best_row(costs, log_of_s == g)]
                                                       for g in moved_best]))
            pre.update(zip(moved_best, new))
        for g in live:
            sel = log_of_s == g
            c = costs[sel]
            out[g] = (U[sel], c, ok[sel], steps[sel],
                      _precomputed(padded[g], pre[g]) if np.isfinite(c).any() else None,
                      first[g], len(starts_of[g]))
    return out


def _best_row(costs, sel) -> int:
    rows = np.flatnonzero(sel)
    c = costs[rows]
    return int(rows[int(np.argmin(np.where(np.isfinite(c), c, np.inf)))])


def _precomputed(problem: Problem, parts) -> dict:
    """:func:`hdid._fitting._fit._stored_analysis`'s dict from a lane's analysis parts."""
    R, J, dense, derived = parts
    m_data = int(math.prod(problem.times.shape))
    return {"jacobian": (J[:m_data], R[:m_data]), "dense": tuple(dense), "derived": derived}
