"""What every layer above asks of a :class:`~hdid._problems._problem.Problem` at a point ``u``,
compiled once per problem structure: the dense trajectory, the data Jacobian, and the
predicted readings with their Jacobian.

The fit, the analysis at the optimum and the results' ``predict`` call these — one
compiled program each — instead of keeping their own copies (which is how the results
layer came to import the analysis layer: issue 20).
"""

from __future__ import annotations

import equinox as eqx
import jax

from ._problem import Problem


@eqx.filter_jit
def dense(problem: Problem, u, times):
    """``(theta, omega, stuck)`` per run at ``times`` ``(R, T)``, offsets not added."""
    return problem.simulate(u, times, full_output=True)


@eqx.filter_jit
def jacobian(problem: Problem, u):
    """``(J, r)``: the data residuals' Jacobian in ``u`` and the residuals."""
    r, J = problem.data_residuals_and_jacobian(u)
    return J, r


@eqx.filter_jit
def prediction_and_jacobian(problem: Problem, u, times):
    """Predicted encoder readings ``(R, T)`` and their Jacobian ``(R, T, n)`` in the
    unknowns (one forward-mode pass)."""

    def f(v):
        p = problem.predict(v, times)
        return p, p

    J, p = jax.jacfwd(f, has_aux=True)(u)
    return p, J


@eqx.filter_jit
def predict_rows(problem: Problem, X, times):
    """Predicted readings ``(N, R, T)`` for every row of ``X`` ``(N, n + 1)``: the
    unknowns, then one trailing column (the posterior's ``log σ_n``, ignored here)."""
    return jax.vmap(lambda x: problem.predict(x[:-1], times))(X)
