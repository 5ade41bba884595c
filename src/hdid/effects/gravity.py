"""Gravity on a pendulum mounted on the output: the spring of a drop test."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractEffect, Motion, ScalePrior, StartValues, parameter


class Gravity(AbstractEffect):
    r"""A pendulum on the output shaft: output torque ``−mgl·sin(θ/N)``, reflected to the
    wave generator as ``−(mgl/N)·sin(θ/N)``.

    ``mgl`` [N m] is the pendulum's mass × g × distance from the axis to its centre of
    mass (its gravity torque when horizontal). θ is measured from the fitted zero, so the
    hanging (stable) position is the per-set-up offset the fit already estimates; the
    output angle is ``θ/N``. Small swings see an output stiffness ``mgl`` and the
    frequency ``sqrt(mgl/I_out)/2π`` with ``I_out = N²·I``. It is "the spring" of a drop
    test (a pendulum released from a hold with the drive torque off), so a model may hold
    it and no ``stiffness`` (``--remove stiffness --add gravity``); with a flexible gear
    and a pendulum both act, in parallel. Log transform (``mgl > 0``: the zero is the
    stable equilibrium); starts at the log's small-swing output stiffness. In a model with
    no spring the log is read as a drop (``hdid._fitting._pendulum``): the release is
    found from the swing (a servo's lift, creep or flicker before it is not the
    pendulum's), ``mgl = N²·I·ω₀²`` from the half-swings between turning points (each
    corrected for its amplitude, ``T/2 = 2K(sin²(A/2))/ω₀``), the zero from the energy
    balance of half-swings in both directions, and the friction levels from how that
    balance's loss grows with the swing (Coulomb: constant, viscous: ∝ amplitude). Unlike the
    other effects it is not free of the angle unit: ``sin`` needs θ in radians (a log in
    degrees or mrad must be converted first); time and torque units are free.

    Residual mark when missing or wrong: the swing period grows with amplitude (softening,
    ``T ≈ T0·(1 + A²/16)`` at output amplitude ``A``), where a spring's stays constant or
    shrinks; a model with a linear spring in its place fits the small swings and misses
    the first, large ones by a phase error that grows with the release angle.
    """

    mgl: Float[ArrayLike, ""] = parameter(
        "N m", "pendulum gravity torque m·g·l at the output (mass × g × arm)",
        start=lambda s: s.k_out)

    name: ClassVar[str] = "gravity"
    key: ClassVar[str] = "gravity"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {"mgl": ScalePrior(
        lambda s: s.k_out,
        "the stiffness of the log's own swing at the output (gravity torque per radian)")}

    @classmethod
    def start_from(cls, values: dict[str, float]) -> Gravity:
        """Starting values for ``--add gravity`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(mgl=values.get("mgl", s.k1))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -self.mgl * jnp.sin(motion.theta / motion.ratio) / motion.ratio


class AbsoluteGravity(AbstractEffect):
    r"""Gravity on a pendulum in a log of absolute angles (a robot joint's controller
    angle): output torque ``−mgl·sin(θ/N − theta_g)``, reflected to the logged axis as
    ``−(mgl/N)·sin(θ/N − theta_g)``.

    The drive torque that holds the arm is ``mgl·sin(θ/N − theta_g)``: the published
    ``G(θ) = A·sin(θ − θ₀)`` of a manipulator joint at ratio 1 (``A = mgl``,
    ``θ₀ = theta_g``). ``theta_g`` [rad, output angle] is where the arm hangs (the stable
    equilibrium), in the log's own angle frame. A free-motion drop measures θ from a
    fitted zero per set-up, so there :class:`Gravity` holds no angle; a driven log has no
    such zero (its angles are the drive's), so a driven fit puts this effect in place of
    :class:`Gravity` (``hdid._fitting._driven_fit``), starting both parameters from the
    equation-error regression of the logged torque on ``sin(θ/N)`` and ``cos(θ/N)``
    (:mod:`hdid._fitting._driven_starts`). Like :class:`Gravity`, ``sin`` needs θ in
    radians.

    Residual mark when missing: a torque that follows ``sin θ``/``cos θ`` of the joint
    angle, hence a drift of the simulated angle downhill, growing where the arm is
    horizontal; with the hanging angle wrong, a torque that looks like an offset plus a
    spring about the wrong angle.
    """

    mgl: Float[ArrayLike, ""] = parameter(
        "N m", "pendulum gravity torque m·g·l at the output (mass × g × arm)",
        start=lambda s: s.k_out)
    theta_g: Float[ArrayLike, ""] = parameter(
        "rad", "output angle at which the pendulum hangs (its stable equilibrium), in the "
        "log's angle frame", transform="identity", start=lambda s: 0.0)

    name: ClassVar[str] = "gravity"

    @classmethod
    def of(cls, gravity: Gravity, theta_g: float = 0.0) -> AbsoluteGravity:
        """``gravity`` with its hanging angle ``theta_g`` (0: the zero of the log)."""
        return cls(mgl=gravity.mgl, theta_g=theta_g)

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -self.mgl * jnp.sin(motion.theta / motion.ratio - self.theta_g) / motion.ratio
