"""The effect interface: one physical effect = one small equinox module.

Every effect contributes a torque acting on the wave generator (WG); the model sums them,
like diffrax's ``MultiTerm`` sums terms. Friction-like effects additionally say how much
torque they can *hold* at rest, which is what makes the simulator stick exactly.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from typing import Any, ClassVar

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PyTree


@dataclass(frozen=True)
class Parameter:
    """Declaration of one physical parameter of an effect.

    Attributes
    ----------
    name:
        Name used in reports, JSON and on the command line (must be unique in a model).
    unit:
        SI unit, e.g. ``"N m/rad"``.
    doc:
        One line: what it is, and on which side of the gear.
    transform:
        How the optimiser sees it: ``"log"`` (strictly positive), ``"identity"`` or
        ``("interval", lo, hi)`` (a logistic map onto the open interval).
    prior:
        Optional weak prior in the *transformed* space, ``(mean, sd)``; ``None`` means
        flat. Used to regularise parameters the data cannot fix (stated in the report).
    scale:
        Typical magnitude of an ``"identity"`` parameter: the optimiser sees
        ``value / scale``, so that its steps are of order one (e.g. ``1e-3`` for a torque
        in N m). Ignored by the other transforms, which are scale-free.
    """

    name: str
    unit: str
    doc: str
    transform: str | tuple[str, float, float] = "log"
    prior: tuple[float, float] | None = None
    scale: float = 1.0


class Motion(eqx.Module):
    """What an effect sees of the wave generator at one instant.

    Attributes
    ----------
    theta:
        WG angle [rad] measured from the spring's zero (the output is locked, so
        ``theta / ratio`` is the flexspline twist at the output).
    omega:
        WG angular velocity [rad/s].
    direction:
        Sliding direction, ``+1`` or ``-1`` while sliding (held fixed through an
        integration step so friction never flips inside one), ``0`` while stuck.
        Friction laws must use ``direction``, not ``sign(omega)``.
    ratio:
        Gear ratio N.
    """

    theta: Float[Array, ""]
    omega: Float[Array, ""]
    direction: Float[Array, ""]
    ratio: Float[ArrayLike, ""]


class AbstractEffect(eqx.Module):
    """A physical effect acting on the wave generator.

    Subclasses declare their parameters as array fields *and* in the class variable
    ``parameters`` (same names, with units and transforms), give themselves a ``name``,
    and implement :meth:`torque`. Friction-like effects also implement
    :meth:`holding_torque`; effects with memory (hysteresis elements, friction state)
    implement :meth:`init_state` / :meth:`update_state`.

    A user-defined effect is one file::

        class Cogging(hdid.AbstractEffect):
            amplitude: float | jax.Array
            name: ClassVar[str] = "cogging"
            parameters: ClassVar = (hdid.Parameter("amplitude", "N m", "cogging torque",
                                                   transform="identity", scale=1e-3),)
            def torque(self, motion, state):
                return -self.amplitude * jnp.sin(24 * motion.theta)
    """

    name: eqx.AbstractClassVar[str]
    parameters: eqx.AbstractClassVar[tuple[Parameter, ...]]

    @abc.abstractmethod
    def torque(self, motion: Motion, state: PyTree) -> Float[Array, ""]:
        """Torque [N m] this effect applies to the WG (positive accelerates +theta).

        Evaluated with ``motion.direction == 0`` at rest: a friction law must then return
        its *sliding* part only (zero for Coulomb/Stribeck), its static capacity goes in
        :meth:`holding_torque`.
        """

    def holding_torque(self, motion: Motion, state: PyTree) -> Float[Array, ""]:
        """Largest torque magnitude [N m] this effect can resist at rest (default 0)."""
        del motion, state
        return jnp.zeros(())

    def init_state(self, theta0: Float[Array, ""]) -> PyTree:
        """Internal state at release (default: none)."""
        del theta0
        return None

    def update_state(
        self, state: PyTree, theta_old: Float[Array, ""], theta_new: Float[Array, ""]
    ) -> PyTree:
        """State after the WG moved from ``theta_old`` to ``theta_new`` (default: unchanged)."""
        del theta_old, theta_new
        return state

    def values(self) -> dict[str, Any]:
        """Current parameter values by name."""
        return {p.name: getattr(self, p.name) for p in self.parameters}


def positive_power(x: Array, exponent: Array) -> Array:
    """``x ** exponent`` for ``x >= 0`` with finite derivatives at ``x == 0`` (double-where)."""
    safe = jnp.where(x > 0, x, 1.0)
    return jnp.where(x > 0, jnp.exp(exponent * jnp.log(safe)), 0.0)
