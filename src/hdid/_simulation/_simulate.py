"""Stick-exact simulation of the free-motion test.

Scheme (chosen by measurement, see ``docs/decisions/simulator-scheme.md``): fixed RK4
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

Cost: most substeps need one RK4 step; the crossing and the stick/slip decision need three
more. :func:`simulate_runs` integrates all runs of a log in one loop and puts the split
behind a ``lax.cond`` on "any run has an event here", so it runs only where it is needed
(2× faster for a residual Jacobian than ``vmap`` over runs, which must run every branch at
every substep; the results are the same to rounding, benchmarks/results/batch_speed.md).
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from .. import _config  # noqa: F401
from .._models._model import Model
from ..effects import Motion

#: Longest RK4 substep [s]. Against the event-driven reference this keeps the error far
#: below the 250 Hz quantization floor (docs/decisions/simulator-scheme.md).
DEFAULT_MAX_SUBSTEP = 5e-4


def substeps_for(sample_period: float, max_substep: float = DEFAULT_MAX_SUBSTEP) -> int:
    """Number of substeps per sample so that each is at most ``max_substep`` seconds."""
    import math

    return max(1, math.ceil(sample_period / max_substep - 1e-9))


def known_value(x):
    """``x`` as a float64 NumPy array when its value is known while tracing, else None.

    A parameter held fixed is a constant even inside ``jit``; a free one is a tracer.
    Checks on values (e.g. a positive inertia) run only on the former: a JAX operation
    on a constant under ``jit`` is itself traced, so the check uses NumPy.
    """
    try:
        return np.asarray(x, dtype=float)
    except (jax.errors.TracerArrayConversionError, jax.errors.ConcretizationTypeError):
        return None


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


def _full_step(model: Model, inertia, carry, h):
    """One RK4 substep with the friction direction frozen: ``(θ1, ω1, θ̈ at the start)``."""
    theta, omega, direction, states = carry
    return _rk4(model, inertia, theta, omega, direction, states, h)


def _crossed(carry, omega1):
    """Whether the velocity of a sliding wave generator reaches zero in the substep."""
    _, omega, direction, _ = carry
    return (direction != 0) & (direction * omega1 <= 0) & (omega1 != omega)


def _event_step(model: Model, inertia, carry, h, full):
    """The substep from ``carry`` given its frozen-direction RK4 result ``full``.

    Where the velocity crosses zero the step is split at the crossing; at rest the
    set-valued friction decides between sticking and sliding off (module docstring).
    """
    theta, omega, direction, states = carry
    theta1, omega1, acc0 = full
    sliding = direction != 0
    crossed = _crossed(carry, omega1)
    alpha = crossing_fraction(omega, omega1, acc0, h, crossed)

    # Re-integrate up to the crossing: on [0, α·h] the velocity keeps its sign, so the
    # friction law is smooth there and RK4 keeps its order (integrating across the kink
    # of the Stribeck curve at ω = 0 would make the stop position only second order).
    theta_a, omega_a, _ = _rk4(model, inertia, theta, omega, direction, states, alpha * h)
    # Close the small remaining gap to ω = 0 with a quadratic in time: the stop lies
    # dt = −ω_a/a later, at θ_stop = θ_a + ω_a·dt/2; motion that slides on resumes from
    # that corrected instant (α·h + dt), which keeps the scheme high-order after
    # reversals (docs/decisions/simulator-scheme.md).
    acc_stop = _accel(model, inertia, theta_a, omega_a, direction, states)
    dt_gap = _safe_div(-omega_a, acc_stop, crossed & (acc_stop != 0))
    theta_cross = theta_a + 0.5 * omega_a * dt_gap
    alpha = jnp.where(crossed, jnp.clip(alpha + dt_gap / h, 0.0, 1.0), alpha)

    event = crossed | ~sliding
    theta_c = jnp.where(crossed, theta_cross, theta)

    rest = Motion(theta=theta_c, omega=jnp.zeros(()), direction=jnp.zeros(()), ratio=model.ratio)
    net = model.torque(rest, states)
    stick = jnp.abs(net) <= model.holding_torque(rest, states)
    new_direction = jnp.sign(net)
    theta2, omega2, _ = _rk4(
        model, inertia, theta_c, jnp.zeros(()), new_direction, states, (1.0 - alpha) * h
    )

    theta_n = jnp.where(event, jnp.where(stick, theta_c, theta2), theta1)
    omega_n = jnp.where(event, jnp.where(stick, 0.0, omega2), omega1)
    direction_n = jnp.where(event, jnp.where(stick, 0.0, new_direction), direction)
    states_n = model.update_state(states, theta, theta_n)
    return theta_n, omega_n, direction_n, states_n


def _substep(model: Model, inertia, carry, h):
    """One complete substep of one run (the plain and the event case in one)."""
    return _event_step(model, inertia, carry, h, _full_step(model, inertia, carry, h))


def _plain_step(model: Model, carry, full):
    """The substep where nothing happens: sliding goes on, rest stays rest."""
    theta, omega, direction, states = carry
    theta1, omega1, _ = full
    sliding = direction != 0
    theta_n = jnp.where(sliding, theta1, theta)
    omega_n = jnp.where(sliding, omega1, omega)
    return theta_n, omega_n, direction, model.update_state(states, theta, theta_n)


def _where_run(mask, a, b):
    """``where`` with a per-run mask over leaves with a leading run axis."""
    return jnp.where(mask.reshape(mask.shape + (1,) * (a.ndim - 1)), a, b)


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
    omega0: Float[ArrayLike, ""] = 0.0,
):
    """Wave-generator angle at ``times`` after a release (from rest, or at ``omega0``).

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
    omega0:
        Velocity at ``t_release`` [rad/s] (0: released from rest).

    Returns
    -------
    theta, or ``(theta, omega, stuck)`` with ``full_output``: arrays of shape ``(T,)``.
    """
    model = jax.tree_util.tree_map(lambda x: jnp.asarray(x)[None], model)
    out = simulate_runs(
        model,
        jnp.asarray(times, dtype=float)[None],
        jnp.asarray(theta0, dtype=float)[None],
        jnp.asarray(t_release, dtype=float)[None],
        added_inertia=jnp.asarray(added_inertia, dtype=float)[None],
        max_substep=max_substep,
        substeps=substeps,
        full_output=True,
        omega0=jnp.asarray(omega0, dtype=float)[None],
    )
    theta, omega, stuck = (o[0] for o in out)
    return (theta, omega, stuck) if full_output else theta


def simulate_runs(
    models: Model,
    times: Float[ArrayLike, "R T"],
    theta0: Float[ArrayLike, " R"],
    t_release: Float[ArrayLike, " R"],
    *,
    added_inertia: Float[ArrayLike, " R"] = 0.0,
    max_substep: float = None,
    substeps: int = 1,
    full_output: bool = False,
    omega0: Float[ArrayLike, " R"] | None = None,
):
    """:func:`simulate` for ``R`` runs at once, in one loop.

    ``omega0`` (default 0) is each run's velocity at ``t_release``: a run that the log
    shows already moving (a ring-down, a log cut after the release) starts sliding.

    ``models`` is a :class:`~hdid.Model` whose every array leaf has a leading axis of
    length ``R`` (one model per run, e.g. ``jax.tree_util.tree_map(lambda x:
    jnp.broadcast_to(x, (R,) + jnp.shape(x)), model)`` for a shared one); the other
    arguments are per run. Results are those of :func:`simulate` run by run.

    Why one loop and not ``vmap(simulate)``: a substep in which no run reaches zero
    velocity (most of them) needs one RK4 step; the crossing and the stick/slip
    decision need three more. Here that branch is a ``lax.cond`` on "any run has an
    event" (a scalar, also under forward-mode tangents), so it runs only when needed;
    under ``vmap`` every branch of every lane would run at every substep. Under an
    outer ``vmap`` (several fits in lockstep) it becomes a select, no worse than before.
    """
    times = jnp.asarray(times, dtype=float)
    theta0 = jnp.asarray(theta0, dtype=float)
    R, n = times.shape
    t_release = jnp.broadcast_to(jnp.asarray(t_release, dtype=float), (R,))
    known, added = known_value(models.inertia), known_value(added_inertia)
    if known is not None and added is not None and not np.all(known + added > 0):
        raise ValueError(
            f"inertia + added_inertia = {known + added}: must be > 0 kg m^2; check both values"
        )
    inertia = jnp.asarray(models.inertia, dtype=float) + added_inertia
    inertia = jnp.broadcast_to(inertia, (R,))
    h_max = DEFAULT_MAX_SUBSTEP if max_substep is None else max_substep
    elapsed = jnp.maximum(times - t_release[:, None], 0.0)
    intervals = jnp.diff(elapsed, axis=1, prepend=0.0)
    full_step = jax.vmap(_full_step)
    event_step = jax.vmap(_event_step)
    plain_step = jax.vmap(_plain_step)

    # The dynamics are autonomous and effect state changes only when θ moves, so once a
    # run sticks it stays stuck: each run is integrated from the first sample after its
    # release until it sticks at a sample (then held); the loop (forward-differentiable
    # while_loop) ends when every run has.
    first = jnp.sum(elapsed <= 0.0, axis=1)

    def running(k, direction):
        return (k == first) | ((k > first) & (direction != 0))

    def cond(carry):
        k, (_, _, direction, _), _ = carry
        return (k < n) & jnp.any(running(k, direction) | (k < first))

    def body(carry):
        k, state, out = carry
        active = running(k, state[2])
        dt = intervals[:, k]
        n_sub = jnp.maximum(substeps, jnp.ceil(dt / h_max - 1e-9)).astype(int)
        h_run = dt / n_sub

        def substep(j, state):
            h = jnp.where(j < n_sub, h_run, 0.0)
            full = full_step(models, inertia, state, h)
            plain = plain_step(models, state, full)
            # Runs not integrated at this sample (before their release, or stuck at a
            # sample already) and the padding substeps of a shorter interval keep the
            # plain step, which leaves a run at rest where it is.
            event = active & (j < n_sub) & (_crossed(state, full[1]) | (state[2] == 0))

            def split():
                stepped = event_step(models, inertia, state, h, full)
                return jax.tree_util.tree_map(lambda a, b: _where_run(event, a, b), stepped, plain)

            return jax.lax.cond(jnp.any(event), split, lambda: plain)

        state = jax.lax.fori_loop(0, jnp.max(jnp.where(active, n_sub, 0)), substep, state)
        theta, omega, direction, _ = state
        out = tuple(o.at[:, k].set(v) for o, v in zip(out, (theta, omega, direction == 0)))
        return k + 1, state, out

    # Before release the wave generator rests at θ0 (held by the servo, not friction); a
    # run given an initial velocity starts sliding in its direction.
    if omega0 is None:
        w0 = jnp.zeros(R)
    else:
        w0 = jnp.broadcast_to(jnp.asarray(omega0, dtype=float), (R,))
    state0 = (theta0, w0, jnp.sign(w0), jax.vmap(lambda m, t: m.init_state(t))(models, theta0))
    out0 = (jnp.broadcast_to(theta0[:, None], (R, n)), jnp.zeros((R, n)), jnp.zeros((R, n), dtype=bool))
    k, (theta_end, _, _, _), (theta, omega, stuck) = jax.lax.while_loop(
        cond, body, (jnp.min(first), state0, out0)
    )
    idx = jnp.arange(n)
    theta = jnp.where(idx >= k, theta_end[:, None], theta)
    stuck = jnp.where(idx >= k, True, stuck) & (idx >= first[:, None])
    if full_output:
        return theta, omega, stuck
    return theta
