"""The problem abstraction: what the fit, the covariance and the posterior need of one.

A problem maps the unknowns ``u`` (transformed physical parameters first, then nuisance
unknowns such as release instants, start angles, offsets) to residuals in units of their
noise σ — data rows, then weak-prior rows — and gives their Jacobian. The one
Levenberg–Marquardt engine (:func:`hdid._fitting._lm.solve_fresh`, :func:`hdid._fitting._lm._lm_lanes`)
runs on any of them. Its instances: free motion (:class:`hdid._problems._problem.Problem`), a
driven log (:class:`hdid._problems._driven_problem.DrivenProblem`) and several logs sharing
physical parameters (:class:`hdid._problems._driven_problem.JointProblem`).
"""

# (no ``from __future__ import annotations``: equinox must see ``AbstractVar`` as an object,
# not a string, to leave ``n_unknowns`` to each problem as a field or a property)
import abc

import equinox as eqx
import jax.numpy as jnp


class AbstractProblem(eqx.Module):
    """Residuals ``r(u)`` in units of their noise σ, and their Jacobian."""

    #: Length of ``u``.
    n_unknowns: eqx.AbstractVar[int]

    @abc.abstractmethod
    def residuals(self, u):
        """Every residual row at ``u``: data, then weak priors."""

    @abc.abstractmethod
    def residuals_and_jacobian(self, u):
        """``(r, ∂r/∂u)`` at ``u`` (each problem computes its Jacobian its own way: forward
        mode per run, structured blocks, or stacked parts)."""

    def cost(self, u):
        """χ² = Σ r², the quantity the fit minimises."""
        return jnp.sum(self.residuals(u) ** 2)
