"""Levenberg–Marquardt on many starts at once: the schedule (phase 1 every start, phase 2 the
best to convergence) and the lanes engine (hand-stepped LM, one lane per start or log)."""

from __future__ import annotations

from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .._problems._problem import Problem


def _local_fits(problem: Problem, U0, max_steps: int, solve=None):
    """Levenberg–Marquardt from every row of ``U0``. Phase 1: every start a few
    iterations; phase 2: the best ones to convergence (:class:`_Schedule`). All starts are
    lanes of one program; a call advances the live ones. ``solve`` runs that program
    (default :func:`_solve_lanes`; diagnose passes one from its program store)."""
    solve = _solve_lanes if solve is None else solve
    U = np.array(U0)
    sched = _Schedule(len(U0), max_steps)
    m = int(np.prod(problem.times.shape)) + problem.n_physical
    state = LMState.empty(len(U0), m, U.shape[1])
    while (task := sched.next()) is not None:
        active, k, fresh = task
        state = state._replace(fresh=np.where(active, fresh, np.asarray(state.fresh)))
        U2, c2, done2, s2, state = solve(
            problem, jnp.asarray(U), jnp.asarray(active), jnp.asarray(k), state
        )
        state = LMState(*state)
        U2 = np.asarray(U2)
        U[active] = U2[active]
        sched.update(np.asarray(c2), np.asarray(done2), np.asarray(s2))
    return U, sched.costs, sched.ok, sched.steps


#: Stop when two consecutive accepted Levenberg–Marquardt steps each lower χ² (residuals
#: in units of the quantization σ) by less than this: the optimum is then within about
#: sqrt(0.01) = 0.1 standard deviations along every direction, and the remaining crawl
#: along flat (prior-dominated) valleys would only cost time.
CHI2_STALL = 0.01


#: Iterations every start gets before only the best ``CONTINUED_STARTS`` go on.
PHASE1_STEPS = 12
CONTINUED_STARTS = 3
#: Phase-2 iterations between checks, and the χ² excess over the best lane at which a
#: lane is abandoned (a different, clearly worse basin: Δχ² = 50 is ~7 standard errors).
PHASE2_CHUNK = 25
DROP_DCHI2 = 50.0


class _Schedule:
    """Which starts of one log run next, and for how long (shared by :func:`fit` and the
    vectorised batch, so that both give every log the same fit).

    Phase 1: every start ``PHASE1_STEPS`` iterations; phase 2: the ``CONTINUED_STARTS``
    best to convergence or ``max_steps``, in chunks of ``PHASE2_CHUNK``; between chunks a
    lane stuck in a basin far worse than the best (Δχ² > ``DROP_DCHI2``) stops. Each call
    (phase 1, every chunk) starts its lanes ``fresh`` (see :class:`LMState`).

    Measured and not kept (``benchmarks/results/batch_speed.md``): checking the Δχ² drop
    every 5 iterations instead of 25 (7 of 40 logs ended in a worse basin), stopping
    phase-1 starts early by their χ² (1 in 80 worse, 7 % fewer iterations), a looser
    stall (0.03: 22 of 80 logs worse by > 0.1).

    ``stop_below``: every lane stops at a check once one has converged below this cost —
    for a fit whose only question is whether some optimum lies below it (a limit's
    verdict at the floor, :func:`hdid._fitting._limits.verdict_cost`); further iterations
    could only lower the answer's χ², not change it.

    ``verdict_line``: the cost above which that answer is "no" (a limit at the floor: the
    fit's cost plus the limit's likelihood-ratio bound). It counts as a lane at every
    phase-2 check: a lane ``DROP_DCHI2`` or more above it stops, as one that far above the
    best lane does — so a limit whose every start lies in a clearly worse basin after
    phase 1 and a chunk stops there, its cost that of its best start so far (an upper
    bound of its optimum's, far above the line), not its optimum's. Not at the end of
    phase 1: a start 50 above after its 12 iterations can still end below (measured on
    60 paper logs, ``benchmarks/results/fit_speed.md``: 2 "fits better"/"fits as well"
    verdicts lost).
    """

    def __init__(self, n: int, max_steps: int, stop_below: float = -np.inf,
                 verdict_line: float = np.inf):
        self.stop_below = float(stop_below)
        self.verdict_line = float(verdict_line)
        self.max_steps = int(max_steps)
        self.phase = 1
        self.used = 0
        self.active = np.ones(n, dtype=bool)
        self.costs = np.full(n, np.inf)
        self.ok = np.zeros(n, dtype=bool)
        self.steps = np.zeros(n, dtype=int)
        self._k = 0

    def next(self):
        """``(active lanes, iterations, fresh)`` of the next call, or None when done."""
        if self.phase == 1:
            k = PHASE1_STEPS
        else:
            if not self.active.any() or self.used >= self.max_steps:
                return None
            k = min(PHASE2_CHUNK, self.max_steps - self.used)
        self._k = k
        return self.active.copy(), k, True

    def update(self, costs, done, steps) -> None:
        """Results of the call for its active lanes."""
        a = self.active
        self.costs[a], self.steps[a] = costs[a], self.steps[a] + steps[a]
        self.used += self._k
        finite = np.where(np.isfinite(self.costs), self.costs, np.inf)
        if self.phase == 1:
            self.phase, self.used = 2, 0
            self.active = np.zeros(len(a), dtype=bool)
            self.active[np.argsort(finite, kind="stable")[:CONTINUED_STARTS]] = True
        else:
            self.ok[a] = done[a]
            best = min(finite.min(), self.verdict_line)  # inf when every lane diverged: none goes on
            self.active = a & ~done & (finite - best < DROP_DCHI2) if np.isfinite(best) else a & False
            if np.any(self.ok & (finite < self.stop_below)):  # the question is answered
                self.active[:] = False


