"""What is evaluated on a driven problem, compiled: the simulation, the residuals, the
prediction, and residuals with their Jacobian (the driven twin of :mod:`hdid._problems._evaluate`)."""

from __future__ import annotations

import equinox as eqx


@eqx.filter_jit
def _simulate(problem, u):
    return problem.simulate(u)


@eqx.filter_jit
def _residuals(problem, u):
    return problem.residuals(u)


@eqx.filter_jit
def _predict(problem, u):
    return problem.predict(u)


@eqx.filter_jit
def _res_jac(problem, u):
    return problem.residuals_and_jacobian(u)
