"""The effect interface: one physical effect = one small equinox module.

Every effect contributes a torque acting on the wave generator (WG); the model sums them,
like diffrax's ``MultiTerm`` sums terms. Friction-like effects additionally say how much
torque they can *hold* at rest, which is what makes the simulator stick exactly.
"""

from __future__ import annotations

import abc
import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, ClassVar, NamedTuple

import equinox as eqx
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float, PyTree


@dataclass(frozen=True)
class Scales:
    """Magnitudes of one log, in the log's own units, from which starting values,
    optimiser scales and weak priors are derived (no constant may encode one gear's size).

    Attributes
    ----------
    ratio:
        Gear ratio N (1: the logged angle is the output's, no gear).
    inertia:
        Inertia at the logged axis (the wave generator) [kg m²], assumed or known.
    k_wg:
        Small-swing restoring stiffness at the logged axis [N m/rad], ``inertia·ω_n²``
        with ω_n from the log (zero crossings, spectrum) or a grid around it.
    amplitude:
        Typical release (or initial) amplitude at the logged axis [rad] from its rest.
    speed:
        Typical peak speed at the logged axis [rad/s].
    torque:
        Typical friction torque at the logged axis [N m] (from the amplitude decay, or a
        fraction of ``k_wg·amplitude``).
    band:
        Largest distance of a logged rest point from the zero [rad] (0 if none).
    """

    ratio: float
    inertia: float
    k_wg: float
    amplitude: float
    speed: float
    torque: float
    band: float = 0.0

    @property
    def k_out(self) -> float:
        """Restoring stiffness seen at the output, ``k_wg·N²`` [N m/rad]."""
        return self.k_wg * self.ratio**2

    @property
    def twist(self) -> float:
        """Typical output twist, ``amplitude / N`` [rad]."""
        return self.amplitude / self.ratio

    @property
    def c_crit(self) -> float:
        """Critical viscous damping at the logged axis, ``2·sqrt(k_wg·inertia)`` [N m s/rad]."""
        return 2.0 * math.sqrt(self.k_wg * self.inertia)

    @property
    def frequency_hz(self) -> float:
        """Small-swing natural frequency ``sqrt(k_wg/inertia)/2π`` [Hz]."""
        return math.sqrt(self.k_wg / self.inertia) / (2.0 * math.pi)


def order_of_magnitude(x: float) -> float:
    """``x`` rounded to a power of ten (scales that differ by less share compiled programs)."""
    x = abs(float(x))
    if not math.isfinite(x) or x == 0.0:
        return 1.0
    return 10.0 ** round(math.log10(x))


#: sd in log of a :class:`ScalePrior` (the posterior's default prior of a positive
#: scale): its central 95 % spans ``exp(±1.96·1.2)`` = a factor 10.5 on each side of the
#: log's scale (issue 34: at least 10).
SCALE_PRIOR_SD = 1.2


