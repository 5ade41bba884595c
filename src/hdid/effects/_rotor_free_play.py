"""A motor rotor behind the gear's free play: a second inertia with its own angle and speed.

Private (not an ``--add`` effect): hdid's simulator advances an effect's state by the
arm's angle alone (``update_state(state, θ_old, θ_new)``: no time step, no speed), and it
ends a run once the arm sticks ("effect state changes only when θ moves"). A rotor is a
second body that moves in time on its own, also while the arm rests. To offer it as an
effect the simulator would need an ODE-state hook: ``x0 = init_state(θ0)`` and
``ẋ = state_derivative(motion, x)`` integrated in the same RK4 stages as ``(θ, ω)``
(``_simulation/_simulate._rk4`` and ``_driven``), a stick test that holds the arm while
the rotor may still move, and a loop that runs until both rest. This module writes the
effect against that hook (:meth:`RotorFreePlay.state_derivative`) and carries its own
fixed-step simulator of a drop (:func:`simulate_drops`) to test it on logs.
"""

from __future__ import annotations

import math
from typing import ClassVar

import equinox as eqx
import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from ._base import AbstractEffect, Motion, parameter

#: Contact (tooth) stiffness as a natural frequency of the rotor on it [Hz]: far above a
#: drop's swing (≈ 1 Hz) and the 100 Hz readings, low enough for RK4 at 0.25 ms.
CONTACT_HZ = 150.0
#: Damping ratio of the contact: 1 = a tooth impact that keeps (almost) no rebound.
CONTACT_ZETA = 1.0
#: Speed [rad/s] over which the dry frictions turn (``tanh(ω/ε)``): below the 0.05 rad/s
#: at which a reading moves; a drop's arm is fitted only until it rests.
SMOOTH_SPEED = 0.01


class RotorFreePlay(AbstractEffect):
    r"""The motor's rotor (inertia ``j_r`` at the output) coupled to the arm through the
    gear's free play ``backlash`` (total, output side), with its own dry friction ``tau_r``.

    States: ``z = φ − θ`` (rotor minus arm angle, output side) [rad] and the rotor's speed
    ``ψ`` [rad/s]. The teeth touch where ``|z| ≥ b/2``; the contact pushes with
    ``f = max(k_c·p + c_c·sign(z)·ż, 0)``, ``p = |z| − b/2``, ``k_c = μ·(2π·CONTACT_HZ)²``,
    ``c_c = 2·CONTACT_ZETA·μ·2π·CONTACT_HZ`` (μ the two bodies' reduced inertia):

        torque on the arm        ``sign(z)·f``
        J_r·ψ̇ = −sign(z)·f − tau_r·tanh(ψ/ε),   ż = ψ − ω.

    The arm's inertia in the model is the rest, ``I − j_r``. At release the rotor rests on
    the flank that held the arm (``z = sign(θ0)·b/2``). Rigid teeth (``b = 0``) make one
    inertia ``I`` with the extra friction ``tau_r``.

    What it does in a drop: while gravity speeds the arm up the arm drives the rotor (full
    inertia). Past the bottom the arm decelerates; once that deceleration exceeds the
    rotor's own, ``tau_r/j_r``, the rotor leaves the flank, crosses the gap, and meanwhile
    the arm decelerates with ``I − j_r`` alone; the rotor then hits the other flank (an
    impact that loses energy) and rides on it through the turning point.

    Residual mark when missing: the decelerating quarter-swings (bottom to turning point)
    are shorter than a one-inertia model's and the accelerating ones longer, in every
    swing; the inertia implied by the half-periods falls with the swing's amplitude, where
    a pendulum's period grows with it.
    """

    j_r: Float[ArrayLike, ""] = parameter(
        "kg m²", "rotor (motor and first gears) inertia referred to the output",
        start=lambda s: 0.5 * s.inertia)
    backlash: Float[ArrayLike, ""] = parameter(
        "rad", "total free play between rotor and arm, output side",
        start=lambda s: 0.02 * s.amplitude)
    tau_r: Float[ArrayLike, ""] = parameter(
        "N m", "rotor's own dry friction, referred to the output",
        start=lambda s: 0.5 * s.torque)

    name: ClassVar[str] = "rotor_free_play"

    def init_state(self, theta0: Float[Array, ""]):
        return (jnp.sign(theta0) * 0.5 * self.backlash, jnp.zeros(()))

    def update_state(self, state, theta_old, theta_new):
        raise TypeError("RotorFreePlay's state moves in time (the rotor's own speed): "
                        "hdid's simulator has no ODE-state hook; use simulate_drops")

    def _contact(self, z, zdot, reduced):
        w = 2.0 * math.pi * CONTACT_HZ
        pen = jnp.maximum(jnp.abs(z) - 0.5 * self.backlash, 0.0)
        f = jnp.maximum(reduced * w * w * pen + 2.0 * CONTACT_ZETA * reduced * w
                        * jnp.sign(z) * zdot, 0.0)
        return jnp.where(pen > 0, jnp.sign(z) * f, 0.0)

    def torque(self, motion: Motion, state, arm_inertia=None) -> Float[Array, ""]:
        """Contact torque on the arm [N m] (``arm_inertia`` sets the reduced inertia;
        default ``j_r``, the rotor's own)."""
        z, psi = state
        j_a = self.j_r if arm_inertia is None else arm_inertia
        return self._contact(z, psi - motion.omega, self.j_r * j_a / (self.j_r + j_a))

    def state_derivative(self, motion: Motion, state, arm_inertia):
        """``(ż, ψ̇)``: the hook hdid's simulator lacks (module docstring)."""
        z, psi = state
        t = self.torque(motion, state, arm_inertia)
        return psi - motion.omega, (-t - self.tau_r * jnp.tanh(psi / SMOOTH_SPEED)) / self.j_r


