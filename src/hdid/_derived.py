"""Derived physical quantities of a model: the stick band (and the data's own bracket of
it), the natural frequency, and what each effect declares (:meth:`AbstractEffect.derived`:
torques per unit inertia, a damping ratio), with their standard errors by the delta method."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ._covariance import _undetermined
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


def band_limit(problem: Problem):
    """How far [log units] to search for the stick band's edges: twice the largest
    excursion from the spring zero in the log (the band cannot extend past where the log
    shows the gear sliding; a fixed 1 rad would not fit a log in mrad or in degrees)."""
    off = problem.offset0[problem.setup_index][:, None]
    return 2.0 * jnp.max(jnp.abs(problem.theta - off))


def derived_quantities(model, theta_max=1.0) -> dict:
    """Derived physical quantities of a model (JAX scalars): the stick band, searched
    within ``±theta_max`` (:func:`band_limit` of the log), the small-swing natural
    frequency, and what each effect declares (:meth:`AbstractEffect.derived`: the library's
    torques per unit inertia and damping ratio; a plugin effect's own)."""
    N = model.ratio
    v = model.values()
    I = v["inertia"]
    lo, hi = model.stick_band(theta_max)
    out = {"stick_band_halfwidth_rad": 0.5 * (hi - lo), "stick_band_lower_rad": lo,
           "stick_band_upper_rad": hi}
    if "k1" in v:
        k_wg = v["k1"] / N**2
    else:  # any other restoring law (a gravity pendulum, segments): its slope at the zero
        k_wg = -jax.grad(lambda th: model.rest_torque(th))(jnp.zeros(()))
    for effect in model.effects:
        for name, value in effect.derived(I, k_wg).items():
            if name in out:
                raise ValueError(f"{type(effect).__name__}.derived(): {name!r} is already "
                                 "derived by another effect; give it a name of its own")
            out[name] = value
    ok = k_wg > 0
    safe = jnp.where(ok, k_wg, 1.0)
    out["natural_frequency_hz"] = jnp.where(ok, jnp.sqrt(safe / I) / (2 * jnp.pi), jnp.nan)
    return out


@eqx.filter_jit
def _derived_and_jacobian(problem: Problem, u):
    P = problem.n_physical

    def quantities(up):
        return derived_quantities(problem.model(jnp.concatenate([up, u[P:]])),
                                  band_limit(problem))

    return quantities(u[:P]), jax.jacfwd(quantities)(u[:P])


def _is_base(model) -> bool:
    """The base model's effects, by class (a user effect may reuse a slot name)."""
    from .effects import CubicStiffness, StribeckFriction, ViscousFriction

    classes = (CubicStiffness, StribeckFriction, ViscousFriction)
    return len(model.effects) == 3 and all(type(e) is c for e, c in zip(model.effects, classes))


def band_bracket(model, runs, duration: float = 0.5) -> tuple[float, float] | None:
    """What the data say about the stick-band half-width without any smoothness: at
    least the largest |rest point| logged, less than the smallest |angle| at which the
    gear reversed and slid on (located with the event-driven reference simulator at the
    fitted parameters). Base model only; ``None`` otherwise."""
    if not _is_base(model) or not runs:
        return None
    from .reference import reference_trajectory

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