# ------------------------------------------------------------------ hand-stepped LM

#: optimistix's ClassicalTrustRegion constants (Gould et al.), which :func:`_lm_lanes`
#: reproduces: a trial is accepted when the χ² decrease is at least ``LM_LOW`` of the
#: Gauss–Newton prediction; above ``LM_HIGH`` of it the damping falls by ``LM_GROW``;
#: a rejected trial multiplies the damping by ``LM_SHRINK``.
LM_LOW, LM_HIGH, LM_GROW, LM_SHRINK = 0.01, 0.99, 3.5, 4.0
#: Stop a lane when its step is below this relative to |u| (optimistix's Cauchy test
#: with rtol = atol = 1e-8).
LM_XTOL = 1e-8


class LMState(NamedTuple):
    """Per-lane state of :func:`_lm_lanes` carried from one call to the next.

    ``fresh`` lanes start as optimistix's solver does in a new call — damping 1, stall
    count 0, and the evaluation at the start point counted as one iteration — so that
    the schedule's phases reproduce ``optimistix.LevenbergMarquardt`` (the reference
    since the first release), while a call that continues a lane (``fresh`` false) is
    indistinguishable from a longer one.
    """

    R: jax.Array  # residuals at U        (L, m)
    J: jax.Array  # Jacobian at U         (L, m, n)
    have: jax.Array  # R, J valid          (L,)
    lam: jax.Array  # damping λ            (L,)
    stall: jax.Array  # consecutive small accepted steps
    jfirst: jax.Array  # last trial accepted: evaluate the next with its Jacobian
    fresh: jax.Array  # start as a new optimistix call

    @staticmethod
    def empty(L: int, m: int, n: int) -> "LMState":
        return LMState(
            np.zeros((L, m)), np.zeros((L, m, n)), np.zeros(L, dtype=bool), np.ones(L),
            np.zeros(L, dtype=int), np.zeros(L, dtype=bool), np.ones(L, dtype=bool),
        )


