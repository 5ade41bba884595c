"""Load-dependent friction: Coulomb and static friction that grow with the twist."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractEffect, Motion, ScalePrior, StartValues, parameter
from ._candidate import Candidate


class LoadDependentFriction(AbstractEffect):
    r"""Friction proportional to the transmitted load, ``τ = c_load·|θ|`` at the WG.

    Tooth and wave-generator-bearing friction rise with the torque the gear transmits;
    with the output locked that torque is the spring's, ``≈ (k1/N²)·|θ|``, so the classic
    ``τ_c = τ_c0 + μ·|spring torque|`` is this effect with ``c_load = μ·k1/N²`` (``μ`` of
    0.05 … 0.3 gives ``c_load`` ≈ 5e-3 … 3e-2 N m/rad for a CSF-8). It opposes sliding and
    adds the same amount to the static capacity. Keeping it linear in ``|θ|`` makes the
    effect self-contained (it needs no other effect's stiffness).

    Residual mark when missing: large swings lose more amplitude per half-cycle than small
    ones (the decrement grows with amplitude, unlike Coulomb's constant ``2·τ_c/k``), so a
    constant-friction fit is too weak early and too strong late; the rest points of large
    releases sit farther out.
    """

    c_load: Float[ArrayLike, ""] = parameter(
        "N m/rad", "friction increase per rad of WG twist (μ·k1/N²)",
        start=lambda s: 0.05 * s.k_wg)

    name: ClassVar[str] = "load_friction"
    key: ClassVar[str] = "load_friction"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {"c_load": ScalePrior(
        lambda s: s.torque / (s.k_wg * s.amplitude),
        "friction torque / spring torque at the release amplitude (a coefficient of 1 turns "
        "the whole ring-down's friction into load friction)")}
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=40,
        starts=lambda v: [{"c_load": 0.02 * v["_k_wg"]}, {"c_load": 0.1 * v["_k_wg"]}],
        mark="large swings lose more amplitude per half-cycle than small ones, so a "
             "constant friction is too weak early and too strong late",
        experiment="releases from at least three amplitudes: the decrement per half-cycle "
                   "then shows its growth with load",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> LoadDependentFriction:
        """Starting values for ``--add load_friction`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(c_load=values.get("c_load", 0.05 * s.k_wg))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -motion.direction * self.c_load * jnp.abs(motion.theta)

    def holding_torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return self.c_load * jnp.abs(motion.theta)
