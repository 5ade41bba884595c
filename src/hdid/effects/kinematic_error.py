"""Kinematic (positional) error of the gear inside the locked-output spring."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractSpring, Motion, StartValues, parameter, same_parameter
from ._candidate import ORDERS, Candidate
from .stiffness import K1_PRIOR, K2_PRIOR, CubicStiffness


class KinematicErrorStiffness(AbstractSpring):
    r"""Cubic spring whose twist carries the gear's kinematic error (paper eq. 3).

    With the output locked the flexspline twist is ``d = θ/N + e(θ)``,
    ``e(θ) = ke_a·sin(n·θ) + ke_b·cos(n·θ)`` [rad, output side], ``n = order`` cycles per
    WG revolution (2 for the elliptical wave generator). The spring's energy gives the WG
    torque ``−T_k(d)·(1/N + e'(θ))``. Replaces the model's spring (:class:`AbstractSpring`).

    Residual mark when missing: a torque periodic in the WG angle that scales with the
    spring torque. Over a ±0.157 rad swing ``n·θ`` spans only ±0.3 rad for ``n = 2``, so
    ``ke_a`` looks like a change of ``k1`` and ``ke_b`` like a shift of the spring's zero:
    free motion barely sees it. Positional error is measured with the output encoder in a
    driven input/output test, not in free motion.
    """

    k1: Float[ArrayLike, ""] = same_parameter(CubicStiffness, "k1")
    k2: Float[ArrayLike, ""] = same_parameter(CubicStiffness, "k2")
    ke_a: Float[ArrayLike, ""] = parameter(
        "rad", "sine amplitude of the kinematic error, output side",
        transform="identity", scale=lambda s: 0.05 * s.twist)
    ke_b: Float[ArrayLike, ""] = parameter(
        "rad", "cosine amplitude of the kinematic error, output side",
        transform="identity", scale=lambda s: 0.05 * s.twist)
    order: Float[ArrayLike, ""] = 2.0

    key: ClassVar[str] = "kinematic_error"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {"k1": K1_PRIOR, "k2": K2_PRIOR}
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=70, replaces="stiffness", orders=ORDERS, settings=len(ORDERS),
        family="position-periodic",
        mark="a spring torque modulated periodically in the WG angle",
        experiment="a driven input/output test with the output encoder: free motion "
                   "barely sees the positional error",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> KinematicErrorStiffness:
        """Starting values for ``--add kinematic_error`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(k1=s.k1, k2=s.k2, ke_a=values.get("ke_a", 0.0), ke_b=values.get("ke_b", 0.0),
                   order=values.get("order", 2.0))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        phase = self.order * motion.theta
        e = self.ke_a * jnp.sin(phase) + self.ke_b * jnp.cos(phase)
        de = self.order * (self.ke_a * jnp.cos(phase) - self.ke_b * jnp.sin(phase))
        spring = CubicStiffness(k1=self.k1, k2=self.k2).spring_torque(motion.theta / motion.ratio + e)
        return -spring * (1.0 / motion.ratio + de)