def _lm_lanes(residuals, residuals_and_jacobian, U0, active, max_steps, state: LMState):
    """Levenberg–Marquardt for a batch of lanes; a rejected trial costs one forward pass.

    ``residuals(U) -> R`` and ``residuals_and_jacobian(U) -> (R, J)`` act on all lanes
    ``U (L, n)``. The iteration is optimistix's ``LevenbergMarquardt`` with a normal-
    equations Cholesky solve, ``(JᵀJ + λI) δ = −Jᵀr``, and its ``ClassicalTrustRegion``
    update of ``λ`` — so the path of every lane is the same — but the control flow is
    over the whole batch rather than vmapped, so the forward-mode Jacobian (≈ 3× a
    forward pass) is computed only where it is used: a trial after a rejected one is a
    forward pass, and the Jacobian follows only if it is accepted (with one lane per
    program; a batch computes it when any lane needs it). optimistix evaluates every
    trial with its Jacobian, and about a third of the trials are rejected.

    Stops a lane after two consecutive accepted steps that each lower χ² by less than
    ``CHI2_STALL``, after a negligible step, or with non-finite residuals at its start.
    Returns ``(U, cost, done, iterations, state)``.
    """
    L, n = U0.shape
    # Each function is called at two or three places below; as inner jits they are traced
    # once each (JAX caches the trace per function), not once per call site — the
    # stick-exact simulation is the slow part of tracing a cold `hdid fit`.
    residuals = jax.jit(residuals)
    residuals_and_jacobian = jax.jit(residuals_and_jacobian)
    max_steps = jnp.broadcast_to(jnp.asarray(max_steps), (L,))
    fresh = state.fresh & active
    R0, J0 = jax.lax.cond(
        jnp.all(state.have | ~active),
        lambda: (state.R, state.J),
        lambda: residuals_and_jacobian(U0),
    )
    cost0 = jnp.sum(R0**2, axis=1)
    finite0 = jnp.isfinite(cost0) & jnp.all(jnp.isfinite(J0), axis=(1, 2))
    cost0 = jnp.where(finite0, cost0, jnp.inf)
    init = dict(
        U=U0, R=R0, J=J0, cost=cost0,
        lam=jnp.where(fresh, 1.0, state.lam),
        stall=jnp.where(fresh, 0, state.stall),
        jfirst=jnp.where(fresh, False, state.jfirst),
        done=~active | ~finite0,
        k=jnp.where(fresh, 1, 0),
    )
    eye = jnp.eye(n)

    def cond(c):
        return jnp.any(~c["done"] & (c["k"] < max_steps))

    def body(c):
        live = ~c["done"] & (c["k"] < max_steps)
        U, R, J, cost, lam = c["U"], c["R"], c["J"], c["cost"], c["lam"]
        A = jnp.einsum("lmi,lmj->lij", J, J)
        g = jnp.einsum("lmi,lm->li", J, R)
        chol = jnp.linalg.cholesky(A + lam[:, None, None] * eye)
        delta = -jax.vmap(lambda C, b: jax.scipy.linalg.cho_solve((C, True), b))(chol, g)
        delta = jnp.where(live[:, None], delta, 0.0)
        Ut = U + delta
        # After an accepted trial the next is likely accepted too: evaluate it with its
        # Jacobian at once. After a rejection, the forward pass only.
        with_J = jnp.any(live & c["jfirst"])
        Rt, Jt = jax.lax.cond(
            with_J, lambda: residuals_and_jacobian(Ut), lambda: (residuals(Ut), J)
        )
        cost_t = jnp.sum(Rt**2, axis=1)
        # Gauss–Newton predicted decrease |r|² − |r + Jδ|² (ClassicalTrustRegion).
        pred = -(2.0 * jnp.sum(g * delta, axis=1) + jnp.einsum("li,lij,lj->l", delta, A, delta))
        actual = cost - cost_t
        acc = live & jnp.isfinite(cost_t) & (actual >= LM_LOW * pred)
        good = acc & (actual > LM_HIGH * pred) & (pred > 0)
        U_new = jnp.where(acc[:, None], Ut, U)
        need = acc & ~with_J
        R_new, J_new = jax.lax.cond(
            jnp.any(need), lambda: residuals_and_jacobian(U_new), lambda: (Rt, Jt)
        )
        R_new = jnp.where(acc[:, None], R_new, R)
        J_new = jnp.where(acc[:, None, None], J_new, J)
        cost_new = jnp.where(acc, jnp.sum(R_new**2, axis=1), cost)
        lam_new = jnp.where(good, lam / LM_GROW, jnp.where(acc, lam, LM_SHRINK * lam))
        small = acc & (cost - cost_new < CHI2_STALL)
        stall = jnp.where(small, c["stall"] + 1, jnp.where(acc, 0, c["stall"]))
        tiny = jnp.linalg.norm(delta, axis=1) <= LM_XTOL * (jnp.linalg.norm(U, axis=1) + LM_XTOL)
        done = c["done"] | (live & ((stall >= 2) | tiny))
        return dict(
            U=U_new, R=R_new, J=J_new, cost=cost_new, done=done,
            lam=jnp.where(live, lam_new, lam), stall=stall,
            jfirst=jnp.where(live, acc, c["jfirst"]), k=c["k"] + live.astype(int),
        )

    out = jax.lax.while_loop(cond, body, init)
    new_state = LMState(
        out["R"], out["J"], active & finite0, out["lam"], out["stall"], out["jfirst"],
        jnp.zeros(L, dtype=bool),
    )
    return out["U"], out["cost"], out["done"] & active, out["k"], new_state


