"""Stick-exact simulation of the free-motion test.

Scheme (chosen by measurement, see ``benchmarks/simulator_schemes.py``): fixed RK4
substeps between samples with the friction *direction* frozen inside a step. When the
velocity would cross zero inside a substep the step is split at the crossing: the
crossing fraction ``α = ω0 / (ω0 − ω1)`` and the cubic-Hermite position there are smooth
functions of the parameters, so the rest position and its sensitivity are correct under
automatic differentiation (unlike time-stepping schemes that snap the stop to the grid).
At the crossing the set-valued friction decides: if the net torque at rest can be held
(``|Σ torque| ≤ Σ holding``) the wave generator stays exactly put — no creep — else it
slides on in the direction of the net torque for the rest of the substep.

The release instant ``t_release`` may lie anywhere between samples: each sample interval
is integrated over its part after the release, ``[max(t_{k−1} − t_r, 0), max(t_k − t_r, 0)]``,
which is continuous (and piecewise smooth) in ``t_r``.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
from jaxtyping import Array, ArrayLike, Float

from . import _config  # noqa: F401
from ._model import Model
from .effects import Motion

#: Longest RK4 substep [s]. Against the event-driven reference this keeps the error far
#: below the 250 Hz quantization floor (benchmarks/results/simulator_schemes.md).
DEFAULT_MAX_SUBSTEP = 5e-4


def substeps_for(sample_period: float, max_substep: float = DEFAULT_MAX_SUBSTEP) -> int:
    """Number of substeps per sample so that each is at most ``max_substep`` seconds."""
    import math

    return max(1, math.ceil(sample_period / max_substep - 1e-9))


def _accel(model: Model, inertia, theta, omega, direction, states):
    motion = Motion(theta=theta, omega=omega, direction=direction, ratio=model.ratio)
    return model.torque(motion, states) / inertia


def rk4(f, theta, omega, t, h):
    """One classical RK4 step of ``θ̈ = f(θ, θ̇, t)``; returns ``(θ, θ̇, f at the start)``."""
    a1 = f(theta, omega, t)
    v2 = omega + 0.5 * h * a1
    a2 = f(theta + 0.5 * h * omega, v2, t + 0.5 * h)
    v3 = omega + 0.5 * h * a2
    a3 = f(theta + 0.5 * h * v2, v3, t + 0.5 * h)
    v4 = omega + h * a3
    a4 = f(theta + h * v3, v4, t + h)
    theta_new = theta + h / 6.0 * (omega + 2.0 * v2 + 2.0 * v3 + v4)
    omega_new = omega + h / 6.0 * (a1 + 2.0 * a2 + 2.0 * a3 + a4)
    return theta_new, omega_new, a1


def _rk4(model, inertia, theta, omega, direction, states, h):
    def f(th, om, _t):
        return _accel(model, inertia, th, om, direction, states)

    return rk4(f, theta, omega, 0.0, h)


def _safe_div(num, den, ok):
    return jnp.where(ok, num / jnp.where(ok, den, 1.0), 0.0)


def crossing_fraction(omega0, omega1, acc0, h, crossed):
    """Fraction α of a substep at which the velocity reaches zero (0 where not ``crossed``).

    Linear estimate refined by one Newton step on the quadratic
    ``v(α) ≈ ω0 + b·α + c·α²`` through ``(ω0, a0·h)`` and ``ω1``.
    """
    alpha_lin = jnp.clip(_safe_div(omega0, omega0 - omega1, crossed), 0.0, 1.0)
    b = acc0 * h
    c = omega1 - omega0 - b
    v_at = omega0 + b * alpha_lin + c * alpha_lin**2
    dv = b + 2.0 * c * alpha_lin
    newton_ok = crossed & (jnp.abs(dv) > 0)
    alpha_nt = alpha_lin - _safe_div(v_at, dv, newton_ok)
    alpha = jnp.where(newton_ok & (alpha_nt >= 0) & (alpha_nt <= 1), alpha_nt, alpha_lin)
    return jnp.where(crossed, alpha, 0.0)


# Phases of the substep state machine (see ``_advance``).
_STEP, _TO_CROSSING, _GAP, _AT_REST, _REMAINDER = 0, 1, 2, 3, 4


def _rk4_torque(model, inertia, theta, omega, direction, states, h):
    """:func:`rk4` of the model's dynamics; also returns the torque at the start."""
    tau1 = model.torque(
        Motion(theta=theta, omega=omega, direction=direction, ratio=model.ratio), states
    )
    a1 = tau1 / inertia
    first = [True]

    def f(th, om, _t):
        if first[0]:  # the start's acceleration is already known
            first[0] = False
            return a1
        return _accel(model, inertia, th, om, direction, states)

    theta_new, omega_new, _ = rk4(f, theta, omega, 0.0, h)
    return theta_new, omega_new, a1, tau1


