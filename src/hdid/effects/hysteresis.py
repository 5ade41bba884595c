"""Hysteresis: a Dahl element in parallel with the spring and friction."""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PyTree

from ._base import AbstractEffect, Motion, ScalePrior, StartValues, parameter
from ._candidate import Candidate, friction_level


class DahlHysteresis(AbstractEffect):
    r"""Dahl friction element (rate-independent hysteresis) at the wave generator.

    The element's torque ``z`` [N m] follows the WG angle with
    ``dz/dθ = sigma_h·(1 − s·z/f_h)``, ``s`` the direction of motion: it rises with initial
    slope ``sigma_h`` and saturates at ``±f_h``, so the torque–angle curve is a loop of
    height ``2·f_h`` whose corners are rounded over about ``f_h/sigma_h`` rad. Its torque on
    the WG is ``−z``, also at rest (an element holds its torque when the motion stops,
    which shifts the rest point). Before release the servo twisted the WG monotonically
    from the spring's zero to ``θ0``, so ``z0 = sign(θ0)·f_h·(1 − exp(−sigma_h·|θ0|/f_h))``.

    Exact within a simulator step: the state keeps an anchor ``(θ_a, z_a)`` and the torque
    is the closed-form solution from the anchor for the step's frozen direction.

    Residual mark when missing: after each reversal the real gear decelerates more gently
    than Coulomb friction predicts (the element's torque turns over gradually), the rest
    point is pulled towards the side the gear came from, and the residual grows with the
    swing amplitude. With ``sigma_h → ∞`` it is Coulomb friction ``f_h``; with ``f_h/sigma_h``
    larger than the swing it is an extra spring: only releases of different amplitudes
    separate it from stiffness and Coulomb friction.
    """

    f_h: Float[ArrayLike, ""] = parameter(
        "N m", "saturation torque of the Dahl element at the wave generator",
        start=lambda s: 0.2 * s.torque)
    sigma_h: Float[ArrayLike, ""] = parameter(
        "N m/rad", "initial (rest) stiffness of the Dahl element, WG side",
        start=lambda s: s.k_wg)

    name: ClassVar[str] = "hysteresis"
    key: ClassVar[str] = "hysteresis"
    #: the posterior's default priors (log-normal around scales of the log in hand)
    posterior_prior: ClassVar[dict] = {
        "f_h": ScalePrior(lambda s: s.torque, "the friction torque of the log's ring-down "
                          "(k_wg × amplitude lost / 4)"),
        "sigma_h": ScalePrior(lambda s: s.k_wg, "k_wg: the log's swing stiffness at the WG")}
    #: how ``hdid diagnose`` tries it
    candidate: ClassVar[Candidate] = Candidate(
        trial=20,
        starts=lambda v: [{"f_h": a * friction_level(v), "sigma_h": b * v["_k_wg"]}
                          for a in (0.2, 0.5) for b in (0.5, 2.0)],
        mark="after each reversal the gear decelerates more gently than Coulomb friction "
             "allows and the rest point is pulled towards where it came from",
        experiment="releases of several amplitudes (the loop's rounded corners do not "
                   "scale with amplitude, Coulomb friction and stiffness do) and 1 kHz "
                   "sampling around the reversals",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> DahlHysteresis:
        """Starting values for ``--add hysteresis`` (see :func:`hdid.effects.library`)."""
        s = StartValues.of(values)
        return cls(f_h=values.get("f_h", 0.2 * s.tau_c), sigma_h=values.get("sigma_h", s.k_wg))

    def _z(self, theta, theta_a, z_a, s):
        moved = jnp.maximum(s * (theta - theta_a), 0.0)
        return s * self.f_h + (z_a - s * self.f_h) * jnp.exp(-self.sigma_h * moved / self.f_h)

    def init_state(self, theta0: Float[Array, ""]) -> PyTree:
        s = jnp.sign(theta0)
        z0 = self._z(theta0, jnp.zeros(()), jnp.zeros(()), s)
        return (jnp.asarray(theta0, dtype=float), z0)

    def update_state(self, state, theta_old, theta_new):
        # The anchor is where the previous step ended (θ_a = theta_old); a step is monotone
        # in angle (the simulator splits steps at velocity zeros), so the closed form from
        # the anchor in the step's direction is exact.
        _, z_a = state
        s = jnp.sign(theta_new - theta_old)
        return (theta_new, self._z(theta_new, theta_old, z_a, s))

    def torque(self, motion: Motion, state) -> Float[Array, ""]:
        theta_a, z_a = state
        return -self._z(motion.theta, theta_a, z_a, motion.direction)
