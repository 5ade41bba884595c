"""Coulomb friction at the wave generator: the nested special case of Stribeck friction."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractFriction, Motion, StartValues, same_parameter
from .stribeck import FRICTION_TORQUE_PRIOR, StribeckFriction


class CoulombFriction(AbstractFriction):
    r"""Coulomb friction: a constant level ``tau_c`` [N m] opposing the sliding direction.

    Sliding: ``tau_f = s·tau_c`` (``s`` the sliding direction); at rest it holds any torque
    up to ``tau_c``. It is Stribeck friction with ``tau_s = tau_c`` (any ``v_s``,
    ``delta``), so it takes the Stribeck effect's slot (``--add coulomb`` replaces it) and
    its ``tau_c`` declaration. A linear spring ``k`` with Coulomb friction loses exactly
    ``2·tau_c/k`` of amplitude per half-swing at an unchanged period, and stops at the
    first turning point inside ``|θ| ≤ tau_c/k`` (the stick band). :func:`hdid.fit` fits
    it as the nested case of a free Stribeck law and warns when the general law ends
    worse; use it directly when a log cannot see the Stribeck shape.

    Residual mark when missing or wrong (fitted instead of Stribeck): rest points too
    close to zero for the decay seen (the breakaway level is above the sliding level),
    and a residual that peaks at the slow ends of each swing where the Stribeck rise acts.
    """

    tau_c: Float[ArrayLike, ""] = same_parameter(StribeckFriction, "tau_c")

    key: ClassVar[str] = "coulomb"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {"tau_c": FRICTION_TORQUE_PRIOR}

    @classmethod
    def start_from(cls, values: dict[str, float]) -> CoulombFriction:
        """Starting values for ``--add coulomb`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(tau_c=s.tau_c)

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -motion.direction * jnp.asarray(self.tau_c, dtype=float)

    def holding_torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del motion, state
        return jnp.asarray(self.tau_c, dtype=float)
