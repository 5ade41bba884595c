"""Positional (pure kinematic) error of the gear: a Fourier series in the motor angle."""

from __future__ import annotations

import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._parameter_set import AbstractParameterSet
from ..effects import Parameter

#: Typical size of a positional-error coefficient [rad, output side]: the physics notes
#: give ≤ 5.8e-4 rad peak-to-peak per revolution for a size-8 gear.
COEFFICIENT_SCALE = 1e-4


class PositionalError(AbstractParameterSet):
    r"""Paper eq. 3: ``θ̃_p(θ) = a0/2 + Σ_{n=1..K} a_n cos(nθ) + b_n sin(nθ)``.

    ``θ`` is the wave-generator (motor) angle as logged, in the motor encoder's frame;
    the error is added to the output angle [rad, output side]. ``a0`` also absorbs the
    zero of the output encoder relative to the motor encoder. The order ``K`` is the
    length of ``a`` and ``b`` (static: a new order is a new structure).

    The free-motion test locks the output, which suppresses this error (paper, Sec. IV):
    only a driven (input/output) log can identify it.
    """

    a0: Float[ArrayLike, ""]
    a: Float[Array, " K"]
    b: Float[Array, " K"]

    def __init__(self, a0=0.0, a=(), b=()):
        self.a0 = jnp.asarray(a0, dtype=float)
        self.a = jnp.asarray(a, dtype=float).reshape(-1)
        self.b = jnp.asarray(b, dtype=float).reshape(-1)
        if self.a.shape != self.b.shape:
            raise ValueError(
                f"PositionalError: a has {self.a.shape[0]} and b {self.b.shape[0]} "
                "coefficients; give one a_n and one b_n per harmonic"
            )

    @classmethod
    def zeros(cls, order: int) -> PositionalError:
        if order < 0:
            raise ValueError(f"order = {order}: must be >= 0")
        return cls(0.0, jnp.zeros(order), jnp.zeros(order))

    @property
    def order(self) -> int:
        return int(self.a.shape[0])

    def __call__(self, theta: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        theta = jnp.asarray(theta, dtype=float)
        n = jnp.arange(1, self.order + 1, dtype=float)
        phase = theta[..., None] * n
        return 0.5 * self.a0 + jnp.sum(self.a * jnp.cos(phase) + self.b * jnp.sin(phase), -1)

    # -- parameters by name (pos_a0, pos_a1 … pos_aK, pos_b1 … pos_bK) ----------------
    def names(self) -> tuple[str, ...]:
        K = self.order
        return ("pos_a0",) + tuple(f"pos_a{n}" for n in range(1, K + 1)) + tuple(
            f"pos_b{n}" for n in range(1, K + 1)
        )

    def parameter_specs(self) -> dict[str, Parameter]:
        out = {}
        for name in self.names():
            kind, n = name[4], name[5:]
            what = {"a": "cosine", "b": "sine"}[kind]
            doc = (
                "positional error: twice its mean (with the output encoder's zero), output side"
                if name == "pos_a0"
                else f"positional error: {what} coefficient of harmonic {n} of the motor angle"
            )
            out[name] = Parameter(name, "rad", doc, transform="identity", scale=COEFFICIENT_SCALE)
        return out

    def values(self) -> dict[str, Array]:
        out = {"pos_a0": self.a0}
        for n in range(1, self.order + 1):
            out[f"pos_a{n}"] = self.a[n - 1]
        for n in range(1, self.order + 1):
            out[f"pos_b{n}"] = self.b[n - 1]
        return out

    def _replaced(self, values) -> PositionalError:
        a0 = values.get("pos_a0", self.a0)
        a = jnp.stack([jnp.asarray(values.get(f"pos_a{n}", self.a[n - 1]), dtype=float)
                       for n in range(1, self.order + 1)]) if self.order else self.a
        b = jnp.stack([jnp.asarray(values.get(f"pos_b{n}", self.b[n - 1]), dtype=float)
                       for n in range(1, self.order + 1)]) if self.order else self.b
        return PositionalError(a0, a, b)

    def peak_to_peak(self, n_points: int = 2048) -> Array:
        """Peak-to-peak of the periodic part over one motor revolution [rad]."""
        theta = jnp.linspace(0.0, 2 * jnp.pi, n_points, endpoint=False)
        e = self(theta)
        return jnp.max(e) - jnp.min(e)
