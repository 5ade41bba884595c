"""Braking of a coasting motor whose back-EMF exceeds its driver's supply."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractEffect, Motion, ScalePrior, parameter
from ._candidate import Candidate
from .gravity_friction import _WithGravity


class BackEmfBraking(AbstractEffect):
    r"""A coasting motor behind a bridge driver: ``τ = −sign(ω)·c_e·max(|ω| − w_e, 0)``.

    With the drive torque off (a drop test's release) the bridge's switches are open, but
    their freewheel diodes are not: once the motor's back-EMF ``k_e·|ω|`` exceeds the supply
    plus two diode drops, current flows back into the supply and brakes the motor,
    ``τ = (k_t/R)·(k_e·|ω| − V_clamp)``. Below the threshold speed ``w_e = V_clamp/k_e``
    nothing flows, so the law is a viscous brake with a dead zone: zero on slow swings,
    ``c_e ≤ k_t·k_e/R`` per rad/s above ``w_e`` (less where the supply cannot absorb the
    current and its voltage rises). Both at the logged axis: ``w_e`` [rad/s], ``c_e``
    [N m s/rad]. A check only the physics gives: ``w_e·k_e`` is the supply voltage plus
    about two diode drops, and across set-ups of one servo on one supply ``w_e`` is one
    constant whatever the load.

    Residual mark when missing: the fast swings (the first ones, the large releases) lose
    more than a friction law fitted to the slow ones allows, and a Stribeck law fitted in
    its place runs to a friction that rises steeply with speed (``tau_c ≫ tau_s`` and
    ``delta`` at its upper bound: a step in the friction at a speed the log reaches).
    """

    c_e: Float[ArrayLike, ""] = parameter(
        "N m s/rad", "braking torque per rad/s above the threshold speed (≤ k_t·k_e/R)",
        # at the log's peak speed the brake starts equal to its ring-down's friction
        start=lambda s: 2.0 * s.torque / s.speed)
    w_e: Float[ArrayLike, ""] = parameter(
        "rad/s", "threshold speed: the supply plus two diode drops over the back-EMF constant",
        start=lambda s: 0.5 * s.speed)

    name: ClassVar[str] = "back_emf"
    key: ClassVar[str] = "back_emf"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {
        "c_e": ScalePrior(lambda s: s.torque / s.speed,
                          "torque per peak speed: the ring-down's friction torque over the "
                          "log's peak speed"),
        "w_e": ScalePrior(lambda s: 0.5 * s.speed, "half the log's peak speed")}
    #: how ``hdid diagnose`` tries it: on a drop (a model with a pendulum), where the
    #: motor coasts with its driver off
    candidate: ClassVar[Candidate] = _WithGravity(
        trial=95,
        mark="the fast swings lose more than a friction law fitted to the slow ones allows; "
             "a Stribeck law in its place rises steeply with speed",
        experiment="releases from several angles: the loss per half-swing then steps up "
                   "above one speed, whatever the load",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> BackEmfBraking:
        """Starting values for ``--add back_emf`` (see :func:`hdid.effects.library`):
        the given ones, else a brake of a thousandth of the model's viscous coefficient
        above 1 rad/s — nearly the model without it, so that a warm start from a fitted
        model (``diagnose``) begins where that model ended, with a gradient that can grow
        it (a fresh fit's ``start`` rules replace both from the log's speed and friction)."""
        return cls(c_e=values.get("c_e", 1e-3 * values.get("c_v", 0.1)),
                   w_e=values.get("w_e", 1.0))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        excess = jnp.maximum(jnp.abs(motion.omega) - self.w_e, 0.0)
        return -jnp.sign(motion.omega) * self.c_e * excess
