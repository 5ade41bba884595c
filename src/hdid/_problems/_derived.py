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


#: Right-hand-side evaluations the bracket's reference simulations may take, all runs
#: together: DOP853 takes 12 a step, and a run of a clean log takes 100–400 steps
#: (1–5 thousand evaluations; 6–15 thousand for a whole paper or rich log), so this is
#: 20× a whole log's need. A friction law that creeps (``tau_s < tau_c`` with a tiny
#: ``v_s``: a speed-stiffness ``∂τ/∂ω`` of ~40 N m s/rad against an inertia of 7e-7
#: kg m², a time constant of 2e-8 s) needs ~1e7 explicit steps a run instead (a clean rich
#: log's fit took > 10 min in it).
BRACKET_MAX_EVALUATIONS = 300_000


#: DOP853 tolerances of the bracket's reference simulations. The bracket's ends are logged
#: angles and reversal angles, printed to 1e-4 rad and compared with the band's standard
#: error; a relative error of 1e-8 in a reversal angle (≲ 2e-9 rad on a 0.16 rad swing)
#: is three orders below even a 20-bit encoder's step (6e-6 rad). Measured on the shipped paper, rich and hidden-
#: hysteresis fits: the ends move by ≤ 1.7e-9 relative from rtol 1e-11 (the reference's
#: default) and the simulations take half the time (45 → 24 ms CPU on the paper log).
BRACKET_RTOL, BRACKET_ATOL = 1e-8, 1e-12


class BracketTooCostly(Exception):
    """The bracket's reference simulations needed more than their evaluation budget."""


def band_bracket(model, runs, duration: float = 0.5,
                 max_evaluations: int = BRACKET_MAX_EVALUATIONS) -> tuple[float, float] | None:
    """What the data say about the stick-band half-width without any smoothness: at
    least the largest |rest point| logged, less than the smallest |angle| at which the
    gear reversed and slid on (located with the event-driven reference simulator at the
    fitted parameters). Base model only; ``None`` otherwise. Raises
    :class:`BracketTooCostly` when the simulations need more than ``max_evaluations``
    right-hand-side evaluations (a stiff friction law at the fitted parameters)."""
    if not _is_base(model) or not runs:
        return None
    from ..reference import reference_trajectory

    v = model.float_values()
    lower = max(abs(r.rest_logged) for r in runs)
    upper = math.inf
    spent = [0]

    def count(_theta, _omega):  # a zero extra torque that counts the evaluations
        spent[0] += 1
        if spent[0] > max_evaluations:
            raise BracketTooCostly(f"more than {max_evaluations} evaluations")
        return 0.0

    for r in runs:
        try:
            traj = reference_trajectory(
                duration, theta0=r.theta0, t_release=0.0, ratio=model.ratio,
                extra_torque=count, rtol=BRACKET_RTOL, atol=BRACKET_ATOL,
                **{k: v[k] for k in ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v", "inertia")},
            )
        except (ValueError, RuntimeError):
            return None
        # every instant at rest from which it slid on (the release included) lies outside
        slid = [abs(th) for (_, th, decision) in traj.events if decision.startswith("slide")]
        if slid:
            upper = min(upper, min(slid))
    return lower, upper
