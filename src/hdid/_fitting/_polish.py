"""A noisy log's fit in two metrics: the search (grid, local fits, limit checks) in weights
where a stuck tail counts as one observation, then its optimum polished in the
likelihood's own weights (:func:`hdid._simulation._prepare.search_weight` says why)."""

from __future__ import annotations

import dataclasses

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._simulation._prepare import search_weight
from ._starts import grid_costs


def searching(setup):
    """``setup`` (:class:`hdid._fitting._fit._Setup`) with the search's weights in its
    prepared log and problem, or ``setup`` itself where they are the likelihood's (an
    encoder log). Same structure, so the same compiled programs."""
    w = search_weight(setup.prep)
    if w is setup.prep.weight:
        return setup
    problem = eqx.tree_at(lambda p: p.weight, setup.problem, jnp.asarray(w, dtype=float))
    return setup._replace(prep=dataclasses.replace(setup.prep, weight=w), problem=problem)


def polished(result, problem, solutions, local_fits, finish, check):
    """The search's optimum ``result`` polished in the likelihood's ``problem``.

    ``solutions`` ``(U, costs, ok, steps)``: the search's local fits; ``local_fits(U0)``
    → ``(U, costs, ok, steps)`` in ``problem``; ``finish(U, costs, ok, steps)`` → the
    result of the best; ``check(result, solutions)`` → the result after its limit checks
    (:func:`hdid._fitting._fit.nested_check`: at the floor only the limits whose term may
    vanish). Levenberg–Marquardt from the search's optimum; the other starts' optima are
    costed where they stand, so the start summary is in one metric. ``restarted_from``
    keeps the search's where the polish restarted from nothing."""
    U, _, ok, steps = (np.array(a) for a in solutions)
    u = np.asarray(result.u, dtype=float)
    Up, cp, okp, sp = local_fits(u[None, :])
    costs = np.array(grid_costs(problem, U), dtype=float)  # (the grid's stored program)
    same = [i for i, row in enumerate(U) if np.array_equal(row, u)]
    if same:  # the search's best start: its polished optimum
        i = same[0]
        U[i], costs[i], ok[i], steps[i] = Up[0], cp[0], okp[0], steps[i] + sp[0]
    else:  # (a limit's restart won the search)
        U, costs = np.concatenate([U, Up]), np.concatenate([costs, cp])
        ok, steps = np.concatenate([ok, okp]), np.concatenate([steps, sp])
    out = check(finish(U, costs, ok, steps), (U, costs, ok, steps))
    if out.restarted_from is None:
        out.restarted_from = result.restarted_from
    return out
