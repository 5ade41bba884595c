"""The driven joint (paper eqs. 3, 7–9): motor torque in, wave-generator and output angles out.

In normal operation the motor torque ``τ_d(t)`` drives the wave generator (WG); a load
torque ``τ_l`` and the output friction ``τ_fout`` act on the flexspline's output end,
which is quasi-static (the paper neglects the output inertia), so the spring carries
exactly ``τ_l + τ_fout``:

* WG, eq. 9:  ``I θ̈ = τ_d(t) − (τ_l(t) + τ_fout)/N − τ_din(θ̇)``, where ``τ_din`` is the
  sum of the model's WG effects other than the spring (Stribeck, viscous, ripple, …);
* output, eq. 8:  ``θ_out = −θ/N + T_k⁻¹(τ_l + τ_fout) + θ̃_p(θ)``, with ``T_k`` the
  model's stiffness law and ``θ̃_p`` the positional error (eq. 3).

Conventions (shared with the independent reference, ``hdid.reference.logs.simulate_driven``):

* ``τ_d`` is held from each sample to the next (``input_hold="zoh"``, zero-order hold:
  a digital drive's command, held by its DAC or PWM until the next), or interpolated
  linearly between samples (``input_hold="foh"``, first-order hold: a sampled analog
  signal such as a measured motor current); ``τ_l`` is interpolated linearly (a
  measured signal).
* ``τ_fout = tau_fout·s``: while the WG slides, ``s`` is its sliding direction (the output
  turns the other way, so the friction opposes it); at rest the output friction keeps
  its last sliding value (the flexspline stays wound; ``s = 0`` before the first motion).
* The WG sticks when ``|τ_d − τ_l/N| ≤ Σ holding + tau_fout/N`` (both static
  capacities) and breaks away, in the direction of the net torque, at the instant it
  exceeds them — found inside the substep (``τ_l`` is linear there), so the breakaway
  time is a smooth function of the parameters.

Sliding is integrated like the free-motion simulator (:mod:`hdid._simulation._simulate`): fixed
RK4 substeps with the friction direction frozen, a step in which the velocity crosses
zero split at the crossing.
"""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .. import _config  # noqa: F401
from .._models._model import Model
from .._models._parameter_set import AbstractParameterSet
from .._models._positional import PositionalError
from ._simulate import DEFAULT_MAX_SUBSTEP, _safe_div, crossing_fraction, known_value, rk4
from ..effects import AbstractSpring, Motion, Parameter

TAU_FOUT_PARAMETER = Parameter(
    "tau_fout", "N m", "Coulomb friction at the output (bearing + load side), output side"
)
#: Largest output twist the inversion of ``T_k`` searches [rad]: ~100× the catalog
#: twist of a size-8 gear at its rated torque, so every physical torque is inside.
MAX_TWIST = 0.2