def _advance(model: Model, inertia, carry, h, n_sub):
    """``n_sub`` substeps of length ``h`` from ``carry = (θ, θ̇, direction, states)``.

    Every iteration of the loop runs exactly one RK4 step (under ``vmap`` a branch would
    cost as much as the taken one), and a small state machine reuses it for the rare
    events, so an ordinary substep costs one RK4 instead of three:

    * ``_STEP`` (sliding): RK4 over ``h``. Accepted unless the velocity crosses zero; then
      the crossing fraction α is stored and the step is redone in pieces:
    * ``_TO_CROSSING``: RK4 from the same state over ``α·h`` (the velocity keeps its sign
      there, so the friction law is smooth and RK4 keeps its order; integrating across
      the kink of the Stribeck curve at ω = 0 would make the stop position only second
      order);
    * ``_GAP``: the acceleration at the end of that piece (the first stage of an RK4
      started there) closes the small remaining gap to ω = 0 with a quadratic in time:
      the stop lies ``dt = −ω_a/a`` later, at ``θ_stop = θ_a + ω_a·dt/2``; motion that
      slides on resumes from that corrected instant ``α·h + dt``, which keeps the scheme
      high-order after reversals (benchmarks/results/simulator_schemes.md);
    * ``_AT_REST`` (also where a substep starts at rest): the net torque at rest (the
      first stage of an RK4 started there with ω = 0, direction 0) against the holding
      torque: if it can be held the wave generator stays exactly put — no creep — and the
      substep ends there, else it slides on in the direction of the net torque:
    * ``_REMAINDER``: RK4 from rest over the rest ``(1 − α)·h`` of the substep.

    The arithmetic is that of the former all-branches substep, step for step. The effect
    states are updated once per substep, from its start to its end, and the torques inside
    a substep use the states at its start, as before.
    """
    theta, omega, direction, states = carry
    zero = jnp.zeros(())
    ratio = model.ratio

    def phase_for(d):
        return jnp.where(d == 0, _AT_REST, _STEP)

    init = (
        jnp.zeros((), dtype=int), phase_for(direction), theta, omega, direction, states,
        zero, theta, zero, zero,
    )

    def cond(c):
        return c[0] < n_sub

    def body(c):
        j, ph, th, om, d, st, alpha, th_x, om_x, d_new = c
        step, to_cross, gap, at_rest, rem = (ph == p for p in range(5))
        from_state = step | to_cross
        resting = at_rest | rem
        th_in = jnp.where(from_state, th, th_x)
        om_in = jnp.where(from_state, om, jnp.where(resting, 0.0, om_x))
        d_in = jnp.where(at_rest, 0.0, jnp.where(rem, d_new, d))
        h_in = jnp.where(
            step, h, jnp.where(to_cross, alpha * h, jnp.where(rem, (1.0 - alpha) * h, 0.0))
        )
        th1, om1, a1, tau1 = _rk4_torque(model, inertia, th_in, om_in, d_in, st, h_in)

        # _STEP: accept, or find the crossing.
        crossed = step & (d * om1 <= 0) & (om1 != om)
        alpha_step = crossing_fraction(om, om1, a1, h, crossed)
        # _GAP: a1 is the acceleration at the end of the piece up to the crossing.
        dt_gap = _safe_div(-om_x, a1, gap & (a1 != 0))
        th_cross = th_x + 0.5 * om_x * dt_gap
        alpha_gap = jnp.clip(alpha + dt_gap / h, 0.0, 1.0)
        # _AT_REST: tau1 is the net torque at rest at th_x.
        rest = Motion(theta=th_x, omega=zero, direction=zero, ratio=ratio)
        stick = jnp.abs(tau1) <= model.holding_torque(rest, st)

        accept = (step & ~crossed) | (at_rest & stick) | rem
        th_acc = jnp.where(at_rest, th_x, th1)
        om_acc = jnp.where(at_rest, 0.0, om1)
        d_acc = jnp.where(at_rest, 0.0, jnp.where(rem, d_new, d))
        st_acc = model.update_state(st, th, th_acc)

        ph_next = jnp.where(
            accept,
            phase_for(d_acc),
            jnp.where(
                step, _TO_CROSSING,
                jnp.where(to_cross, _GAP, jnp.where(gap, _AT_REST, _REMAINDER)),
            ),
        )
        # Carried for the phases to come: α (α' after the gap), the crossing/rest point
        # (θ_a, ω_a after _TO_CROSSING), the direction to slide on.
        alpha_n = jnp.where(
            accept, 0.0, jnp.where(step, alpha_step, jnp.where(gap, alpha_gap, alpha))
        )
        th_x_n = jnp.where(
            accept, th_acc, jnp.where(to_cross, th1, jnp.where(gap, th_cross, th_x))
        )
        om_x_n = jnp.where(to_cross, om1, om_x)
        d_new_n = jnp.where(at_rest, jnp.sign(tau1), d_new)

        def keep(new, old):
            return jnp.where(accept, new, old)

        return (
            j + accept.astype(j.dtype), ph_next,
            keep(th_acc, th), keep(om_acc, om), keep(d_acc, d),
            jax.tree_util.tree_map(keep, st_acc, st),
            alpha_n, th_x_n, om_x_n, d_new_n,
        )

    _, _, theta, omega, direction, states, *_ = jax.lax.while_loop(cond, body, init)
    return theta, omega, direction, states


