"""The unknowns vector ``u`` of a :class:`~hdid._problems._problem.Problem` by parameter
name: set named physical values in it (one row or many), hold some with strong prior rows,
and take the data part of a cost. Shared by the limit checks (:mod:`._limits`) and the
restarts (:mod:`._cubic_restart`, :mod:`._fit`)."""

from __future__ import annotations

from typing import Callable

import numpy as np

from .._models._transforms import to_unconstrained

#: sd (transformed units) of the prior rows that hold a limit's parameters.
PIN_SD = 1e-4


def data_chi2(problem, u, cost: float) -> float:
    """The data χ² at ``u`` from its cost (data χ² plus the prior rows)."""
    P = problem.n_physical
    z = (np.asarray(u)[:P] - np.asarray(problem.prior_mean)) / np.asarray(problem.prior_sd)
    return float(cost) - float(np.sum(np.where(np.asarray(problem.prior_on), z, 0.0) ** 2))


def with_values(problem, model, u, values: dict) -> np.ndarray:
    """``u`` with the physical parameters named in ``values`` set to them."""
    specs = model.parameter_specs()
    v = np.array(u, dtype=float)
    for n, x in values.items():
        if n in problem.free:
            v[list(problem.free).index(n)] = float(to_unconstrained(specs[n], x))
    return v


def with_values_rows(problem, model, U, start: Callable[[dict], dict], pins: dict) -> np.ndarray:
    """:func:`with_values` for every row of ``U`` at once: row ``i`` with the values
    ``start(v_i)`` (``v_i`` its own values, fixed ones included) and then ``pins`` set —
    a limit's starts (NumPy on whole columns: one pass, not a model per row)."""
    U = np.array(U, dtype=float, ndmin=2)
    specs = model.parameter_specs()
    free = list(problem.free)
    values = {**{k: np.full(len(U), float(v)) for k, v in problem.base.values().items()},
              **problem.free_values_np(U)}
    for n, x in {**start(values), **pins}.items():
        if n in free:
            U[:, free.index(n)] = to_unconstrained(specs[n], np.broadcast_to(
                np.asarray(x, dtype=float), (len(U),)))
    return U


def pinned(problem, model, pins: dict):
    """``problem`` with strong prior rows (sd ``PIN_SD``) holding ``pins`` (values of free
    parameters): the same compiled programs (the rows are array leaves)."""
    import equinox as eqx
    import jax.numpy as jnp

    specs = model.parameter_specs()
    free = list(problem.free)
    mean = np.asarray(problem.prior_mean, dtype=float).copy()
    sd = np.asarray(problem.prior_sd, dtype=float).copy()
    on = np.asarray(problem.prior_on, dtype=bool).copy()
    for n, x in pins.items():
        i = free.index(n)
        mean[i], sd[i], on[i] = float(to_unconstrained(specs[n], x)), PIN_SD, True
    return eqx.tree_at(lambda p: (p.prior_mean, p.prior_sd, p.prior_on), problem,
                       (jnp.asarray(mean), jnp.asarray(sd), jnp.asarray(on)))
