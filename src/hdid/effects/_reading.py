"""The measurement side of a model: how a logged reading relates to the simulated state.

Every other effect adds a torque; a *reading* component adds none. It says at which instant
of the simulated motion each logged reading was taken. The forward model
(:class:`~hdid._problems._problem.Problem`) asks the model's one reading component (if any)
for those instants and simulates the state there, so the prediction, the residual frame and
the fit all see the same "model state at the instant the device sampled it".
"""

from __future__ import annotations

from typing import ClassVar

import jax.numpy as jnp
from jaxtyping import Array, Float

from ._base import AbstractEffect, Motion


class AbstractReading(AbstractEffect):
    """A measurement-side component: no torque; it maps the log's timestamps to the instants
    the readings describe (:meth:`sample_times`). A model holds one at most (slot
    ``name = "reading"``), found by this type (:attr:`hdid.Model.reading`)."""

    name: ClassVar[str] = "reading"

    def torque(self, motion: Motion, state: None) -> Float[Array, ""]:
        del motion, state
        return jnp.zeros(())

    def sample_times(self, times: Float[Array, "R T"]) -> Float[Array, "R T"]:
        """The instant [s, the log's clock] whose state reading ``(r, k)`` shows; must be
        non-decreasing along each run and never after ``times``."""
        raise NotImplementedError
