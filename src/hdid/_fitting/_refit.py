"""Refits for :func:`hdid.diagnose`: every start of one model structure through one
Levenberg–Marquardt program, results analysed only where they are needed.

A candidate refit (a model with an effect added) is set up once per model structure; its
starts are explicit unknown vectors (:func:`warm`: the current fit's optimum — release
instants, start angles, offsets included — with the effect's parameters at a
data-derived value) and the best points of :func:`hdid.fit`'s data-driven grid
(:func:`grid`). All of them run with :func:`hdid.fit`'s own schedule (every start a few
iterations, the best to convergence), one start per call of a one-lane program
(:data:`LANES`), so models of the same structure share one compiled program whatever
their number of starts, and :mod:`hdid._problems._programs` keeps it for later processes. The
full analysis (covariance, residual frame) is computed only for the fits whose residual
:func:`hdid.diagnose` inspects (:meth:`StructureFit.result`), in one program that also
simulates what the residual frame needs."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import jax
import jax.numpy as jnp
import numpy as np

from .. import _config  # noqa: F401
from .._problems import _programs
from .._results import _residuals
from ._fit import _finish, _setup, _Setup
from ._identifiability import MOVED_COUNTS
from ._lm import PHASE1_STEPS, LMState
from ._one_lane import (  # noqa: F401  (also diagnose's names)
    LANES, _call_args, _local_fits, _solve_lanes, _stored_solve,
)
from .._problems._problem import Problem
from ._starts import _grid_candidates, grid_costs, with_drop_starts
from .._models._transforms import interval_to_u, to_unconstrained

#: Options of :func:`hdid.fit` that shape the problem (the rest belong to the schedule).
SETUP_OPTIONS = ("inertia", "fix", "free_inertia", "inertia_prior", "release_time",
                 "counts_per_rev", "max_substep", "ratio", "resolution")


def residuals_and_jacobian(problem: Problem, u) -> tuple[np.ndarray, np.ndarray]:
    """Residuals and Jacobian at ``u`` from the structure's Levenberg–Marquardt program
    (no program of their own: a fresh lane evaluates both at its start, and with an
    iteration budget of one — the start counts as one — it stops there)."""
    n = int(problem.n_unknowns)
    m = int(np.prod(problem.times.shape)) + problem.n_physical
    U = np.asarray(u, dtype=float)[None, :]
    *_, state = _stored_solve(problem, jnp.asarray(U), jnp.asarray(np.ones(1, dtype=bool)),
                              jnp.asarray(1), LMState.empty(1, m, n))
    return np.asarray(state[0])[0], np.asarray(state[1])[0]


def _analysis_parts(p: Problem, u, fine):
    """The JAX parts of :func:`hdid._fitting._identifiability.analyse` at ``u`` (its
    ``precomputed`` parts), and the simulation on
    :func:`hdid._results._residuals.stick_times`'s grid ``fine`` (one program for both)."""
    r, J = p.data_residuals_and_jacobian(u)
    dense = p.simulate(u, full_output=True)
    return ((J, r), dense, p.derived_and_jacobian(u), p.simulate(u, fine, full_output=True))


def prefetch(s: _Setup) -> bool:
    """Start reading the Levenberg–Marquardt program of ``s`` (:func:`run`'s one program
    per model structure) from the store in a background thread
    (:func:`hdid._problems._programs.prefetch`); ``True`` if a read was started."""
    p = s.problem
    n = p.n_unknowns
    m = int(np.prod(p.times.shape)) + p.n_physical
    state = LMState(*(np.asarray(f) for f in LMState.empty(LANES, m, n)))
    return _programs.prefetch("solve_lanes", _solve_lanes, p,
                              *_call_args(np.zeros((LANES, n)), np.ones(LANES, dtype=bool),
                                          PHASE1_STEPS, state))


