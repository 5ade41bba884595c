"""Catalog three-segment torsional stiffness (soft wind-up)."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractSpring, Motion, ScalePrior, StartValues, parameter
from ._candidate import Candidate


class ThreeSegmentStiffness(AbstractSpring):
    r"""Piecewise-linear spring of the Harmonic Drive catalogs, output side.

    ``T(d) = K1·d`` up to ``T1``, slope ``K2`` up to ``T2 = T1 + dT12``, slope ``K3``
    beyond, odd in the twist ``d = θ/N``; torque on the WG ``−T(d)/N``. The corners sit at
    ``d1 = T1/K1`` and ``d2 = d1 + dT12/K2``. CSF-8-100 catalog: ``T1`` = 0.29 N m,
    ``K1`` = 910, ``T2`` = 0.75 N m, ``K2`` = 1000, ``K3`` = 1200 N m/rad. Replaces the
    model's spring (:class:`AbstractSpring`).

    Residual mark when missing: a cubic cannot follow a soft centre (``K1 < K2``), so the
    swing period near rest is too short in the cubic model: the phase error grows as the
    amplitude decays, and the last half-cycles before rest carry the residual. A release
    amplitude that stays inside the first segment measures ``K1`` alone.
    """

    # the CSF-8 catalog's segments relative to its cubic fit (physics notes)
    K1: Float[ArrayLike, ""] = parameter(
        "N m/rad", "stiffness of the first segment (|T| ≤ T1), output side",
        start=lambda s: 0.97 * s.k_out)
    K2: Float[ArrayLike, ""] = parameter(
        "N m/rad", "stiffness of the second segment (T1 … T2), output side",
        start=lambda s: 1.06 * s.k_out)
    K3: Float[ArrayLike, ""] = parameter(
        "N m/rad", "stiffness beyond T2, output side",
        start=lambda s: 1.28 * s.k_out)
    T1: Float[ArrayLike, ""] = parameter(
        "N m", "output torque at the first corner",
        start=lambda s: 0.2 * s.k_out * s.twist)
    dT12: Float[ArrayLike, ""] = parameter(
        "N m", "T2 − T1: output torque between the corners",
        start=lambda s: 0.31 * s.k_out * s.twist)

    key: ClassVar[str] = "soft_windup"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {
        **{k: ScalePrior(lambda s: s.k_out, "k_wg·N²: the stiffness of the log's own swing")
           for k in ("K1", "K2", "K3")},
        **{k: ScalePrior(lambda s: s.k_out * s.twist, "k1·θ: the spring torque at the "
                         "release twist") for k in ("T1", "dT12")}}
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=60, replaces="stiffness",
        starts=lambda v: [{}, {"K1": 0.6 * v["k1"]}] if "k1" in v else [{}],
        mark="the swing period near rest differs from the cubic model's: the phase error "
             "grows as the amplitude decays",
        experiment="a small-amplitude release (inside the first catalog segment) measures "
                   "the centre stiffness K1 directly",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> ThreeSegmentStiffness:
        """Starting values for ``--add soft_windup`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        k1 = s.k1
        return cls(K1=values.get("K1", 0.97 * k1), K2=values.get("K2", 1.06 * k1),
                   K3=values.get("K3", 1.28 * k1), T1=values.get("T1", 0.29 * k1 / 940.0),
                   dT12=values.get("dT12", 0.46 * k1 / 940.0))

    def spring_torque(self, twist: Float[Array, ""]) -> Float[Array, ""]:
        """Output-side torque [N m] at output twist ``twist`` [rad]."""
        a = jnp.abs(twist)
        d1 = self.T1 / self.K1
        d2 = d1 + self.dT12 / self.K2
        t = jnp.where(
            a <= d1,
            self.K1 * a,
            jnp.where(a <= d2, self.T1 + self.K2 * (a - d1), self.T1 + self.dT12 + self.K3 * (a - d2)),
        )
        return jnp.sign(twist) * t

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -self.spring_torque(motion.theta / motion.ratio) / motion.ratio