def lanes_vmap(fn, *, shared: int = 0):
    """``jax.vmap(fn)`` over a leading lane axis, but a single lane is not vmapped.

    The simulator's event branch is a ``lax.cond`` that runs only in the substeps that
    need it (:func:`hdid._simulation._simulate.simulate_runs`); under ``vmap`` it becomes a select
    that runs every branch. One-lane programs (the batch fit's) keep the ``cond``.
    The first ``shared`` arguments are not batched.
    """

    def mapped(*args):
        lanes = jax.tree_util.tree_leaves(args[shared:])[0].shape[0]
        if lanes == 1:
            one = [jax.tree_util.tree_map(lambda x: x[0], a) for a in args[shared:]]
            out = fn(*args[:shared], *one)
            return jax.tree_util.tree_map(lambda x: x[None], out)
        axes = (None,) * shared + (0,) * (len(args) - shared)
        return jax.vmap(fn, in_axes=axes)(*args)

    return mapped


@eqx.filter_jit
def _solve_lanes(problem: Problem, U0, active, max_steps, state: LMState):
    """:func:`_lm_lanes` for the starts of one log."""
    return _lm_lanes(
        lanes_vmap(problem.residuals), lanes_vmap(problem.residuals_and_jacobian), U0, active,
        max_steps, state,
    )


#: Residual rows per problem structure (:func:`residual_rows`).
_ROWS: dict = {}


def residual_rows(problem, u) -> int:
    """Rows of ``problem.residuals(u)``: ``jax.eval_shape`` once per
    problem structure — its tree (type and static fields) and its arrays' shapes and
    dtypes; a problem whose prior rows or data values change has the same count. The
    shape evaluation traces the simulation (0.24–0.30 s on the shipped paper log, against
    17 ms for a 6-lane LM call; the driven fit and the posterior's mode search and limit
    fits call :func:`solve_fresh` tens to hundreds of times,
    ``docs/decisions/mode-search-programs.md``)."""
    leaves, treedef = jax.tree_util.tree_flatten(problem)
    try:
        key = (treedef, tuple(u.shape), str(u.dtype), tuple((tuple(np.shape(x)), str(getattr(x, "dtype", type(x))))
                                 for x in leaves))
        hash(key)
    except TypeError:  # an unhashable static field: no cache
        key = None
    if key is None or key not in _ROWS:
        m = jax.eval_shape(problem.residuals, jax.ShapeDtypeStruct(u.shape, u.dtype)).shape[0]
        if key is None:
            return m
        _ROWS[key] = m
    return _ROWS[key]


def solve_fresh(problem, U0, active, max_steps):
    """Levenberg–Marquardt from every row of ``U0``, at most ``max_steps`` iterations,
    every lane started fresh: ``(U, cost, done, iterations)``. The one engine
    (:func:`_lm_lanes`) for any :class:`~hdid._problems._base.AbstractProblem` (free,
    driven, joint) — what the driven fit calls in chunks."""
    U0 = jnp.asarray(U0)
    L, n = U0.shape
    m = residual_rows(problem, U0[0])
    U, cost, done, k, _ = _solve_lanes(problem, U0, jnp.asarray(active), jnp.asarray(max_steps),
                                       LMState.empty(L, m, n))
    return U, cost, done, k
