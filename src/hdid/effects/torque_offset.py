"""A constant torque on the wave generator: drive offset, gravity bias."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractEffect, Motion, StartValues, parameter


class TorqueOffset(AbstractEffect):
    r"""Constant torque ``tau_0`` [N m] that the drive must supply to hold the WG still.

    Adds ``−tau_0`` to the WG's torque balance, ``I θ̈ = τ_d − tau_0 − τ_f(θ̇) − …``,
    whatever the angle, velocity or direction: a current-sensor or amplifier offset,
    a gravity bias on a vertical or tilted axis, a constant spring preload. Its sign is
    that of the offset term of inverse-dynamics models (``τ_d = I θ̈ + … + tau_0``, e.g.
    the EMPS benchmark's IDIM-LS ``OF``). It is not friction: at rest it adds to the
    torque that friction must hold, so it shifts the breakaway torques to
    ``tau_0 ± tau_s``. In the log's units: on a linear axis a force [N]. Identity
    transform (either sign), optimiser scale and start from the log's torque scale.

    Residual mark when missing or wrong: Coulomb friction that looks asymmetric
    (breakaway and sliding levels differ by ``2·tau_0`` between the two directions), a
    drift of the simulated position in one direction while the drive holds still, and a
    constant residual torque in an equation-error fit.
    """

    tau_0: Float[ArrayLike, ""] = parameter(
        "N m", "constant torque the drive supplies at rest (offset, gravity bias), WG side",
        transform="identity", scale=lambda s: s.torque, start=lambda s: 0.0)

    name: ClassVar[str] = "torque_offset"
    key: ClassVar[str] = "torque_offset"

    @classmethod
    def start_from(cls, values: dict[str, float]) -> TorqueOffset:
        """Starting values for ``--add torque_offset`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(tau_0=values.get("tau_0", 0.0))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -jnp.asarray(self.tau_0, dtype=float) + 0.0 * motion.omega
