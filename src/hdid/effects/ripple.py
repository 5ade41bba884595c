"""Position-periodic torque: mesh ripple or motor cogging."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractEffect, Motion, StartValues, parameter
from ._candidate import ORDERS, PERIODOGRAM_ORDERS, Candidate


class PositionRipple(AbstractEffect):
    r"""A torque periodic in the WG angle, ``τ = ripple_a·sin(n·θ) + ripple_b·cos(n·θ)``.

    ``order`` ``n`` is in cycles per wave-generator revolution (2 for the elliptical
    wave generator's mesh, the pole/slot count for motor cogging). It is not a fitted
    parameter (the fit would be multimodal): scan it, as ``hdid diagnose`` does, or set
    it. The sine/cosine pair makes amplitude and phase linear parameters;
    ``amplitude = hypot(a, b)``, ``phase = atan2(b, a)``. Angles are measured from the
    spring's zero, so the phase is relative to it.

    Residual mark when missing: a residual periodic in the WG angle (not in time), with
    the same phase in every run; the rest points scatter by ``≈ amplitude/(k1/N²)``. A
    swing of ±0.157 rad spans only ``0.05·n`` periods, so orders below ~20 look like a
    change of stiffness or of the spring's zero and cannot be told apart from them.
    """

    ripple_a: Float[ArrayLike, ""] = parameter(
        "N m", "sine amplitude of the position-periodic torque (WG)",
        transform="identity", scale=lambda s: 0.03 * s.torque)
    ripple_b: Float[ArrayLike, ""] = parameter(
        "N m", "cosine amplitude of the position-periodic torque (WG)",
        transform="identity", scale=lambda s: 0.03 * s.torque)
    order: Float[ArrayLike, ""] = 24.0

    name: ClassVar[str] = "ripple"
    key: ClassVar[str] = "ripple"
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=50, orders=ORDERS, periodogram=True, settings=PERIODOGRAM_ORDERS,
        family="position-periodic",
        mark="the residual is periodic in the wave-generator angle, not in time, with the "
             "same phase in every run",
        experiment="releases starting from different WG angles (shift the spring zero by "
                   "a fraction of the ripple period) separate a position-periodic torque "
                   "from stiffness",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> PositionRipple:
        """Starting values for ``--add ripple`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(ripple_a=values.get("ripple_a", 0.0), ripple_b=values.get("ripple_b", 0.0),
                   order=values.get("order", 24.0))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        phase = self.order * motion.theta
        return self.ripple_a * jnp.sin(phase) + self.ripple_b * jnp.cos(phase)
