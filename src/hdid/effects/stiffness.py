"""Cubic torsional stiffness of the flexspline (paper eq. 4)."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractSpring, Motion, ScalePrior, StartValues, parameter
from ._candidate import Candidate


#: The posterior's default prior of a spring's linear stiffness at the output: log-normal
#: around the stiffness of the log's own swing (a factor 10.5 either way at 95 %).
K1_PRIOR = ScalePrior(lambda s: s.k_out,
                      "k_wg·N²: the stiffness of the log's own swing (k_wg = J·ω², ω from its "
                      "turning points)")
#: ... and of its cubic coefficient: where the cubic torque equals the linear one at the
#: log's release twist (``k1/θ²``).
K2_PRIOR = ScalePrior(lambda s: s.k_out / s.twist**2,
                      "k1/θ²: the cubic torque equals the linear one at the release twist "
                      "θ = amplitude/N")


class CubicStiffness(AbstractSpring):
    r"""Nonlinear torsional spring, ``T_k(d) = k1·d + k2·d³`` at the output.

    The output is locked, so the twist is ``d = theta / N`` and the spring torque
    reflected to the wave generator is ``-T_k(d) / N``.

    Residual mark when missing or wrong: a frequency that depends on amplitude
    (hardening ``k2 > 0`` speeds up large swings).
    """

    k1: Float[ArrayLike, ""] = parameter(
        "N m/rad", "linear torsional stiffness, output side",
        start=lambda s: s.k_out, sample_in_value=True)
    # k2·d³ about 17 % of the torque at the largest twist (the CSF-8 catalog's cubic)
    k2: Float[ArrayLike, ""] = parameter(
        "N m/rad^3", "cubic torsional stiffness, output side",
        start=lambda s: 0.17 * s.k_out / s.twist**2, flat_in_value=True, sample_in_value=True)

    key: ClassVar[str] = "stiffness"
    #: the posterior's default priors: log-normal around the log's own spring scales
    posterior_prior: ClassVar[dict] = {"k1": K1_PRIOR, "k2": K2_PRIOR}
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=80, replaces="linear_stiffness",
        mark="large first swings are faster than a linear spring allows (hardening)",
        experiment="releases at two amplitudes: the frequency then depends on amplitude",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> CubicStiffness:
        """Starting values for ``--add stiffness`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(k1=s.k1, k2=s.k2)

    def derived(self, inertia, k_wg):
        """Stiffness per unit inertia: what a free-motion log fixes when the inertia is
        only assumed (the motion depends on ``k/I``)."""
        del k_wg
        return {"k1/inertia": self.k1 / inertia, "k2/inertia": self.k2 / inertia}

    def spring_torque(self, twist: Float[Array, ""]) -> Float[Array, ""]:
        """Output-side torque ``T_k`` [N m] at output twist ``twist`` [rad]."""
        return self.k1 * twist + self.k2 * twist**3

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -self.spring_torque(motion.theta / motion.ratio) / motion.ratio

    def wg_stiffness(self, ratio: float) -> Array:
        """Small-twist stiffness reflected to the wave generator, ``k1 / N²`` [N m/rad]."""
        return jnp.asarray(self.k1) / ratio**2