@dataclass(frozen=True)
class ScalePrior:
    """The posterior's default prior of one parameter (``AbstractEffect.posterior_prior``):
    Gaussian in the parameter's transformed space — log-normal for a positive (``"log"``)
    parameter — with median ``centre(scales)``, a scale of the log in hand
    (:class:`Scales`, in its own units: no constant encodes one gear's size), and ``sd``
    in that space (default ``SCALE_PRIOR_SD``: a factor 10.5 either way at 95 %).
    ``source`` says in words where the scale comes from (shown in the report and JSON).

    Example: a cubic spring coefficient centred where the cubic term equals the linear
    one at the log's release twist::

        posterior_prior = {"k2": ScalePrior(lambda s: s.k_out / s.twist**2,
                                            "k1/θ²: cubic = linear torque at the release twist")}
    """

    centre: Callable[[Scales], float]
    source: str
    sd: float = SCALE_PRIOR_SD


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
        flat. A mean of ``None`` centres the prior on the transformed :attr:`start` of the
        log at hand (a scale-free prior, e.g. a Stribeck velocity relative to the log's
        speeds). Used to regularise parameters the data cannot fix (stated in the report).
    scale:
        Typical magnitude of an ``"identity"`` parameter: the optimiser sees
        ``value / scale``, so that its steps are of order one. A number, or a function of
        the log's :class:`Scales` (e.g. ``lambda s: s.torque`` for a torque), resolved
        per log to a power of ten. Ignored by the other transforms, which are scale-free.
    start:
        Starting value from the log's :class:`Scales` (e.g. ``lambda s: s.k_out`` for a
        linear stiffness at the output, ``lambda s: 0.1 * s.k_out / s.twist**2`` for a
        cubic one); ``None``: the model's current value. This is how every library effect
        starts on a log of any gear size and in any consistent units.
    flat_in_value:
        The posterior's default flat prior on a ``"log"`` parameter is flat in its *value*,
        not its log: for coefficients of terms that may vanish (``k2``, ``tau_c``, ``c_v``),
        whose "absent" end a log-flat prior would give an unbounded volume.
    sample_in_value:
        The posterior samples a ``"log"`` parameter in its value (relative to the
        least-squares one): for the terms of sums the data fix as straight lines
        (``k1·d + k2·d³``, ``τ_c + c_v·v``), bananas in their logs. Changes the mixing,
        not the posterior (the density carries the Jacobian).
    """

    name: str
    unit: str
    doc: str
    transform: str | tuple[str, float, float] = "log"
    prior: tuple[float | None, float] | None = None
    scale: float | Callable[[Scales], float] = 1.0
    start: Callable[[Scales], float] | None = None
    flat_in_value: bool = False
    sample_in_value: bool = False

    def resolved(self, scales: Scales | None) -> Parameter:
        """This declaration with a callable :attr:`scale` evaluated on ``scales``
        (rounded to a power of ten; 1 without scales)."""
        if not callable(self.scale):
            return self
        value = order_of_magnitude(self.scale(scales)) if scales is not None else 1.0
        return dataclasses.replace(self, scale=value)


#: Key of a field's metadata that makes it a declared parameter (:func:`parameter`).
PARAMETER_METADATA = "hdid_parameter"


def parameter(unit: str, doc: str, *, transform: str | tuple[str, float, float] = "log",
              prior: tuple[float | None, float] | None = None,
              scale: float | Callable[[Scales], float] = 1.0,
              start: Callable[[Scales], float] | None = None,
              flat_in_value: bool = False, sample_in_value: bool = False):
    """Declare an effect's physical parameter once, as the field that holds its value::

        c_v: Float[ArrayLike, ""] = parameter("N m s/rad", "viscous coefficient",
                                              start=lambda s: 0.05 * s.c_crit)

    The arguments are those of :class:`Parameter` (its ``name`` is the field's); the
    effect's ``parameters`` are collected from these fields, in their order.
    """
    meta = dict(unit=unit, doc=doc, transform=transform, prior=prior, scale=scale, start=start,
                flat_in_value=flat_in_value, sample_in_value=sample_in_value)
    return eqx.field(metadata={PARAMETER_METADATA: meta})


def same_parameter(effect: type, name: str):
    """The declaration of another effect's parameter ``name``, reused (a backlash spring
    shares the cubic spring's ``k1`` and ``k2``: the same unit, doc, transform and start)."""
    p = next((p for p in effect.parameters if p.name == name), None)
    if p is None:
        raise TypeError(f"{effect.__name__} declares no parameter {name!r}")
    return parameter(p.unit, p.doc, transform=p.transform, prior=p.prior, scale=p.scale,
                     start=p.start, flat_in_value=p.flat_in_value,
                     sample_in_value=p.sample_in_value)


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


class StartValues(NamedTuple):
    """Starting values that several library effects share, from a model's values (a
    fitted one's, or the defaults): the spring, the Stribeck law, the small-swing
    stiffness at the logged axis (``_k_wg``, as the caller measured it; ``k1/N²`` with
    N = 100 only as a last resort)."""

    k1: float
    k2: float
    tau_c: float
    tau_s: float
    k_wg: float
    stribeck: dict

    @classmethod
    def of(cls, v: dict[str, float]) -> StartValues:
        k1 = v.get("k1", v.get("K1", 940.0))
        tau_c, tau_s = v.get("tau_c", 3e-3), v.get("tau_s", 4.5e-3)
        return cls(k1=k1, k2=v.get("k2", 6.5e7), tau_c=tau_c, tau_s=tau_s,
                   k_wg=v.get("_k_wg", k1 / 1e4),
                   stribeck=dict(tau_c=tau_c, tau_s=tau_s, v_s=v.get("v_s", 3.0),
                                 delta=v.get("delta", 1.0)))


class AbstractEffect(eqx.Module):
    """A physical effect acting on the wave generator.

    Subclasses declare each parameter once, as a field made by :func:`parameter` (its
    unit, doc, transform, prior and start; the class variable ``parameters`` is collected
    from these fields), give themselves a ``name`` (the slot it fills: an effect of the same
    name replaces it) and implement :meth:`torque`. (An effect may instead list
    ``parameters`` itself, as :class:`Parameter` objects named like its fields.) Friction-like effects also implement
    :meth:`holding_torque`; effects with memory (hysteresis elements, friction state)
    implement :meth:`init_state` / :meth:`update_state`.

    A user-defined effect is one file::

        class Cogging(hdid.AbstractEffect):
            amplitude: float | jax.Array = hdid.effects.parameter(
                "N m", "cogging torque", transform="identity", scale=1e-3)
            name: ClassVar[str] = "cogging"
            def torque(self, motion, state):
                return -self.amplitude * jnp.sin(24 * motion.theta)
    """

    name: eqx.AbstractClassVar[str]
    parameters: eqx.AbstractClassVar[tuple[Parameter, ...]]
    #: The ``--add`` name of a library or plugin effect: its module's file stem (or its
    #: ``hdid.effects`` entry point's name). ``None``: not offered by ``--add``.
    key: ClassVar[str | None] = None
    #: Pairs ``(a, b)`` of this effect's parameters with ``a ≤ b`` imposed by the
    #: posterior's prior (zero density otherwise), e.g. breakaway at least Coulomb friction.
    ordered: ClassVar[tuple[tuple[str, str], ...]] = ()
    #: The posterior's default priors of this effect's parameters: ``{name: ScalePrior}``
    #: (a log-normal around a scale of the log, :class:`ScalePrior`) or ``{name: (centre
    #: value, sd in the transformed space)}`` (a centre of ``None`` is the log's own start,
    #: as :attr:`Parameter.prior`). They replace the least-squares weak prior rows of those
    #: parameters in the posterior only; a positive parameter an effect leaves out gets a
    #: log-normal around its ``start`` rule (``hdid._posterior.priors``).
    posterior_prior: ClassVar[dict[str, Any]] = {}
    #: How ``hdid diagnose`` tries this effect (:class:`hdid.effects.Candidate`: trial
    #: order, starting values, scanned orders, residual mark, separating experiment);
    #: ``None``: not tried.
    candidate: ClassVar[Any] = None

    def __init_subclass__(cls, **kwargs):
        super().__init_subclass__(**kwargs)
        own = tuple(
            Parameter(name, **f.metadata[PARAMETER_METADATA]) for name, f in vars(cls).items()
            if isinstance(f, dataclasses.Field) and PARAMETER_METADATA in f.metadata)
        if own and "parameters" in vars(cls):
            raise TypeError(f"{cls.__name__}: declare each parameter once, as a field made by "
                            "hdid.effects.parameter(); drop the `parameters` class variable")
        if own:
            cls.parameters = own
            # a class variable, not a field (an annotation object: dataclasses then need
            # not resolve a string annotation in the effect's own module)
            cls.__annotations__["parameters"] = ClassVar[tuple]

    @classmethod
    def start_from(cls, values: dict[str, float]) -> AbstractEffect:
        """This effect with starting values from ``values`` (a fitted or default model's
        parameter values; see :func:`hdid.effects.library`). Library effects define it."""
        raise NotImplementedError(
            f"{cls.__name__}: define start_from(values) to offer it as `--add {cls.key}`")

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

    def derived(self, inertia: Array, k_wg: Array) -> dict[str, Array]:
        """Quantities this effect adds to a fit's derived table (``result.derived``, the
        posterior's and the batch summary's), as JAX scalars computed from its parameters
        and differentiable in them: their standard errors follow by the delta method.

        ``inertia`` [kg m²] is the model's; ``k_wg`` [N m/rad] its small-swing restoring
        stiffness at the logged axis (≤ 0 where there is none). Default: nothing.
        """
        del inertia, k_wg
        return {}

    def values(self) -> dict[str, Any]:
        """Current parameter values by name."""
        return {p.name: getattr(self, p.name) for p in self.parameters}


class AbstractSpring(AbstractEffect):
    """A torsional spring law: the restoring torque of the flexspline's twist.

    A model holds one spring at most: every spring fills the slot ``name = "stiffness"``,
    so adding one (``--add backlash``) replaces the model's. Code that needs *the* spring
    finds it by this type (:attr:`hdid.Model.spring`), never by a name: the driven joint
    reads the output twist through it, and it must then be memoryless
    (``init_state`` returns ``None``). Subclasses implement :meth:`torque` (at the WG, as
    every effect) and may offer ``spring_torque(twist)`` at the output.
    """

    name: ClassVar[str] = "stiffness"


class AbstractFriction(AbstractEffect):
    """A dry friction law at the wave generator: a sliding torque (:meth:`torque`) and the
    torque it can hold at rest (:meth:`holding_torque`, which makes the simulator stick).

    A model holds one at most: every friction law fills the slot ``name = "stribeck"``
    (the historic name, kept so that saved fits and JSON read back), so adding one
    (``--add coulomb``) replaces the model's. Code that needs *the* friction law finds it
    by this type (:attr:`hdid.Model.friction`), never by a name. Velocity-proportional
    (viscous) and load-dependent terms are separate effects that add to it.
    """

    name: ClassVar[str] = "stribeck"


def positive_power(x: Array, exponent: Array) -> Array:
    """``x ** exponent`` for ``x >= 0`` with finite derivatives at ``x == 0`` (double-where)."""
    safe = jnp.where(x > 0, x, 1.0)
    return jnp.where(x > 0, jnp.exp(exponent * jnp.log(safe)), 0.0)
