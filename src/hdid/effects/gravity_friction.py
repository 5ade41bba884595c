"""Friction that grows with the gravity torque the gear transmits (a pendulum's load)."""

from __future__ import annotations

import math
from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractEffect, Motion, ScalePrior, StartValues, parameter
from ._candidate import Candidate
from .arm_gravity import ArmGravity


class _WithGravity(Candidate):
    """A candidate meaningful only on a model that holds a pendulum (a ``gravity`` effect):
    without one there is no gravity torque for the friction to follow; nor on one whose
    gravity is :class:`~hdid.effects.arm_gravity.ArmGravity`, which carries this friction."""

    def applies(self, model) -> bool:
        return (any(e.name == "gravity" and not isinstance(e, ArmGravity) for e in model.effects)
                and super().applies(model))


class GravityLoadFriction(AbstractEffect):
    r"""Dry friction proportional to the pendulum's gravity torque, the load the gear
    transmits in a drop: ``τ = −s·c_g·|sin(θ/N)|/N`` at the logged axis (``s`` the
    sliding direction), and the same amount added to the static capacity.

    Tooth, bearing and worm/spur-mesh friction grow with the torque a gear transmits
    (an efficiency ``η < 1``: a loss ``(1 − η)·|τ_transmitted|``). In a free drop the
    only torque that drives the gear is the pendulum's, ``mgl·sin(θ_out)``; the gear
    passes the share that accelerates the motor's rotor (``J_rotor,reflected / I_total``
    of it, a constant of the set-up), so the loss is ``c_g·|sin θ_out|`` at the output with
    ``c_g = (1 − η)·mgl·J_rotor/I_total`` [N m] — reflected to the logged axis as
    ``/N``. Like :class:`~hdid.effects.LoadDependentFriction` (whose load is a spring's
    twist, ``|θ|``) it is self-contained: it follows the shape of the gravity torque, not
    another effect's parameter. Two checks only the physics gives: across set-ups of one
    gear with known ``m``, ``l``, ``c_g·I_total/mgl`` is one constant (the gear's
    ``(1 − η)·J_rotor``); and a friction that follows a bearing's radial load (``∝ m``,
    not ``∝ J_rotor/I_total``) does not make it so. ``sin`` needs θ in radians (as
    :class:`~hdid.effects.Gravity`).

    Residual mark when missing: the amplitude lost per half-swing grows with the swing
    faster than Coulomb (constant) and viscous (``∝`` speed) friction allow, so a
    constant-friction fit is too weak on the first, large swings and too strong on the
    last ones; the fitted gravity torque comes out high (a stronger pull shortens the
    swing that the missing friction shortens), and a Stribeck law runs to a rising
    friction with speed (large swings are fast ones).
    """

    c_g: Float[ArrayLike, ""] = parameter(
        "N m", "friction per unit of sin(output angle): the share of the gravity torque the "
        "gear loses (1 − η)·mgl·J_rotor/I_total",
        start=lambda s: 0.1 * s.k_out)

    name: ClassVar[str] = "gravity_friction"
    key: ClassVar[str] = "gravity_friction"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {"c_g": ScalePrior(
        lambda s: s.torque * s.ratio / max(math.sin(min(s.twist, math.pi / 2)), 1e-6),
        "friction torque / sin(release angle): the whole ring-down's friction as load "
        "friction at the release amplitude")}
    #: how ``hdid diagnose`` tries it (only on a model with a pendulum)
    candidate: ClassVar[Candidate] = _WithGravity(
        trial=45,
        starts=lambda v: [{"c_g": 0.03 * v.get("mgl", v["_k_wg"])},
                          {"c_g": 0.15 * v.get("mgl", v["_k_wg"])}],
        mark="the amplitude lost per half-swing grows with the swing faster than constant "
             "or viscous friction allow; the fitted gravity torque comes out high",
        experiment="releases from several angles, and the same arm with two masses: the "
                   "loss per half-swing then separates a load from a speed dependence",
        family="load_friction",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> GravityLoadFriction:
        """Starting values for ``--add gravity_friction`` (see :func:`hdid.effects.library`):
        a tenth of the pendulum's ``mgl`` (of the output stiffness where none is given)."""
        s = StartValues.of(values)
        return cls(c_g=values.get("c_g", 0.1 * values.get("mgl", s.k1)))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -motion.direction * self._load(motion)

    def holding_torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return self._load(motion)

    def _load(self, motion: Motion) -> Float[Array, ""]:
        """Friction magnitude at the logged axis [N m]."""
        return self.c_g * jnp.abs(jnp.sin(motion.theta / motion.ratio)) / motion.ratio


__all__ = ["GravityLoadFriction"]
