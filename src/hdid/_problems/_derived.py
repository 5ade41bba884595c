"""Standard errors of the derived physical quantities (:meth:`hdid.Model.derived`: the
stick band, the natural frequency, what each effect declares) by the delta method, from
:meth:`Problem.derived_and_jacobian` compiled once per problem structure."""

from __future__ import annotations

import math

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .._covariance import _undetermined
from ._problem import Problem


def _derived(problem: Problem, u, cov, null, precomputed=None) -> dict:
    """Stick band, inertia-normalised torques, natural frequency, damping ratio (± std)."""
    if precomputed is None:
        precomputed = _derived_and_jacobian(problem, jnp.asarray(u))
    vals, jac = precomputed
    P = problem.n_physical
    out = {}
    for k, v in vals.items():
        g = np.zeros(problem.n_unknowns)
        g[:P] = np.asarray(jac[k]) if P else 0.0
        if _undetermined(g, null):
            std = math.inf
        else:
            std = float(math.sqrt(max(g @ cov @ g, 0.0)))
        out[k] = (float(v), std)
    return out


@eqx.filter_jit
def _derived_and_jacobian(problem: Problem, u):
    """:meth:`Problem.derived_and_jacobian`, compiled once per problem structure."""
    return problem.derived_and_jacobian(u)


def _is_base(model) -> bool:
    """The base model's effects, by class (a user effect may reuse a slot name)."""
    from ..effects import CubicStiffness, StribeckFriction, ViscousFriction

    classes = (CubicStiffness, StribeckFriction, ViscousFriction)
    return len(model.effects) == 3 and all(type(e) is c for e, c in zip(model.effects, classes))


def band_bracket(model, runs, duration: float = 0.5) -> tuple[float, float] | None:
    """What the data say about the stick-band half-width without any smoothness: at
    least the largest |rest point| logged, less than the smallest |angle| at which the
    gear reversed and slid on (located with the event-driven reference simulator at the
    fitted parameters). Base model only; ``None`` otherwise."""
    if not _is_base(model) or not runs:
        return None
    from ..reference import reference_trajectory

    v = model.float_values()
    lower = max(abs(r.rest_logged) for r in runs)
    upper = math.inf
    for r in runs:
        try:
            traj = reference_trajectory(
                duration, theta0=r.theta0, t_release=0.0, ratio=model.ratio,
                **{k: v[k] for k in ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v", "inertia")},
            )
        except (ValueError, RuntimeError):
            return None
        # every instant at rest from which it slid on (the release included) lies outside
        slid = [abs(th) for (_, th, decision) in traj.events if decision.startswith("slide")]
        if slid:
            upper = min(upper, min(slid))
    return lower, upper
