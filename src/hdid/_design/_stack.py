"""Many candidate experiments as one batch of runs of the exact simulator.

Runs do not interact: a design's Fisher information is the sum of its runs' blocks. So
every run of every candidate (grouped by sample rate, one program per group) is one row
of a single :class:`~hdid._problems._problem.Problem`, each run its own set-up, with
weight 1, readings 0 and encoder step 1: one forward-mode pass gives every run's
noise-free trajectory (as the residual, ``√12·θ``) and its Jacobian in the run's local
unknowns — the physical parameters (the fit's free ones, and the inertia), the release
instant, the start angle and the set-up's offset (:meth:`Problem._runs_residuals`). The
candidate's weights and noise are applied afterwards in NumPy. Shapes are padded to
buckets (runs to a multiple of 16, samples to a power of two) so that hdid's program store
(:mod:`hdid._problems._programs`) serves later calls and processes without tracing.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from .. import _config  # noqa: F401
from .._problems import _programs
from .._problems._problem import Problem
from .._models._transforms import to_unconstrained
from ._candidates import Experiment

#: Runs of one program are padded to a multiple of this (pads rest at the spring zero).
RUN_BUCKET = 16
#: Pad runs per release-time half width [samples] of the release bracket (the unknown is
#: the logistic position inside it; u = 0 is the bracket's middle, the true release).
RELEASE_HALF_WIDTH = 0.5


@dataclass
class Stacked:
    """The runs of a group of candidates: where each candidate's runs are."""

    problem: Problem
    local: np.ndarray                  # (R_pad, P+3) local unknowns at the current fit
    index: dict[int, np.ndarray]       # candidate position -> its rows
    release: np.ndarray                # (R_pad,) release instants [s]
    lengths: np.ndarray                # (R_pad,) samples of each run
    theta: np.ndarray | None = None    # (R_pad, T) trajectories at ``local`` (evaluate)
    J: np.ndarray | None = None        # (R_pad, T, P+3) their Jacobian


def physical(fit, names: tuple[str, ...]) -> np.ndarray:
    """The fit's values of ``names`` in the optimiser's (transformed) space."""
    specs = fit.model.parameter_specs()
    values = fit.model.float_values()
    return np.array([float(to_unconstrained(specs[n], values[n])) for n in names])


def stack(cands: list[tuple[int, Experiment]], fit, names: tuple[str, ...],
          max_substep: float) -> Stacked:
    """One problem holding every run of ``cands`` (all at one sample rate)."""
    R = sum(e.n_runs for _, e in cands)
    R_pad = RUN_BUCKET * math.ceil(R / RUN_BUCKET)
    n_max = max(e.n_samples for _, e in cands)
    T = 1 << max(int(n_max - 1).bit_length(), 4)
    times = np.zeros((R_pad, T))
    theta0 = np.zeros(R_pad)
    added = np.zeros(R_pad)
    lo = np.zeros(R_pad)
    hi = np.zeros(R_pad)
    release = np.zeros(R_pad)
    lengths = np.full(R_pad, T)
    index = {}
    row = 0
    for pos, e in cands:
        n = e.n_samples
        t = np.arange(n) / e.rate
        rows = np.arange(row, row + e.n_runs)
        index[pos] = rows
        for k, r in enumerate(rows):
            times[r, :n], times[r, n:] = t, t[-1]
            theta0[r] = e.amplitudes[k]
            added[r] = e.added_inertia[k]
            release[r] = e.releases[k]
            lo[r] = release[r] - RELEASE_HALF_WIDTH / e.rate
            hi[r] = release[r] + RELEASE_HALF_WIDTH / e.rate
            lengths[r] = n
        row += e.n_runs
    if row < R_pad:  # pads: released at the first sample from the spring zero (at rest)
        times[row:] = np.arange(T) / cands[0][1].rate
        lo[row:] = hi[row:] = release[row:] = 0.0
    problem = _problem(fit, names, times, theta0, added, lo, hi, max_substep)
    up = physical(fit, names)
    local = np.concatenate([np.broadcast_to(up, (R_pad, len(names))), np.zeros((R_pad, 3))],
                           axis=1)
    return Stacked(problem, local, index, release, lengths)


def _problem(fit, names, times, theta0, added, lo, hi, max_substep) -> Problem:
    R, T = times.shape
    base = jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=float), fit.model)
    P = len(names)
    return Problem(
        base=base, times=jnp.asarray(times), theta=jnp.zeros((R, T)), weight=jnp.ones((R, T)),
        setup_index=jnp.arange(R), added_inertia=jnp.asarray(added), hold=jnp.asarray(theta0),
        release_lo=jnp.asarray(lo), release_hi=jnp.asarray(hi), offset0=jnp.zeros(R),
        step=jnp.asarray(1.0), prior_mean=jnp.zeros(P), prior_sd=jnp.ones(P),
        prior_on=jnp.zeros(P, dtype=bool), free=tuple(names), release_free=True,
        max_substep=float(max_substep), offset_scale=jnp.asarray(1.0),
        moving_index=jnp.zeros(0, dtype=int), vel_scale=jnp.asarray(1.0),
        omega_guess=jnp.zeros(R), theta0_scale=None, n_moving=0,
    )


def _trajectory_and_jacobian(problem: Problem, local):
    """``(θ, ∂θ/∂local)``: ``(R, T)`` and ``(R, T, P+3)`` (θ in the encoder frame at a zero
    offset, i.e. the spring's frame)."""
    L = local.shape[1]
    R = local.shape[0]
    basis = jnp.broadcast_to(jnp.eye(L)[:, None, :], (L, R, L))
    r, tangents = jax.vmap(
        lambda t: jax.jvp(problem._runs_residuals, (local,), (t,)), out_axes=(None, 0)
    )(basis)
    scale = 1.0 / jnp.sqrt(12.0)  # residual = weight·(θ − 0)/σ with σ = 1/√12
    return r * scale, jnp.moveaxis(tangents, 0, -1) * scale


def _trajectory(problem: Problem, local):
    """θ ``(R, T)`` for per-run unknowns ``local`` (one simulation, no tangents)."""
    return problem._runs_predict(local)


def evaluate(st: Stacked) -> tuple[np.ndarray, np.ndarray]:
    """Noise-free trajectories and their Jacobians of every run of ``st`` (kept in it)."""
    if st.theta is None:
        theta, J = _programs.call("design_jacobian", _trajectory_and_jacobian, st.problem,
                                  jnp.asarray(st.local))
        st.theta, st.J = np.asarray(theta), np.asarray(J)
    return st.theta, st.J


def trajectories(st: Stacked, locals_: np.ndarray) -> np.ndarray:
    """Trajectories ``(K, R, T)`` of ``st``'s runs at ``K`` sets of local unknowns
    ``(K, R, P+3)`` (the runs tiled ``K`` times into one simulation loop)."""
    K = locals_.shape[0]
    p = st.problem

    def tile(a):
        return jnp.tile(a, (K,) + (1,) * (a.ndim - 1))

    runs = lambda q: (q.times, q.theta, q.weight, q.setup_index, q.added_inertia,  # noqa: E731
                      q.hold, q.release_lo, q.release_hi, q.offset0, q.omega_guess)
    tiled = eqx.tree_at(runs, p, tuple(tile(a) for a in runs(p)))
    R = p.n_runs
    out = _programs.call("design_trajectories", _trajectory, tiled,
                         jnp.asarray(locals_.reshape(K * R, -1)))
    return np.asarray(out).reshape(K, R, -1)