def trapped_runs(problem: Problem, prep, r) -> np.ndarray:
    """:func:`hdid._fitting._fit.trapped_runs` from the residuals ``r`` at the optimum (the LM's
    last ones: no simulation, no program): runs whose model reading is the same at every
    weighted sample (the model never releases them) although the log shows them moving
    (rest ≠ hold by more than ``MOVED_COUNTS``). The model reading is
    ``θ + r·σ/w``; "the same" is within 10⁻⁶ of an encoder step (its rounding error is
    ~10⁻¹⁷ rad, a run that moves spans many steps)."""
    R, T = problem.times.shape
    w = np.asarray(problem.weight)
    seen = w > 0
    model = np.asarray(problem.theta) + np.divide(
        np.asarray(r)[: R * T].reshape(R, T) * float(problem.sigma), w,
        out=np.zeros((R, T)), where=seen)
    hi = np.max(np.where(seen, model, -np.inf), axis=1)
    lo = np.min(np.where(seen, model, np.inf), axis=1)
    still = (hi - lo) <= 1e-6 * float(prep.resolution)
    moved = np.abs(prep.rest - prep.hold) > MOVED_COUNTS * prep.resolution
    return np.flatnonzero(moved & still)


def _untrapped(problem: Problem, prep, u, r):
    """:func:`hdid._fitting._fit._untrapped` from the residuals ``r`` at ``u``: a restart for an
    optimum that holds runs the log shows moving (their start angles back at their hold
    readings, their release instants at the data's guess), or ``None``."""
    trapped = trapped_runs(problem, prep, r)
    if trapped.size == 0:
        return None
    v = np.array(u, dtype=float)
    i = problem.n_physical
    if problem.release_free:
        lo, hi = np.asarray(problem.release_lo), np.asarray(problem.release_hi)
        v[i + trapped] = np.asarray(interval_to_u(prep.release_guess, lo, hi))[trapped]
        i += problem.n_runs
    v[i + trapped] = 0.0
    return v


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
    cost = grid_costs(s.problem, U)
    U0, _ = with_drop_starts(s.problem, s.prep, s.model, U, cost, keys, n_starts, False)
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
            p, prep = self.setup.problem, self.setup.prep
            _, release, *_ = p.unpack_np(self.u)
            fine = _residuals.fine_times(p.times, release, prep.lengths, prep.sample_period)
            parts = _programs.call("analysis", _analysis_parts, p, jnp.asarray(self.u),
                                   jnp.asarray(fine))
            (J, r), dense, derived, dense_fine = jax.tree_util.tree_map(np.asarray, parts)
            pre = {"jacobian": (J, r), "dense": dense, "derived": derived}
            self._result = _finish(self.setup, self.U, self.costs, self.ok, self.steps,
                                   time.perf_counter(), bracket=False, precomputed=pre)
            # the residual frame and the whiteness test reuse them (no programs of theirs)
            setattr(self._result, _residuals.PARTS,
                    {"u": np.array(self.u), "jacobian": (J, r), "dense": dense,
                     "dense_fine": (fine, dense_fine)})
        return self._result


def run(label: str, s: _Setup, starts: list[tuple[str, np.ndarray]],
        max_steps: int = 300) -> StructureFit:
    """Levenberg–Marquardt from every start (:func:`hdid.fit`'s schedule, calls of one
    program per model structure: :func:`_local_fits`), with :func:`hdid.fit`'s restart
    of runs the optimum holds stuck."""
    t0 = time.perf_counter()
    starts = list(starts)
    origins = [o for o, _ in starts]
    U0 = np.stack([np.asarray(u, dtype=float) for _, u in starts])
    U, costs, ok, steps, R = _local_fits(s.problem, U0, max_steps)
    c = np.where(np.isfinite(costs), costs, np.inf)
    if np.isfinite(c).any():
        b = int(np.argmin(c))
        retry = _untrapped(s.problem, s.prep, U[b], R[b])
        if retry is not None:
            U1, c1, ok1, s1, _ = _local_fits(s.problem, retry[None, :], max_steps)
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
    r, J = residuals_and_jacobian(s.problem, u)
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