class DropLaw(eqx.Module):
    """The arm's own torques in a drop: gravity ``−mgl·sin θ`` and hdid's Stribeck plus
    viscous friction ``−tanh(ω/ε)·(τ_c + (τ_s − τ_c)·exp(−|ω/v_s|^δ)) − c_v·ω`` [N m]."""

    mgl: Float[ArrayLike, ""]
    tau_c: Float[ArrayLike, ""]
    tau_s: Float[ArrayLike, ""]
    v_s: Float[ArrayLike, ""]
    delta: Float[ArrayLike, ""]
    c_v: Float[ArrayLike, ""]

    def __call__(self, theta, omega):
        a = jnp.abs(omega)
        x = jnp.exp(self.delta * jnp.log(jnp.maximum(a, 1e-12) / self.v_s))
        level = self.tau_c + (self.tau_s - self.tau_c) * jnp.exp(-x)
        return (-self.mgl * jnp.sin(theta) - jnp.tanh(omega / SMOOTH_SPEED) * level
                - self.c_v * omega)


def _rk4(f, y, h):
    k1 = f(y)
    k2 = f(jax.tree_util.tree_map(lambda a, b: a + 0.5 * h * b, y, k1))
    k3 = f(jax.tree_util.tree_map(lambda a, b: a + 0.5 * h * b, y, k2))
    k4 = f(jax.tree_util.tree_map(lambda a, b: a + h * b, y, k3))
    return jax.tree_util.tree_map(lambda a, b, c, d, e: a + h / 6 * (b + 2 * c + 2 * d + e),
                                  y, k1, k2, k3, k4)


def simulate_drops(law: DropLaw, rotor: RotorFreePlay | None, inertia,
                   times: Float[ArrayLike, "R T"], theta0: Float[ArrayLike, " R"],
                   t_release: Float[ArrayLike, " R"], *, duration: float, h: float = 2.5e-4,
                   omega0: float = 0.0):
    """Arm angle [rad] at ``times`` for ``R`` drops from rest (or both bodies at ``omega0``
    [rad/s]) at ``theta0`` released at ``t_release`` (held at ``theta0`` before): fixed RK4 steps ``h`` [s] from each release
    for ``duration`` s, then cubic Hermite in (θ, ω) at the samples (smooth in the release
    time). ``rotor=None``: one inertia ``inertia``; else the arm has ``inertia − j_r``."""
    times = jnp.asarray(times, dtype=float)
    n = int(math.ceil(duration / h)) + 2
    w0 = jnp.asarray(omega0, dtype=float)

    def one(th0, tr, ts):
        if rotor is None:
            def f(y):
                th, om = y
                return om, law(th, om) / inertia
            y0 = (th0, w0)
        else:
            j_a = inertia - rotor.j_r

            def f(y):
                th, om, z, psi = y
                m = Motion(theta=th, omega=om, direction=jnp.sign(om), ratio=1.0)
                dz, dpsi = rotor.state_derivative(m, (z, psi), j_a)
                return om, (law(th, om) + rotor.torque(m, (z, psi), j_a)) / j_a, dz, dpsi
            z0, _ = rotor.init_state(th0)
            y0 = (th0, w0, z0, w0)

        def step(y, _):
            y1 = _rk4(f, y, h)
            return y1, (y1[0], y1[1])

        _, (th, om) = jax.lax.scan(step, y0, None, length=n)
        th = jnp.concatenate([th0[None], th])
        om = jnp.concatenate([w0[None], om])
        s = jnp.clip((ts - tr) / h, 0.0, n - 1e-9)
        i = jnp.floor(s).astype(int)
        u = s - i
        p0, p1, m0, m1 = th[i], th[i + 1], om[i] * h, om[i + 1] * h
        return ((2 * u**3 - 3 * u**2 + 1) * p0 + (u**3 - 2 * u**2 + u) * m0
                + (-2 * u**3 + 3 * u**2) * p1 + (u**3 - u**2) * m1)

    return jax.vmap(one)(jnp.asarray(theta0, dtype=float), jnp.asarray(t_release, dtype=float),
                         times)
