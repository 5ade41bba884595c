"""Direction-dependent (asymmetric) Stribeck friction at the wave generator."""

from __future__ import annotations

from typing import ClassVar

from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractFriction, Motion, StartValues, parameter, same_parameter
from ._candidate import Candidate
from .stribeck import StribeckFriction


class AsymmetricStribeckFriction(AbstractFriction):
    r"""Stribeck friction that is ``(1 + asym)`` times stronger sliding in +θ than the
    symmetric law and ``(1 − asym)`` times in −θ, static and kinetic alike.

    Sliding in direction ``s``: ``τ_f = s·(1 + s·asym)·m(ω)``, ``m`` the Stribeck magnitude of
    :class:`StribeckFriction`. Written as ``−(s + asym)·m(ω)`` the asymmetric part is a bias
    torque ``−asym·m(ω)`` that also acts at rest (``m(0) = tau_s``), which is exactly how the
    stick band becomes ``[−(1 − asym)·tau_s, (1 + asym)·tau_s]`` in net torque; the holding
    capacity stays ``tau_s``. Replaces the effect named ``"stribeck"``.

    Residual mark when missing: the rest points of + and − releases sit asymmetrically
    about the spring's zero, and the residual has a part that does not flip with the
    velocity. Its constant part ``−asym·tau_c`` is indistinguishable from a shift of the
    spring's zero (the per-set-up offset) in free motion: only the Stribeck part
    ``−asym·(m(ω) − tau_c)`` is visible, so a known spring zero (a zero-torque reading with
    the servo on) is the experiment that measures it.
    """

    tau_c: Float[ArrayLike, ""] = same_parameter(StribeckFriction, "tau_c")
    tau_s: Float[ArrayLike, ""] = same_parameter(StribeckFriction, "tau_s")
    v_s: Float[ArrayLike, ""] = same_parameter(StribeckFriction, "v_s")
    delta: Float[ArrayLike, ""] = same_parameter(StribeckFriction, "delta")
    asym: Float[ArrayLike, ""] = parameter(
        "1", "friction asymmetry: +θ is (1+asym), −θ is (1−asym) times",
        transform=("interval", -0.9, 0.9))

    key: ClassVar[str] = "asymmetric_friction"
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=30, replaces="stribeck",
        starts=lambda v: [{"asym": -0.25}, {"asym": 0.25}],
        mark="rest points of + and − releases sit asymmetrically and part of the residual "
             "does not flip with the velocity",
        experiment="a known spring zero (zero-torque reading with the servo on): without "
                   "it the Coulomb part of an asymmetry is the same as an encoder offset",
    )
    ordered: ClassVar[tuple[tuple[str, str], ...]] = StribeckFriction.ordered
    posterior_prior: ClassVar[dict] = StribeckFriction.posterior_prior

    @classmethod
    def start_from(cls, values: dict[str, float]) -> AsymmetricStribeckFriction:
        """Starting values for ``--add asymmetric_friction`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(**s.stribeck, asym=values.get("asym", 0.0))

    def _symmetric(self) -> StribeckFriction:
        return StribeckFriction(tau_c=self.tau_c, tau_s=self.tau_s, v_s=self.v_s, delta=self.delta)

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -(motion.direction + self.asym) * self._symmetric().sliding_magnitude(motion.omega)

    def holding_torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        return self._symmetric().holding_torque(motion, state)
