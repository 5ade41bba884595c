"""Free play (lost motion): a dead zone in the torsional spring."""

from __future__ import annotations

import math
from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractSpring, Motion, ScalePrior, StartValues, parameter, same_parameter
from ._candidate import Candidate
from .stiffness import K1_PRIOR, K2_PRIOR, CubicStiffness


class FreePlayStiffness(AbstractSpring):
    r"""Cubic spring with a dead zone: ``T = k1·e + k2·e³``, ``e = sign(d)·max(|d| − b/2N, 0)``.

    ``backlash`` is the total free play measured at the wave generator [rad] (at the
    output it is ``backlash / N``). Inside the zone the spring exerts no torque, so the
    gear coasts on friction alone. It replaces the model's spring (:class:`AbstractSpring`).

    Residual mark when missing: the approach to rest is too abrupt (the real gear
    coasts without spring torque inside the zone); rest points spread wider than the
    stick band alone explains.
    """

    k1: Float[ArrayLike, ""] = same_parameter(CubicStiffness, "k1")
    k2: Float[ArrayLike, ""] = same_parameter(CubicStiffness, "k2")
    backlash: Float[ArrayLike, ""] = parameter(
        "rad", "total free play at the wave generator",
        start=lambda s: 0.06 * s.amplitude)

    key: ClassVar[str] = "backlash"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {"k1": K1_PRIOR, "k2": K2_PRIOR, "backlash": ScalePrior(
        lambda s: 0.06 * s.amplitude,
        "6 % of the release amplitude (its start rule): a free play small against the swing")}
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=10, replaces="stiffness",
        # free play a few % of the logged swing (0.005 and 0.02 rad on a CSF-8's ±0.157)
        starts=lambda v: ([{"backlash": f * v["_swing"]} for f in (0.016, 0.064)]
                          if math.isfinite(v["_swing"]) else [{}]),
        mark="the approach to rest is too abrupt in the model — the gear coasts through a "
             "dead zone without spring torque — and rest points spread wider than stiction "
             "explains",
        experiment="releases from several amplitudes and a 1 kHz log resolve the coasting "
                   "through the dead zone; an added-inertia run changes the coasting time "
                   "but not the band",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> FreePlayStiffness:
        """Starting values for ``--add backlash`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(k1=s.k1, k2=s.k2, backlash=values.get("backlash", 0.01))

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        d = motion.theta / motion.ratio
        half = 0.5 * self.backlash / motion.ratio
        e = jnp.sign(d) * jnp.maximum(jnp.abs(d) - half, 0.0)
        # the same spring law as CubicStiffness, applied to the twist beyond the zone
        return -CubicStiffness(k1=self.k1, k2=self.k2).spring_torque(e) / motion.ratio
