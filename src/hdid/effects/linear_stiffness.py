"""Linear torsional stiffness: the cubic term switched off."""

from __future__ import annotations

from typing import ClassVar

from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractSpring, Motion, StartValues, same_parameter
from .stiffness import K1_PRIOR, CubicStiffness


class LinearStiffness(AbstractSpring):
    r"""Linear spring ``T_k(d) = k1·d`` at the output (``CubicStiffness`` with ``k2 = 0``).

    Use it to switch the cubic term off, e.g. to check whether the data need it. Replaces
    the model's spring (:class:`AbstractSpring`).

    Residual mark when the cubic term is missing: the large first swings of a release are
    slower in the model than in the gear (a hardening spring speeds them up), so the phase
    error is largest early and shrinks as the amplitude decays.
    """

    k1: Float[ArrayLike, ""] = same_parameter(CubicStiffness, "k1")

    key: ClassVar[str] = "linear_stiffness"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {"k1": K1_PRIOR}

    @classmethod
    def start_from(cls, values: dict[str, float]) -> LinearStiffness:
        """Starting values for ``--add linear_stiffness`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(k1=s.k1)

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del state
        return -self.k1 * (motion.theta / motion.ratio) / motion.ratio
