"""An optimum of the least-squares cost (:class:`Mode`), its Laplace mass and the merge
rule of the mode search (:mod:`.modes`, :mod:`.aliases`), and the views of the fit the
search runs on (the sampled priors' rows, another optimum)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import jax.numpy as jnp
import numpy as np

from .._problems._problem import Problem
from .density import PRIOR_HALF_WIDTH
from .lanes import _solve_in_lanes, solve_fresh

#: Two optima joined by a straight path whose cost rises less than this above the worse
#: of the two are one mode (a flat, curved valley on which the optimiser stopped twice).
MODE_BARRIER = 4.0
#: Variance of the flat ±PRIOR_HALF_WIDTH prior, added as a ridge to the Gauss–Newton
#: precision so that directions the data cannot see get the prior's width, not infinity.
_BOX_PRECISION = 12.0 / (2 * PRIOR_HALF_WIDTH) ** 2


@dataclass
class Mode:
    """One local optimum of the least-squares cost and its Laplace approximation."""

    u: np.ndarray            # unknowns (the fit's space)
    cost: float              # Σ r² (data and weak-prior rows) in q/√12 units
    cov: np.ndarray          # Laplace covariance of u (Gauss–Newton, prior ridge)
    log_evidence: float      # −cost/2 + ½ log det(2π cov): relative Laplace mass
    weight: float = 1.0      # normalised share of the posterior mass (Laplace)
    values: dict[str, float] = field(default_factory=dict)
    #: "optimum", or "limit:NAME": a limit fit (NAME held near zero, :mod:`.limits`)
    kind: str = "optimum"
    limit: Any = None        # its :class:`~hdid._posterior.limits.LimitFit`
    #: one warning line the sampler carries (:mod:`.inside`: the fit's optimum broke an order)
    note: str | None = None
    #: the alias search's :class:`~hdid._posterior.aliases.AliasSearch` (first optimum only)
    aliases: Any = None

    def to_dict(self) -> dict[str, Any]:
        return {"cost": self.cost, "weight": self.weight, "log_evidence": self.log_evidence,
                "values": dict(self.values), "kind": self.kind,
                **({"aliases": self.aliases.to_dict()} if self.aliases is not None else {})}


def _rj(problem: Problem, u):
    """Residuals and Jacobian (data rows, then weak-prior rows) at ``u``: the data part
    from the program the fit's analysis compiled (``_evaluate.jacobian``: no compile of
    its own), the prior rows in NumPy (``Problem.residuals_and_jacobian``'s)."""
    from .._problems._evaluate import jacobian

    J, r = map(np.asarray, jacobian(problem, jnp.asarray(u)))
    u = np.asarray(u, dtype=float)
    P = problem.n_physical
    on = np.asarray(problem.prior_on, dtype=bool)
    sd = np.asarray(problem.prior_sd, dtype=float)
    rp = np.where(on, (u[:P] - np.asarray(problem.prior_mean, dtype=float)) / sd, 0.0)
    Jp = np.zeros((P, J.shape[1]))
    Jp[:, :P] = np.diag(np.where(on, 1.0 / sd, 0.0))
    return np.concatenate([r, rp]), np.concatenate([J, Jp], axis=0)


def _path_costs(problem: Problem, U):
    """Cost of every row of ``U``: the LM program with no iteration (its cost at the
    start), in one call of all rows."""
    return _solve_in_lanes(solve_fresh, problem, U, np.ones(len(U), dtype=bool), 0)[1]


def _laplace(problem: Problem, u) -> tuple[float, np.ndarray, float]:
    r, J = _rj(problem, u)
    cost = float(np.sum(r**2))
    # cost = Σ r² ⇒ −log p = cost/2, Gauss–Newton Hessian JᵀJ.
    H = J.T @ J + _BOX_PRECISION * np.eye(J.shape[1])
    w, V = np.linalg.eigh(0.5 * (H + H.T))
    w = np.clip(w, _BOX_PRECISION, None)
    cov = (V / w) @ V.T
    logdet_cov = -float(np.sum(np.log(w)))
    return cost, cov, -0.5 * cost + 0.5 * logdet_cov + 0.5 * w.size * math.log(2 * math.pi)


class _PriorFit:
    """``fit`` seen through a problem whose weak-prior rows are the user's Gaussian prior
    (what :func:`find_modes` minimises is then the posterior's −log density)."""

    def __init__(self, fit, problem):
        self._fit, self.problem = fit, problem

    def __getattr__(self, name):
        return getattr(self._fit, name)


class _Moved(_PriorFit):
    """``fit`` (a :class:`_PriorFit` view or the fit) moved to the unknowns ``u``: the mode
    search restarts around another optimum (:mod:`.inside`)."""

    def __init__(self, fit, u):
        super().__init__(fit, fit.problem)
        self.u = np.asarray(u, dtype=float)
        self.values = fit.problem.values_np(self.u)


def _same_optimum(problem: Problem, m: Mode, u) -> bool:
    """Whether ``u`` is ``m``'s optimum (:func:`find_modes`' merge rule: a straight path
    that rises less than ``MODE_BARRIER`` above the worse end), for an optimum of ``m``'s
    kind only."""
    if m.kind != "optimum":
        return False
    path = m.u + np.linspace(0.0, 1.0, 9)[:, None] * (np.asarray(u) - m.u)
    pc = np.asarray(_path_costs(problem, path))
    return bool(np.all(np.isfinite(pc)) and np.max(pc) - max(pc[0], pc[-1]) < MODE_BARRIER)
