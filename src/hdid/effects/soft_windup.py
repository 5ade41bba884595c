"""Catalog three-segment torsional stiffness (soft wind-up)."""

from __future__ import annotations

import math
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
        starts=lambda v: _starts(v),
        mark="the swing period near rest differs from the cubic model's: the phase error "
             "grows as the amplitude decays",
        experiment="a small-amplitude release (inside the first catalog segment) measures "
                   "the centre stiffness K1 directly",
    )

    @staticmethod
    def free_play_corner(k1: float, backlash: float, ratio: float, twist: float) -> dict[str, float]:
        """The segments at the corner that *is* a free play: total play ``backlash`` [rad,
        at the WG] then a linear spring ``k1`` [N m/rad, output side]. ``K1`` → 0 (held at
        ``CORNER_K1·k1``, the log transform keeps it positive), ``T1/K1 = backlash/2N`` (the
        zone's half-width at the output), ``K2 = K3 = k1``; the second corner half-way out
        to the output twist ``twist`` [rad], where a stiffening spring bends."""
        d1 = 0.5 * backlash / ratio
        K1 = CORNER_K1 * k1
        return {"K1": K1, "T1": K1 * d1, "K2": k1, "K3": k1,
                "dT12": k1 * max(0.5 * twist - d1, d1)}

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


#: Free play's own start fractions of the logged swing (``backlash``'s candidate starts).
FREE_PLAY_FRACTIONS = (0.016, 0.064)
#: ``K1/k1`` at the dead-zone corner start: a centre segment 100x softer than the spring
#: exerts less than 1 % of its torque inside the zone (a free play to the fit's eye).
CORNER_K1 = 0.01


def _starts(v: dict[str, float]) -> list[dict[str, float]]:
    """``diagnose``'s starts: the catalog shape, a softer centre (0.6 k1), and the
    dead-zone corner (:meth:`ThreeSegmentStiffness.free_play_corner`) at free play's own
    start fractions of the logged swing: with ``K1`` → 0 the segments *are* a free play
    then a spring, a basin the soft-centre starts never reach (a backlash log's soft
    wind-up fit stayed at K1 0.25 k1 from them). ``N = √(k1/k_wg)``."""
    if "k1" not in v:
        return [{}]
    out = [{}, {"K1": 0.6 * v["k1"]}]
    k_wg, swing = v.get("_k_wg", math.nan), v.get("_swing", math.nan)
    if math.isfinite(k_wg) and k_wg > 0 and math.isfinite(swing) and swing > 0:
        n = math.sqrt(v["k1"] / k_wg)
        out += [ThreeSegmentStiffness.free_play_corner(v["k1"], f * swing, n, swing / n)
                for f in FREE_PLAY_FRACTIONS]
    return out
