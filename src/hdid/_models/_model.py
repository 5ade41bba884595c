"""A harmonic-drive model: an inertia plus effects whose torques are summed at the WG."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PyTree

from .. import _config  # noqa: F401  (float64)
from ._parameter_set import AbstractParameterSet
from ..effects import (
    AbstractEffect,
    AbstractFriction,
    AbstractReading,
    AbstractSpring,
    CubicStiffness,
    Motion,
    Parameter,
    Scales,
    StribeckFriction,
    ViscousFriction,
)

#: Gear ratio of the CSF-8-100 (and most robot-joint harmonic drives).
DEFAULT_RATIO = 100.0

#: Default total inertia at the wave generator [kg m²]: CSF-8 wave-generator/input
#: inertia ≈ 2.5e-7 (scaled from the CSF-14 catalog value 3.3e-6 kg m²) plus a small
#: Maxon brushless rotor ≈ 4.5e-7 (catalog range 1e-7 … 5e-7). Free motion only fixes
#: torques *relative* to this value; override it with ``inertia=`` / ``--inertia``.
DEFAULT_INERTIA = 7.0e-7

#: CSF-8-100-like starting point (physics notes): least-squares cubic over the catalog's
#: three-segment stiffness; friction from size-8 starting torques.
CATALOG_CSF8 = {
    "k1": 940.0,
    "k2": 6.5e7,
    "tau_c": 3.0e-3,
    "tau_s": 4.5e-3,
    "v_s": 3.0,
    "delta": 1.0,
    "c_v": 2.0e-5,
}

INERTIA_PARAMETER = Parameter(
    "inertia", "kg m^2", "total inertia at the wave generator (gear input + motor rotor)"
)


class Model(AbstractParameterSet):
    """Inertia plus a tuple of effects, ``I·θ̈ = Σ effect torques`` at the wave generator.

    Attributes
    ----------
    effects:
        The physical effects (each an :class:`~hdid.effects.AbstractEffect`).
    inertia:
        Total inertia at the wave generator [kg m²].
    ratio:
        Gear ratio N (static).

    Examples
    --------
    >>> model = Model.default()                       # cubic spring + Stribeck + viscous
    >>> model = model.replace(k1=1000.0, tau_c=2e-3)  # new values, same structure
    >>> model.values()["k1"]
    1000.0
    """

    effects: tuple[AbstractEffect, ...]
    inertia: Float[ArrayLike, ""]
    ratio: float = eqx.field(static=True, default=DEFAULT_RATIO)
    #: Optimiser scales of ``"identity"`` parameters whose declared ``scale`` is a
    #: function of the log (:meth:`with_scales`), as ``((name, power of ten), …)``.
    param_scales: tuple[tuple[str, float], ...] = eqx.field(static=True, default=())

    def __check_init__(self):
        seen: dict[str, str] = {"inertia": "model"}
        names = set()
        for e in self.effects:
            if not isinstance(e, AbstractEffect):
                raise TypeError(
                    f"effects: {e!r} is not an hdid AbstractEffect; subclass "
                    "hdid.AbstractEffect and implement torque()"
                )
            if e.name in names:
                raise ValueError(f"effects: two effects are named {e.name!r}; names must be unique")
            names.add(e.name)
            for p in e.parameters:
                if p.name in seen:
                    raise ValueError(
                        f"effects: parameter {p.name!r} of effect {e.name!r} clashes with "
                        f"{seen[p.name]!r}; rename it"
                    )
                seen[p.name] = e.name

    # -- construction ---------------------------------------------------------------
    @classmethod
    def default(
        cls, inertia: float = DEFAULT_INERTIA, ratio: float = DEFAULT_RATIO, **values: float
    ) -> Model:
        """The base model of the paper (eqs. 4, 5, 10) with CSF-8-100-like values."""
        v = {**CATALOG_CSF8, **values}
        effects = (
            CubicStiffness(k1=v["k1"], k2=v["k2"]),
            StribeckFriction(tau_c=v["tau_c"], tau_s=v["tau_s"], v_s=v["v_s"], delta=v["delta"]),
            ViscousFriction(c_v=v["c_v"]),
        )
        return cls(effects=effects, inertia=inertia, ratio=ratio)

    def with_effect(self, effect: AbstractEffect) -> Model:
        """A model with ``effect`` added (or replacing the effect of the same name)."""
        kept = tuple(e for e in self.effects if e.name != effect.name)
        return Model(effects=kept + (effect,), inertia=self.inertia, ratio=self.ratio,
                     param_scales=self.param_scales)

    def without(self, name: str) -> Model:
        """A model without the effect called ``name``."""
        if name not in self.effect_names:
            raise KeyError(f"no effect named {name!r}; the model has {list(self.effect_names)}")
        kept = tuple(e for e in self.effects if e.name != name)
        return Model(effects=kept, inertia=self.inertia, ratio=self.ratio,
                     param_scales=self.param_scales)

    def with_ratio(self, ratio: float) -> Model:
        """The same model for gear ratio ``ratio`` (1: the logged angle is the output's)."""
        if not (isinstance(ratio, (int, float)) and math.isfinite(ratio) and ratio > 0):
            raise ValueError(f"ratio = {ratio!r}: must be a positive number (1 for no gear)")
        return Model(effects=self.effects, inertia=self.inertia, ratio=float(ratio),
                     param_scales=self.param_scales)

    def with_scales(self, scales: Scales) -> Model:
        """The same model with the optimiser scales of its ``"identity"`` parameters
        resolved from a log's :class:`~hdid.effects.Scales` (see ``Parameter.scale``)."""
        resolved = tuple(
            (p.name, p.resolved(scales).scale)
            for e in self.effects for p in e.parameters if callable(p.scale)
        )
        return Model(effects=self.effects, inertia=self.inertia, ratio=self.ratio,
                     param_scales=resolved)

    @property
    def effect_names(self) -> tuple[str, ...]:
        return tuple(e.name for e in self.effects)

    @property
    def spring(self) -> AbstractSpring | None:
        """The model's spring law (the effect that is an :class:`~hdid.AbstractSpring`),
        or ``None`` (a pendulum, a direct drive with no spring)."""
        return next((e for e in self.effects if isinstance(e, AbstractSpring)), None)

    @property
    def friction(self) -> AbstractFriction | None:
        """The model's dry friction law (the effect that is an
        :class:`~hdid.AbstractFriction`: Stribeck, Coulomb, asymmetric), or ``None``."""
        return next((e for e in self.effects if isinstance(e, AbstractFriction)), None)

    @property
    def reading(self) -> AbstractReading | None:
        """The model's measurement-side component (an :class:`~hdid.effects.AbstractReading`:
        at which instant of the motion each reading was taken, e.g. a sample-and-hold
        device's age), or ``None``: each reading is the state at its timestamp."""
        return next((e for e in self.effects if isinstance(e, AbstractReading)), None)

    def effect(self, name: str) -> AbstractEffect:
        for e in self.effects:
            if e.name == name:
                return e
        raise KeyError(f"no effect named {name!r}; the model has {list(self.effect_names)}")

    # -- parameters -----------------------------------------------------------------
    def parameter_specs(self) -> dict[str, Parameter]:
        """Every parameter declaration by name, effects first, inertia last."""
        over = dict(self.param_scales)
        specs = {}
        for e in self.effects:
            for p in e.parameters:
                if callable(p.scale):
                    p = dataclasses.replace(p, scale=over.get(p.name, 1.0))
                specs[p.name] = p
        specs["inertia"] = INERTIA_PARAMETER
        return specs

    def values(self) -> dict[str, Any]:
        """Parameter values by name (arrays or floats as stored)."""
        out: dict[str, Any] = {}
        for e in self.effects:
            out.update(e.values())
        out["inertia"] = self.inertia
        return out

    def _replaced(self, values: dict[str, ArrayLike]) -> Model:
        effects = []
        for e in self.effects:
            names = [p.name for p in e.parameters if p.name in values]
            if names:
                e = eqx.tree_at(
                    lambda m, names=names: [getattr(m, n) for n in names],
                    e,
                    [values[n] for n in names],
                    is_leaf=lambda x: x is None,
                )
            effects.append(e)
        inertia = values.get("inertia", self.inertia)
        return Model(effects=tuple(effects), inertia=inertia, ratio=self.ratio,
                     param_scales=self.param_scales)

    # -- dynamics -------------------------------------------------------------------
    def init_state(self, theta0: Array) -> tuple[PyTree, ...]:
        return tuple(e.init_state(theta0) for e in self.effects)

    def update_state(self, states, theta_old, theta_new):
        return tuple(
            e.update_state(s, theta_old, theta_new) for e, s in zip(self.effects, states)
        )

    def torque(self, motion: Motion, states) -> Float[Array, ""]:
        """Sum of the effects' torques on the wave generator [N m]."""
        return sum(
            (e.torque(motion, s) for e, s in zip(self.effects, states)), jnp.zeros(())
        )

    def holding_torque(self, motion: Motion, states) -> Float[Array, ""]:
        """Sum of the effects' static capacities [N m]."""
        return sum(
            (e.holding_torque(motion, s) for e, s in zip(self.effects, states)),
            jnp.zeros(()),
        )

    def rest_torque(self, theta: Array, states=None) -> Float[Array, ""]:
        """Net torque at rest at ``theta`` (friction's sliding part is zero at rest)."""
        theta = jnp.asarray(theta, dtype=float)
        if states is None:
            states = self.init_state(theta)
        motion = Motion(theta=theta, omega=jnp.zeros(()), direction=jnp.zeros(()), ratio=self.ratio)
        return self.torque(motion, states)

    def stick_band(self, theta_max: float = 1.0) -> tuple[Array, Array]:
        """Edges ``(lower, upper)`` [rad, WG, from the spring zero] of the stick band.

        The band is where the torque at rest can be held by static friction,
        ``|Σ torque(θ, ω=0)| ≤ Σ holding``. Found by bisection on each side; the result
        is differentiable in the parameters (implicit-function derivative).
        """
        return -_band_edge(self, -1.0, theta_max), _band_edge(self, 1.0, theta_max)

    def stick_band_halfwidth(self, theta_max: float = 1.0) -> Array:
        """Mean half-width of the stick band [rad at the WG]."""
        lo, hi = self.stick_band(theta_max)
        return 0.5 * (hi - lo)

    def derived(self, theta_max: float = 1.0) -> dict[str, Array]:
        """Derived physical quantities (JAX scalars): the stick band, searched within
        ``±theta_max`` (a log's :meth:`~hdid._problems._problem.Problem.band_limit`), the
        small-swing natural frequency, and what each effect declares
        (:meth:`AbstractEffect.derived`: the library's torques per unit inertia and damping
        ratio; a plugin effect's own)."""
        v = self.values()
        inertia = v["inertia"]
        lo, hi = self.stick_band(theta_max)
        out = {"stick_band_halfwidth_rad": 0.5 * (hi - lo), "stick_band_lower_rad": lo,
               "stick_band_upper_rad": hi}
        if "k1" in v:
            k_wg = v["k1"] / self.ratio**2
        else:  # any other restoring law (a gravity pendulum, segments): its slope at zero
            k_wg = -jax.grad(lambda th: self.rest_torque(th))(jnp.zeros(()))
        for effect in self.effects:
            for name, value in effect.derived(inertia, k_wg).items():
                if name in out:
                    raise ValueError(f"{type(effect).__name__}.derived(): {name!r} is already "
                                     "derived by another effect; give it a name of its own")
                out[name] = value
        ok = k_wg > 0
        safe = jnp.where(ok, k_wg, 1.0)
        out["natural_frequency_hz"] = jnp.where(ok, jnp.sqrt(safe / inertia) / (2 * jnp.pi),
                                                jnp.nan)
        return out


def _band_edge(model: Model, side: float, theta_max: float) -> Array:
    """Distance from zero to where the rest torque on ``side`` first exceeds holding."""
    stop = jax.lax.stop_gradient
    frozen = jax.tree_util.tree_map(lambda a: stop(a) if eqx.is_array(a) else a, model)

    def body(_, bracket):
        lo, hi = bracket
        mid = 0.5 * (lo + hi)
        inside = _excess(frozen, side, mid) <= 0
        return jnp.where(inside, mid, lo), jnp.where(inside, hi, mid)

    # The first crossing: a restoring torque that is not monotone (a pendulum's mgl·sin,
    # which falls again past a quarter turn) is back inside the band beyond its peak, where
    # a bisection over [0, theta_max] can land (a 3.4 rad "band" on a drop log); so bisect
    # between the last of 64 points inside the band and the first outside.
    top = jnp.asarray(theta_max, dtype=float)
    xs = jnp.linspace(0.0, top, 65)[1:]
    outside = jax.vmap(lambda x: _excess(frozen, side, x))(xs) > 0
    first = jnp.argmax(outside)
    found = jnp.any(outside)
    hi0 = jnp.where(found, xs[first], top)
    lo0 = jnp.where(found & (first > 0), xs[jnp.maximum(first - 1, 0)], 0.0)
    lo, hi = jax.lax.fori_loop(0, 80, body, (lo0, hi0))
    x_star = stop(0.5 * (lo + hi))
    # One implicit-function Newton correction: value unchanged, derivative correct.
    slope = stop(jax.grad(lambda x: _excess(frozen, side, x))(x_star))
    g = _excess(model, side, x_star)
    return x_star - (g - stop(g)) / slope


def _excess(model: Model, side: float, x):
    """``|rest torque| − holding`` at ``theta = side·x``; negative inside the band."""
    theta = side * x
    states = model.init_state(theta)
    motion = Motion(theta=theta, omega=jnp.zeros(()), direction=jnp.zeros(()), ratio=model.ratio)
    return jnp.abs(model.torque(motion, states)) - model.holding_torque(motion, states)
