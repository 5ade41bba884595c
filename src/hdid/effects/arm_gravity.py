"""An arm's gravity in a log of absolute angles, with the dry friction its load causes."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import Motion, ScalePrior, StartValues, parameter, same_parameter
from .gravity import AbsoluteGravity


class ArmGravity(AbsoluteGravity):
    r"""Gravity on an arm whose joint angle is logged absolutely (a robot joint's
    controller angle), and a dry friction that grows with the gravity load: at the logged
    axis the torque is ``−(mgl/N)·sin(θ/N − theta_g) − s·(c_g/N)·|sin(θ/N − theta_g)|``
    (``s`` the sliding direction), and the static capacity gains ``(c_g/N)·|sin(θ/N −
    theta_g)|``.

    ``mgl`` [N m] and ``theta_g`` [rad, output angle, where the arm hangs] are those of
    :class:`~hdid.effects.gravity.AbsoluteGravity` (the published ``G(θ) = A·sin(θ − θ₀)``
    of a manipulator joint at ratio 1); ``c_g`` [N m, output side] is the friction at full
    load (the arm horizontal). Bearing and gear friction grow with the torque a joint
    carries, and the torque a slow joint carries is mostly its gravity load, so the loss
    follows ``|sin(θ/N − theta_g)|``: zero where the arm hangs, largest where it is
    horizontal. One effect holds both terms so that they share one hanging angle (a
    separate friction effect would need its own, which the log cannot tell from
    ``theta_g``). It fills the ``gravity`` slot: ``--add arm_gravity`` replaces a model's
    ``gravity``, and a driven fit starts ``mgl`` and ``theta_g`` from its equation-error
    regression as for :class:`~hdid.effects.gravity.AbsoluteGravity`. For a drop test,
    whose angles have a fitted zero, use ``gravity`` and ``gravity_friction`` instead.
    ``sin`` needs θ in radians.

    Residual mark when missing (with ``gravity`` in the model): a torque that flips with
    the direction of motion and grows with ``|sin|`` of the arm's angle from hanging, so a
    constant Coulomb level is too weak with the arm out and too strong near hanging; an
    output-error fit of a slow driven log then inflates the inertia and the viscous
    coefficient to carry it (UR10e joint 2: inertia +56 % without it, +7 % with it).
    """

    mgl: Float[ArrayLike, ""] = same_parameter(AbsoluteGravity, "mgl")
    theta_g: Float[ArrayLike, ""] = same_parameter(AbsoluteGravity, "theta_g")
    c_g: Float[ArrayLike, ""] = parameter(
        "N m", "dry friction at full gravity load (arm horizontal), output side; it scales "
        "with |sin(θ/N − theta_g)|", start=lambda s: 0.5 * s.torque * s.ratio)

    key: ClassVar[str] = "arm_gravity"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {
        "mgl": ScalePrior(lambda s: s.k_out, "the stiffness of the log's own swing at the "
                          "output (gravity torque per radian)"),
        "c_g": ScalePrior(lambda s: s.torque * s.ratio,
                          "the log's friction torque, at the output")}

    @classmethod
    def start_from(cls, values: dict[str, float]) -> ArmGravity:
        """Starting values for ``--add arm_gravity`` (see :func:`hdid.effects.library`): the
        model's ``mgl`` (its output stiffness where none is given), ``theta_g`` or 0, and
        ``c_g`` a tenth of ``mgl``."""
        mgl = values.get("mgl", StartValues.of(values).k1)
        return cls(mgl=mgl, theta_g=values.get("theta_g", 0.0),
                   c_g=values.get("c_g", 0.1 * mgl))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        x = motion.theta / motion.ratio - self.theta_g
        return -(self.mgl * jnp.sin(x) + motion.direction * self.c_g * jnp.abs(jnp.sin(x))) \
            / motion.ratio

    def holding_torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return self.c_g * jnp.abs(jnp.sin(motion.theta / motion.ratio - self.theta_g)) \
            / motion.ratio


__all__ = ["ArmGravity"]
