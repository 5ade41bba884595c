"""Viscous damping at the wave generator."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractEffect, Motion, ScalePrior, StartValues, parameter
from ._candidate import Candidate



#: The posterior's default prior of a viscous coefficient: log-normal around the log's
#: friction torque per its peak speed (the viscous torque at the peak speed equals the
#: ring-down's friction level), a factor 10.5 either way at 95 %. It replaces the
#: flat-in-value prior (issue 34, decision (a)); ``default_prior="flat"`` keeps that.
VISCOUS_PRIOR = ScalePrior(lambda s: s.torque / s.speed,
                           "torque per peak speed: the ring-down's friction torque over the "
                           "log's peak speed")

class ViscousFriction(AbstractEffect):
    r"""Linear viscous torque ``−c_v·ω`` (grease shear, back-EMF if phases are shorted).

    Residual mark when missing or wrong: decay envelope exponential rather than linear,
    error growing with speed.
    """

    c_v: Float[ArrayLike, ""] = parameter(
        "N m s/rad", "viscous friction coefficient at the wave generator",
        start=lambda s: 0.05 * s.c_crit, flat_in_value=True, sample_in_value=True)

    name: ClassVar[str] = "viscous"
    key: ClassVar[str] = "viscous"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {"c_v": VISCOUS_PRIOR}
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=100,
        mark="the decay envelope is exponential rather than linear and the error grows "
             "with speed",
        experiment="releases at several amplitudes separate viscous (∝ speed) from "
                   "Coulomb (constant) losses",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> ViscousFriction:
        """Starting values for ``--add viscous`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(c_v=values.get("c_v", 2e-5))

    def derived(self, inertia, k_wg):
        """``c_v`` per unit inertia, and the damping ratio ``ζ = c_v / (2·√(k_wg·I))`` of
        the small-swing oscillator (NaN without a restoring stiffness)."""
        ok = k_wg > 0
        safe = jnp.where(ok, k_wg, 1.0)
        return {"c_v/inertia": self.c_v / inertia,
                "damping_ratio": jnp.where(ok, self.c_v / (2 * jnp.sqrt(safe * inertia)), jnp.nan)}

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -self.c_v * motion.omega
