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