def _substep(model: Model, inertia, carry, h):
    """One substep of length ``h`` from ``carry = (θ, θ̇, direction, states)``."""
    return _advance(model, inertia, carry, h, 1)


_DEFAULT_SUBSTEP = _substep


def simulate(
    model: Model,
    times: Float[ArrayLike, " T"],
    theta0: Float[ArrayLike, ""],
    t_release: Float[ArrayLike, ""],
    *,
    added_inertia: Float[ArrayLike, ""] = 0.0,
    max_substep: float = None,
    substeps: int = 1,
    full_output: bool = False,
):
    """Wave-generator angle at ``times`` after a release from rest.

    Parameters
    ----------
    model:
        The :class:`~hdid.Model`.
    times:
        Sample times [s], non-decreasing.
    theta0:
        WG angle at release [rad], measured from the spring's zero.
    t_release:
        Release instant [s]; anywhere, also between samples. Before it ``θ = θ0``.
    added_inertia:
        Known inertia added for this run [kg m²].
    max_substep:
        Longest RK4 substep [s] (default ``DEFAULT_MAX_SUBSTEP``); each sample interval
        is cut into ``max(substeps, ceil(interval / max_substep))`` equal substeps, so a
        release long before the first sample is integrated as finely as the rest.
    substeps:
        Minimum number of substeps per sample interval.
    full_output:
        Also return velocity and the stuck flag at each sample.

    Returns
    -------
    theta, or ``(theta, omega, stuck)`` with ``full_output``: arrays of shape ``(T,)``.
    """
    times = jnp.asarray(times, dtype=float)
    theta0 = jnp.asarray(theta0, dtype=float)
    t_release = jnp.asarray(t_release, dtype=float)
    inertia = jnp.asarray(model.inertia, dtype=float) + added_inertia
    if not isinstance(inertia, jax.core.Tracer) and not bool(jnp.all(inertia > 0)):
        raise ValueError(
            f"inertia + added_inertia = {inertia}: must be > 0 kg m^2; check both values"
        )
    h_max = DEFAULT_MAX_SUBSTEP if max_substep is None else max_substep
    n = times.shape[0]
    elapsed = jnp.maximum(times - t_release, 0.0)
    intervals = jnp.diff(elapsed, prepend=0.0)

    # The dynamics are autonomous and effect state changes only when θ moves, so once
    # the wave generator sticks it stays stuck: integrate from the first sample after
    # the release until it sticks (forward-differentiable while_loop), then hold.
    first = jnp.sum(elapsed <= 0.0)

    def cond(carry):
        k, (_, _, direction, _), _ = carry
        return (k < n) & ((direction != 0) | (k == first))

    def body(carry):
        k, state, out = carry
        dt = intervals[k]
        n_sub = jnp.maximum(substeps, jnp.ceil(dt / h_max - 1e-9)).astype(int)
        h = dt / n_sub
        if _substep is _DEFAULT_SUBSTEP:
            state = _advance(model, inertia, state, h, n_sub)
        else:  # a candidate scheme swapped in (benchmarks/simulator_schemes.py)
            state = jax.lax.fori_loop(
                0, n_sub, lambda _, c: _substep(model, inertia, c, h), state
            )
        theta, omega, direction, _ = state
        out = tuple(o.at[k].set(v) for o, v in zip(out, (theta, omega, direction == 0)))
        return k + 1, state, out

    # Before release the wave generator rests at θ0 (held by the servo, not friction).
    state0 = (theta0, jnp.zeros(()), jnp.zeros(()), model.init_state(theta0))
    out0 = (jnp.full((n,), theta0), jnp.zeros((n,)), jnp.zeros((n,), dtype=bool))
    k, (theta_end, _, _, _), (theta, omega, stuck) = jax.lax.while_loop(
        cond, body, (first, state0, out0)
    )
    idx = jnp.arange(n)
    theta = jnp.where(idx >= k, theta_end, theta)
    stuck = jnp.where(idx >= k, True, stuck) & (idx >= first)
    if full_output:
        return theta, omega, stuck
    return theta
