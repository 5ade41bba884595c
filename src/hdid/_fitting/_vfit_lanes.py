"""The compiled lane programs of the vectorised batch fit and the buckets they run on: each
lane is one (log, start) pair with its own log's arrays; logs of one structure and padded
shape share a bucket; :class:`_LogFit` is one log's progress (:mod:`hdid._fitting._vfit` drives
them)."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field

import equinox as eqx
import jax
import numpy as np

from ._fit import _Setup
from ._lm import LMState, _lm_lanes, _Schedule, lanes_vmap
from .._problems._problem import Problem


# ----------------------------------------------------------------------------- programs


@eqx.filter_jit
def _lane_costs(problems: Problem, U):
    """χ² of each lane's candidate under its own log's problem (forward simulation only)."""
    return jax.vmap(lambda p, u: p.cost(u))(problems, U)


@eqx.filter_jit
def _lane_lengths(problems: Problem, U):
    """Samples each lane's simulation runs before every run sticks (its cost in a call)."""

    def one(p: Problem, u):
        _, _, stuck = p.simulate(u, full_output=True)
        return jax.numpy.max(jax.numpy.sum(~stuck, axis=1))

    return jax.vmap(one)(problems, U)


@eqx.filter_jit
def _lane_solve(problems: Problem, U, active, max_steps, *state):
    """:func:`hdid._fitting._lm._lm_lanes` over lanes, each with its own log and budget.

    ``state`` (the fields of :class:`hdid._fitting._lm.LMState`) carries each lane's residuals,
    Jacobian and damping from its previous call, so a call does not start by recomputing
    them. Returns ``(U, cost, done, iterations, *state)``.
    """
    u, cost, done, k, st = _lm_lanes(
        lambda V: lanes_vmap(lambda p, u: p.residuals(u))(problems, V),
        lambda V: lanes_vmap(lambda p, u: p.residuals_and_jacobian(u))(problems, V),
        U, active, max_steps, LMState(*state),
    )
    return (u, cost, done, k, *st)


@eqx.filter_jit
def _lane_analysis(problems: Problem, U):
    """The JAX parts of :func:`hdid._fitting._identifiability.analyse`, for each lane."""

    def one(p: Problem, u):
        r, J = p.data_residuals_and_jacobian(u)
        dense = p.simulate(u, full_output=True)
        return (J, r), dense, p.derived_and_jacobian(u)

    return jax.vmap(one)(problems, U)


# ----------------------------------------------------------------------------- buckets


def _pad_problem(problem: Problem, T: int) -> Problem:
    """``problem`` with every run padded to ``T`` samples: the last sample repeated, weight 0."""
    n = problem.times.shape[1]
    if n == T:
        return problem

    def pad(x):
        x = np.asarray(x)
        return np.concatenate([x, np.repeat(x[:, -1:], T - n, axis=1)], axis=1)

    return eqx.tree_at(
        lambda p: (p.times, p.theta, p.weight),
        problem,
        (pad(problem.times), pad(problem.theta),
         np.concatenate([np.asarray(problem.weight), np.zeros((problem.n_runs, T - n))], axis=1)),
    )


def _bucket_key(problem: Problem):
    leaves, treedef = jax.tree_util.tree_flatten(problem)
    return treedef, tuple((np.shape(x), np.asarray(x).dtype.str) for x in leaves)


class _Bucket:
    """Logs whose (padded) problems share structure and shapes, stacked on a leading axis."""

    def __init__(self, problems: Sequence[Problem], key):
        self.key = key
        leaves = [jax.tree_util.tree_flatten(p) for p in problems]
        self.treedef = leaves[0][1]
        self.stacked = [np.stack([np.asarray(lv[0][i]) for lv in leaves]) for i in
                        range(len(leaves[0][0]))]
        p = problems[0]
        #: residual rows per lane (data, then priors)
        self.n_residuals = int(np.prod(p.times.shape)) + p.n_physical

    def gather(self, index: np.ndarray) -> Problem:
        """The problems of logs ``index`` (one per lane), stacked."""
        return jax.tree_util.tree_unflatten(self.treedef, [x[index] for x in self.stacked])


# ----------------------------------------------------------------------------- state


@dataclass
class _LogFit:
    """One log's progress through the schedule of :func:`hdid.fit`."""

    setup: _Setup
    bucket: int
    row: int  # index within its bucket
    U: np.ndarray | None = None
    costs: np.ndarray | None = None
    ok: np.ndarray | None = None
    steps: np.ndarray | None = None
    sched: _Schedule | None = None
    #: per start, the fields of its LMState after its last call
    lm: dict = field(default_factory=dict)