class DrivenJoint(AbstractParameterSet):
    """A harmonic drive in normal operation: WG model, output friction, positional error.

    Attributes
    ----------
    model:
        The :class:`~hdid.Model` of the WG side; its spring (:attr:`Model.spring`, an
        :class:`~hdid.AbstractSpring`) is the law ``T_k`` used for the output twist, its
        other effects act on the WG.
    tau_fout:
        Coulomb friction torque at the output [N m, output side].
    positional:
        The positional error :class:`PositionalError` (order 0 = a constant only).
    """

    model: Model
    tau_fout: Float[ArrayLike, ""]
    positional: PositionalError

    def __check_init__(self):
        stiff = self.model.spring
        if stiff is None:
            raise ValueError(
                "model: a driven joint needs a spring law (an hdid.AbstractSpring effect) "
                f"for the output twist; the model has {list(self.model.effect_names)}"
            )
        if stiff.init_state(jnp.zeros(())) is not None:
            raise ValueError(
                f"model: the stiffness law {type(stiff).__name__} has memory; the driven "
                "output angle needs a memoryless spring T_k(d) to invert"
            )

    @classmethod
    def default(cls, model: Model | None = None, order: int = 2, tau_fout: float = 0.05):
        return cls(Model.default() if model is None else model, tau_fout, PositionalError.zeros(order))

    @property
    def ratio(self) -> float:
        return self.model.ratio

    # -- parameters -----------------------------------------------------------------
    def parameter_specs(self) -> dict[str, Parameter]:
        return {**self.model.parameter_specs(), "tau_fout": TAU_FOUT_PARAMETER,
                **self.positional.parameter_specs()}

    def values(self) -> dict:
        return {**self.model.values(), "tau_fout": self.tau_fout, **self.positional.values()}

    def _replaced(self, values) -> DrivenJoint:
        model_names = set(self.model.parameter_specs())
        pos_names = set(self.positional.names())
        mv = {k: v for k, v in values.items() if k in model_names}
        pv = {k: v for k, v in values.items() if k in pos_names}
        return DrivenJoint(
            self.model.replace(**mv) if mv else self.model,
            values.get("tau_fout", self.tau_fout),
            self.positional.replace(**pv) if pv else self.positional,
        )

    def with_order(self, order: int) -> DrivenJoint:
        """The same joint with a positional error of ``order`` harmonics (kept ones kept)."""
        old = self.positional
        k = min(order, old.order)
        a = jnp.zeros(order).at[:k].set(old.a[:k])
        b = jnp.zeros(order).at[:k].set(old.b[:k])
        return DrivenJoint(self.model, self.tau_fout, PositionalError(old.a0, a, b))

    # -- physics ----------------------------------------------------------------------
    @property
    def spring(self) -> AbstractSpring:
        return self.model.spring

    @property
    def wg_model(self) -> Model:
        """The WG-side effects: every effect but the spring (eq. 9's ``τ_din``)."""
        return self.model.without(self.spring.name)

    def spring_torque(self, twist: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """``T_k(d)`` [N m, output side] at output twist ``d`` [rad]."""
        N = self.ratio
        spring = self.spring

        def one(d):
            m = Motion(theta=N * d, omega=jnp.zeros(()), direction=jnp.zeros(()), ratio=N)
            return -N * spring.torque(m, None)

        d = jnp.asarray(twist, dtype=float)
        return jnp.vectorize(one)(d)

    def twist(self, torque: Float[ArrayLike, "..."]) -> Float[Array, "..."]:
        """``T_k⁻¹(τ)`` [rad]: bisection for the value, one implicit-function Newton step
        for the derivatives (exact for any monotone spring law)."""
        torque = jnp.asarray(torque, dtype=float)
        stop = jax.lax.stop_gradient
        frozen = jax.tree_util.tree_map(lambda a: stop(a) if eqx.is_array(a) else a, self)

        def one(tau):
            tau_s = stop(tau)

            def body(_, br):
                lo, hi = br
                mid = 0.5 * (lo + hi)
                below = frozen.spring_torque(mid) < tau_s
                return jnp.where(below, mid, lo), jnp.where(below, hi, mid)

            lo, hi = jax.lax.fori_loop(
                0, 64, body, (jnp.asarray(-MAX_TWIST), jnp.asarray(MAX_TWIST))
            )
            d_star = stop(0.5 * (lo + hi))
            slope = stop(jax.grad(frozen.spring_torque)(d_star))
            g = self.spring_torque(d_star) - tau
            return d_star - (g - stop(g)) / slope

        return jnp.vectorize(one)(torque)

    def kinematic_error(self, theta, load_torque, direction) -> Float[Array, "..."]:
        """Output kinematic error ``θ_out + θ/N`` = flexibility + positional parts [rad]."""
        return self.flexibility_error(load_torque, direction) + self.positional(theta)

    def flexibility_error(self, load_torque, direction) -> Float[Array, "..."]:
        """``T_k⁻¹(τ_l + τ_fout·s)`` [rad]: the twist the load and output friction cause."""
        return self.twist(jnp.asarray(load_torque) + self.tau_fout * jnp.asarray(direction))

    def output_angle(self, theta, load_torque, direction) -> Float[Array, "..."]:
        """Eq. 8: ``θ_out = −θ/N + T_k⁻¹(τ_l + τ_fout) + θ̃_p(θ)`` [rad]."""
        return -jnp.asarray(theta) / self.ratio + self.kinematic_error(theta, load_torque, direction)


# ----------------------------------------------------------------------------- simulator


def _substep(joint: DrivenJoint, wg: Model, inertia, ext0, ext_rate, carry, t, h):
    """One substep of length ``h`` starting at local time ``t`` of the sample interval.

    ``ext(t) = ext0 + ext_rate·t`` is the external torque at the WG, ``τ_d − τ_l(t)/N``.
    """
    theta, omega, direction, s_last, states = carry
    N = joint.ratio
    f_out = joint.tau_fout / N

    def accel_dir(d):
        def f(th, om, tt):
            m = Motion(theta=th, omega=om, direction=d, ratio=N)
            return (wg.torque(m, states) + ext0 + ext_rate * tt - f_out * d) / inertia

        return f

    def rest_net(th, tt):
        m = Motion(theta=th, omega=jnp.zeros(()), direction=jnp.zeros(()), ratio=N)
        return wg.torque(m, states) + ext0 + ext_rate * tt, wg.holding_torque(m, states) + f_out

    sliding = direction != 0
    theta1, omega1, acc0 = rk4(accel_dir(direction), theta, omega, t, h)

    # -- sliding: does the velocity cross zero inside the substep? ----------------------
    crossed = sliding & (direction * omega1 <= 0) & (omega1 != omega)
    alpha = crossing_fraction(omega, omega1, acc0, h, crossed)
    theta_a, omega_a, _ = rk4(accel_dir(direction), theta, omega, t, alpha * h)
    acc_stop = accel_dir(direction)(theta_a, omega_a, t + alpha * h)
    dt_gap = _safe_div(-omega_a, acc_stop, crossed & (acc_stop != 0))
    theta_cross = theta_a + 0.5 * omega_a * dt_gap
    alpha = jnp.where(crossed, jnp.clip(alpha + dt_gap / h, 0.0, 1.0), alpha)
    net_c, hold_c = rest_net(theta_cross, t + alpha * h)
    stick_c = jnp.abs(net_c) <= hold_c

    # -- stuck: does the net torque exceed the capacity inside the substep? -------------
    net0, hold0 = rest_net(theta, t)
    net1, hold1 = rest_net(theta, t + h)
    e0 = jnp.abs(net0) - hold0
    e1 = jnp.abs(net1) - hold1
    break0 = e0 > 0
    break1 = ~break0 & (e1 > 0)
    beta = jnp.where(break1, jnp.clip(_safe_div(e0, e0 - e1, break1), 0.0, 1.0), 0.0)
    dir_break = jnp.where(break0, jnp.sign(net0), jnp.sign(net1))

    # -- one RK4 from rest for whichever branch starts sliding from rest --------------
    from_cross = crossed & ~stick_c
    from_stuck = ~sliding & (break0 | break1)
    frac = jnp.where(crossed, alpha, beta)
    theta_r = jnp.where(crossed, theta_cross, theta)
    dir_r = jnp.where(crossed, jnp.sign(net_c), dir_break)
    theta2, omega2, _ = rk4(accel_dir(dir_r), theta_r, jnp.zeros(()), t + frac * h, (1.0 - frac) * h)

    go = from_cross | from_stuck
    theta_n = jnp.where(go, theta2, jnp.where(crossed, theta_cross, jnp.where(sliding, theta1, theta)))
    omega_n = jnp.where(go, omega2, jnp.where(crossed | ~sliding, 0.0, omega1))
    dir_n = jnp.where(go, dir_r, jnp.where(crossed | ~sliding, 0.0, direction))
    s_n = jnp.where(dir_n != 0, dir_n, s_last)
    states_n = wg.update_state(states, theta, theta_n)
    return theta_n, omega_n, dir_n, s_n, states_n


def substeps_for_times(times, max_substep: float | None = None) -> int:
    """Substeps per sample interval so that none is longer than ``max_substep``."""
    h_max = DEFAULT_MAX_SUBSTEP if max_substep is None else max_substep
    dt = np.diff(np.asarray(times, dtype=float), axis=-1)
    longest = float(np.max(dt)) if dt.size else 0.0
    return max(1, math.ceil(longest / h_max - 1e-9))


def simulate_driven(
    joint: DrivenJoint,
    times: Float[ArrayLike, " T"],
    motor_torque: Float[ArrayLike, " T"],
    load_torque: Float[ArrayLike, " T"] | None = None,
    theta0: Float[ArrayLike, ""] = 0.0,
    omega0: Float[ArrayLike, ""] = 0.0,
    *,
    output_direction0: Float[ArrayLike, ""] = 0.0,
    substeps: int | None = None,
    max_substep: float | None = None,
    full_output: bool = False,
    input_hold: str = "zoh",
):
    """WG angle (and, with ``full_output``, the rest) of a driven run at ``times``.

    Parameters
    ----------
    joint:
        The :class:`DrivenJoint`.
    times:
        Sample times [s], increasing; the state at ``times[0]`` is ``(theta0, omega0)``.
    motor_torque:
        Motor torque at the WG [N m] per sample (held or interpolated: ``input_hold``).
    load_torque:
        External torque on the output [N m] per sample, linear between samples (default 0).
    theta0, omega0:
        WG angle [rad] and velocity [rad/s] at ``times[0]``.
    output_direction0:
        Sign of the output friction at ``times[0]`` when the WG starts at rest there
        (the direction it last slid in; 0: never moved). Ignored when ``omega0 != 0``.
    substeps:
        RK4 substeps per sample interval (static); default from ``max_substep``
        (0.5 ms), which needs concrete ``times``.
    input_hold:
        ``"zoh"``: the motor torque is held from each sample to the next (a command);
        ``"foh"``: it is interpolated linearly between samples (a sampled analog signal).
    full_output:
        Return a dict with ``theta``, ``omega``, ``direction`` (0 while stuck),
        ``output_direction`` (the output friction's sign ``s``), ``theta_out`` (eq. 8).
    """
    times = jnp.asarray(times, dtype=float)
    tau_d = jnp.asarray(motor_torque, dtype=float)
    tau_l = jnp.zeros_like(times) if load_torque is None else jnp.asarray(load_torque, dtype=float)
    if substeps is None:
        substeps = substeps_for_times(times, max_substep)
    model = joint.model
    known = known_value(model.inertia)
    if known is not None and not np.all(known > 0):
        raise ValueError(f"inertia = {float(known)}: must be > 0 kg m^2")
    inertia = jnp.asarray(model.inertia, dtype=float)
    wg = joint.wg_model
    N = joint.ratio
    theta0 = jnp.asarray(theta0, dtype=float)
    omega0 = jnp.asarray(omega0, dtype=float)

    if input_hold not in ("zoh", "foh"):
        raise ValueError(f"input_hold = {input_hold!r}: must be 'zoh' (held) or 'foh' (linear)")
    dts = jnp.diff(times)
    ext0 = tau_d[:-1] - tau_l[:-1] / N
    rate = -_safe_div(jnp.diff(tau_l), dts, dts > 0) / N
    if input_hold == "foh":
        rate = rate + _safe_div(jnp.diff(tau_d), dts, dts > 0)

    def interval(carry, xs):
        dt, e0, er = xs
        h = dt / substeps

        def sub(i, c):
            return _substep(joint, wg, inertia, e0, er, c, i * h, h)

        carry = jax.lax.fori_loop(0, substeps, sub, carry)
        theta, omega, direction, s_last, _ = carry
        return carry, (theta, omega, direction, s_last)

    d0 = jnp.sign(omega0)
    s0 = jnp.where(d0 != 0, d0, jnp.asarray(output_direction0, dtype=float))
    carry0 = (theta0, omega0, d0, s0, wg.init_state(theta0))
    _, (th, om, di, sl) = jax.lax.scan(interval, carry0, (dts, ext0, rate))
    theta = jnp.concatenate([theta0[None], th])
    if not full_output:
        return theta
    omega = jnp.concatenate([omega0[None], om])
    direction = jnp.concatenate([d0[None], di])
    s_last = jnp.concatenate([s0[None], sl])
    return {
        "theta": theta,
        "omega": omega,
        "direction": direction,
        "output_direction": s_last,
        "theta_out": joint.output_angle(theta, tau_l, s_last),
    }
