"""Refits for :func:`hdid.diagnose`: every start of one model structure as lanes of one
Levenberg–Marquardt program, results analysed only where they are needed.

A candidate refit (a model with an effect added) is set up once per model structure; its
starts are explicit unknown vectors (:func:`warm`: the current fit's optimum — release
instants, start angles, offsets included — with the effect's parameters at a
data-derived value) and the best points of :func:`hdid.fit`'s data-driven grid
(:func:`grid`). All of them run as lanes of one program with :func:`hdid.fit`'s own
schedule (every start a few iterations, the best to convergence), so models of the same
structure share one compiled program. The full analysis (covariance, residual frame) is
computed only for the fits whose residual :func:`hdid.diagnose` inspects
(:meth:`StructureFit.result`).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from . import _config  # noqa: F401
from . import _programs
from ._fit import (
    LMState,
    _choose_starts,
    _finish,
    _grid_candidates,
    _local_fits as _fit_local_fits,
    _lm_lanes,
    _Schedule,
    _setup,
    _Setup,
    _untrapped,
    lanes_vmap,
)
from ._identifiability import band_limit, derived_quantities
from ._problem import Problem
from ._transforms import to_unconstrained

#: Options of :func:`hdid.fit` that shape the problem (the rest belong to the schedule).
SETUP_OPTIONS = ("inertia", "fix", "free_inertia", "inertia_prior", "release_time",
                 "counts_per_rev", "max_substep", "ratio", "resolution")


def _residuals_and_jacobian(problem: Problem, u):
    return problem.residuals_and_jacobian(u)


def _costs(problem: Problem, U):
    return jax.vmap(problem.cost)(U)


def _solve_lanes(problem: Problem, U0, active, max_steps, state: LMState):
    """:func:`hdid._fit._solve_lanes` (the same program), run through the program store."""
    return _lm_lanes(
        lanes_vmap(problem.residuals), lanes_vmap(problem.residuals_and_jacobian), U0, active,
        max_steps, state,
    )


def _analysis_parts(p: Problem, u):
    """The JAX parts of :func:`hdid._identifiability.analyse` at ``u`` (as
    :func:`hdid._vfit._lane_analysis` computes them for one lane)."""
    r, J = p.data_residuals_and_jacobian(u)
    dense = p.simulate(u, full_output=True)
    P = p.n_physical

    def quantities(up):
        return derived_quantities(p.model(jnp.concatenate([up, u[P:]])), band_limit(p))

    return (J, r), dense, (quantities(u[:P]), jax.jacfwd(quantities)(u[:P]))


def _stored_solve(problem: Problem, U, active, k, state):
    return _programs.call("solve_lanes", _solve_lanes, problem, U, active, k, state)


def _local_fits(problem: Problem, U0, max_steps: int):
    """:func:`hdid._fit._local_fits` with its program from :mod:`hdid._programs` (no
    tracing in a process that finds it stored)."""
    return _fit_local_fits(problem, U0, max_steps, solve=_stored_solve)


def setup(log, model, options: dict[str, Any]) -> _Setup:
    """The least-squares problem of ``model`` on ``log`` (``fix`` limited to the model's
    parameters: a candidate may replace a fixed one)."""
    opts = {k: v for k, v in options.items() if k in SETUP_OPTIONS and v is not None}
    fix = opts.get("fix")
    specs = model.parameter_specs()
    if isinstance(fix, dict):
        opts["fix"] = {k: v for k, v in fix.items() if k in specs} or None
    elif fix is not None:
        opts["fix"] = [k for k in fix if k in specs] or None
    return _setup(log, model, **opts)


def warm(s: _Setup, values: dict[str, float], tail: np.ndarray) -> np.ndarray:
    """An unknown vector of ``s``: physical parameters from ``values`` (the set-up model's
    own where missing), the rest (release instants, start angles, offsets, initial
    velocities) copied from another fit of the same log (``tail``)."""
    problem = s.problem
    specs = s.model.parameter_specs()
    own = s.model.float_values()
    phys = [float(to_unconstrained(specs[n], values.get(n, own[n]))) for n in problem.free]
    out = np.concatenate([np.asarray(phys, dtype=float), np.asarray(tail, dtype=float)])
    if out.size != problem.n_unknowns:
        raise ValueError(f"warm start has {out.size} unknowns, the problem {problem.n_unknowns}")
    return out


def tail_of(result_problem: Problem, u) -> np.ndarray:
    """The non-physical unknowns of a fit (release, start angles, offsets, velocities)."""
    return np.asarray(u, dtype=float)[result_problem.n_physical:]


def grid(s: _Setup, n_starts: int) -> np.ndarray:
    """The ``n_starts`` best points of :func:`hdid.fit`'s data-driven grid (every free
    parameter from its effect's ``Parameter.start`` rule at the log's own scales)."""
    if n_starts <= 0:
        return np.zeros((0, s.problem.n_unknowns))
    U, keys = _grid_candidates(s.problem, s.prep, s.model, False)
    cost = np.asarray(_programs.call("grid_costs", _costs, s.problem, jnp.asarray(U)))
    U0, _ = _choose_starts(U, cost, keys, n_starts, False)
    return np.asarray(U0)


@dataclass
class StructureFit:
    """The multi-start refit of one model on one log."""

    label: str
    setup: _Setup
    U: np.ndarray
    costs: np.ndarray
    ok: np.ndarray
    steps: np.ndarray
    #: which start each row came from ("warm", "grid", "reverse", …)
    origins: list[str]
    wall_s: float = 0.0
    _result: Any = field(default=None, repr=False)

    @property
    def best(self) -> int:
        c = np.where(np.isfinite(self.costs), self.costs, np.inf)
        return int(np.argmin(c))

    @property
    def cost(self) -> float:
        return float(self.costs[self.best])

    @property
    def u(self) -> np.ndarray:
        return self.U[self.best]

    @property
    def finite(self) -> bool:
        return bool(np.isfinite(self.cost))

    @property
    def n_unknowns(self) -> int:
        return int(self.setup.problem.n_unknowns)

    @property
    def n_effective(self) -> float:
        return float(self.setup.prep.n_effective)

    @property
    def model(self):
        return self.setup.model

    def values(self) -> dict[str, float]:
        """Every parameter of the model at the best start (fixed ones included)."""
        vals, *_ = self.setup.problem.unpack_np(self.u)
        return {**self.setup.model.float_values(), **{k: float(v) for k, v in vals.items()}}

    def rms_rad(self) -> float:
        """RMS of the weighted data residual [rad], as :attr:`FitResult.rms_residual_rad`
        defines it (``σ_q·√(χ²_data/n_eff)``)."""
        if not self.finite:
            return math.nan
        p = self.setup.problem
        # the cost less its prior terms (NumPy: no program to compile for this)
        P = p.n_physical
        z = (self.u[:P] - np.asarray(p.prior_mean)) / np.asarray(p.prior_sd)
        prior = float(np.sum(np.where(np.asarray(p.prior_on), z, 0.0) ** 2))
        chi2 = max(self.cost - prior, 0.0)
        sigma = float(p.sigma)
        return sigma * math.sqrt(chi2 / self.n_effective)

    def result(self):
        """The analysed :class:`~hdid.FitResult` of the best start (computed once)."""
        if self._result is None:
            parts = _programs.call("analysis", _analysis_parts, self.setup.problem,
                                   jnp.asarray(self.u))
            (J, r), dense, derived = jax.tree_util.tree_map(np.asarray, parts)
            pre = {"jacobian": (J, r), "dense": dense, "derived": derived}
            self._result = _finish(self.setup, self.U, self.costs, self.ok, self.steps,
                                   time.perf_counter(), bracket=False, precomputed=pre)
        return self._result


def run(label: str, s: _Setup, starts: list[tuple[str, np.ndarray]],
        max_steps: int = 300, width: int | None = None) -> StructureFit:
    """Levenberg–Marquardt from every start (lanes of one program, :func:`hdid.fit`'s
    schedule), with :func:`hdid.fit`'s restart of runs the optimum holds stuck.

    ``width``: pad the lanes to a multiple of it (copies of the first start), so that
    later runs of the same structure with another number of starts reuse its program.
    """
    t0 = time.perf_counter()
    starts = list(starts)
    if width and len(starts) % width:
        starts += [("pad", starts[0][1])] * (width - len(starts) % width)
    origins = [o for o, _ in starts]
    U0 = np.stack([np.asarray(u, dtype=float) for _, u in starts])
    U, costs, ok, steps = _local_fits(s.problem, U0, max_steps)
    c = np.where(np.isfinite(costs), costs, np.inf)
    if np.isfinite(c).any():
        retry = _untrapped(s.problem, s.prep, U[int(np.argmin(c))])
        if retry is not None:
            # as many lanes as the first call (copies): its compiled program is reused
            U1, c1, ok1, s1 = _local_fits(s.problem, np.repeat(retry[None, :], len(U0), 0),
                                          max_steps)
            U, costs = np.concatenate([U, U1]), np.concatenate([costs, c1])
            ok, steps = np.concatenate([ok, ok1]), np.concatenate([steps, s1])
            origins += ["untrapped"] * len(U1)
    return StructureFit(label, s, np.asarray(U), np.asarray(costs, dtype=float),
                        np.asarray(ok), np.asarray(steps), origins,
                        time.perf_counter() - t0)


def gauss_newton_step(s: _Setup, u: np.ndarray, added: list[str]) -> tuple[float, np.ndarray]:
    """Score screen of the parameters ``added`` at ``u``: the χ² decrease one Gauss–Newton
    step predicts with every unknown free, less the decrease it predicts with ``added``
    held (``rᵀJ(JᵀJ)⁺Jᵀr`` for the full and the reduced Jacobian), and the full step. At
    an optimum of the nested model with the effect at zero this is Rao's score statistic
    for the effect (1948): a one-step screen of many discrete settings (ripple orders)
    before full refits, which sees the collinearity of a low order with stiffness and
    offset (their columns are in both Jacobians)."""
    r, J = map(np.asarray, _programs.call("residuals_and_jacobian", _residuals_and_jacobian,
                                          s.problem, jnp.asarray(u)))
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        return 0.0, np.zeros_like(np.asarray(u))

    def gain(M):
        step, *_ = np.linalg.lstsq(M, -r, rcond=1e-10)
        return float(-(M.T @ r) @ step), step

    full, step = gain(J)
    keep = [i for i in range(J.shape[1])
            if i >= s.problem.n_physical or s.problem.free[i] not in added]
    reduced, _ = gain(J[:, keep])
    return max(full - reduced, 0.0), step
