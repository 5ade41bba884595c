"""Direction-dependent (asymmetric) viscous friction at the wave generator."""

from __future__ import annotations

from typing import ClassVar

from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractEffect, Motion, StartValues, parameter
from .viscous import VISCOUS_PRIOR


class AsymmetricViscousFriction(AbstractEffect):
    r"""Viscous torque ``−c_vp·ω`` sliding in +θ and ``−c_vn·ω`` sliding in −θ, zero at rest.

    The coefficient follows the sliding ``direction`` ``s`` (held through an integration
    step, like every friction law here): ``τ = −(c̄ + s·Δ)·ω`` with ``c̄ = (c_vp + c_vn)/2``
    and ``Δ = (c_vp − c_vn)/2``. At rest ``ω = 0`` and it adds nothing, and it holds no
    torque. ``c_vp = c_vn`` is :class:`ViscousFriction`'s ``c_v``, which it replaces (its
    ``name`` is ``"viscous"``). Both in N m s/rad at the WG; log transforms; each starts at
    5 % of the log's critical damping ``2·sqrt(k·I)``.

    Residual mark when missing or wrong: the half-swings in + and − directions decay by
    different factors (with a linear spring ``k`` a swing in direction ``s`` ends at
    ``exp(−π·ζ_s/sqrt(1 − ζ_s²))`` of its starting amplitude, ``ζ_s = c_vs/(2·sqrt(k·I))``),
    so the peaks on the two sides of the zero shrink at different rates and a symmetric
    ``c_v`` leaves a residual odd in the velocity that is larger on one side.
    """

    c_vp: Float[ArrayLike, ""] = parameter(
        "N m s/rad", "viscous friction coefficient sliding in +θ (wave generator)",
        start=lambda s: 0.05 * s.c_crit)
    c_vn: Float[ArrayLike, ""] = parameter(
        "N m s/rad", "viscous friction coefficient sliding in −θ (wave generator)",
        start=lambda s: 0.05 * s.c_crit)

    name: ClassVar[str] = "viscous"
    key: ClassVar[str] = "asymmetric_viscous"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {"c_vp": VISCOUS_PRIOR, "c_vn": VISCOUS_PRIOR}

    @classmethod
    def start_from(cls, values: dict[str, float]) -> AsymmetricViscousFriction:
        """Starting values for ``--add asymmetric_viscous`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(c_vp=values.get("c_vp", values.get("c_v", 2e-5)),
                   c_vn=values.get("c_vn", values.get("c_v", 2e-5)))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        mean = 0.5 * (self.c_vp + self.c_vn)
        half = 0.5 * (self.c_vp - self.c_vn)
        return -(mean + motion.direction * half) * motion.omega
