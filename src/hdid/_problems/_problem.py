"""The least-squares problem: parameter layout, forward model and weighted residuals."""

from __future__ import annotations

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _config  # noqa: F401
from .._models._model import Model
from .._simulation._prepare import Prepared
from ._base import AbstractProblem
from .._simulation._simulate import simulate_runs
from .._models._transforms import from_unconstrained, interval_from_u

#: Scale of the per-set-up offset in the optimiser's space, relative to the log's typical
#: release amplitude (rounded to a power of ten: 0.01 rad for ±0.157 rad releases).
OFFSET_SCALE_REL = 0.064


class Problem(AbstractProblem):
    """Residuals of one log for a model whose ``free`` parameters are being fitted.

    The unknowns ``u`` are laid out as: free physical parameters (transformed), then the
    release instant of each run (logistic map onto its bracket; absent when fixed), the
    true encoder reading at release of each run (in encoder steps from the logged hold),
    the encoder reading at the spring's zero of each set-up (``offset_scale`` units), and
    — only for logs with runs that start in motion — the initial velocity of each such
    run (``vel_scale`` units; ``moving_index`` says which runs).
    Residuals are ``weight·(model − measured)/σ_q`` with ``σ_q = step/√12`` — the
    quantization noise of an ideal encoder — followed by weak-prior rows.
    """

    base: Model
    times: Float[Array, "R T"]
    theta: Float[Array, "R T"]
    weight: Float[Array, "R T"]
    setup_index: Array
    added_inertia: Float[Array, " R"]
    hold: Float[Array, " R"]
    release_lo: Float[Array, " R"]
    release_hi: Float[Array, " R"]
    offset0: Float[Array, " S"]
    step: Float[Array, ""]
    prior_mean: Float[Array, " P"]
    prior_sd: Float[Array, " P"]
    prior_on: Array
    free: tuple[str, ...] = eqx.field(static=True)
    release_free: bool = eqx.field(static=True)
    max_substep: float = eqx.field(static=True)
    offset_scale: Float[Array, ""] = None
    moving_index: Array = None
    vel_scale: Float[Array, ""] = None
    omega_guess: Float[Array, " R"] = None
    theta0_scale: Float[Array, ""] = None
    n_moving: int = eqx.field(static=True, default=0)

    @property
    def n_runs(self) -> int:
        return self.times.shape[0]

    @property
    def n_setups(self) -> int:
        return self.offset0.shape[0]

    @property
    def n_physical(self) -> int:
        return len(self.free)

    @property
    def n_unknowns(self) -> int:
        return (self.n_physical + (2 if self.release_free else 1) * self.n_runs
                + self.n_setups + self.n_moving)

    @property
    def theta0_step(self):
        """Unit of the start-angle unknowns: the encoder step (a start angle is known to
        about a count), or, for readings on no grid whose noise may be tiny, at least a
        thousandth of the log's amplitude (``theta0_scale``), so the optimiser's steps
        stay of order one."""
        return self.step if self.theta0_scale is None else self.theta0_scale

    @property
    def sigma(self):
        return self.step / jnp.sqrt(12.0)

    # -- layout -----------------------------------------------------------------------
    def unpack(self, u):
        P, R = self.n_physical, self.n_runs
        specs = self.base.parameter_specs()
        values = {n: from_unconstrained(specs[n], u[i]) for i, n in enumerate(self.free)}
        i = P
        if self.release_free:
            t_release = interval_from_u(u[i : i + R], self.release_lo, self.release_hi)
            i += R
        else:
            t_release = self.release_lo
        theta0_enc = self.hold + self.theta0_step * u[i : i + R]
        i += R
        offset = self.offset0 + self.offset_scale * u[i : i + self.n_setups]
        return values, t_release, theta0_enc, offset

    def omega0(self, u):
        """Initial velocity of every run ``(R,)`` (0 for runs released from a hold)."""
        if self.n_moving == 0:
            return jnp.zeros(self.n_runs)
        return jnp.zeros(self.n_runs).at[self.moving_index].set(
            self.vel_scale * u[self.n_unknowns - self.n_moving:])

    def omega0_np(self, u) -> np.ndarray:
        """NumPy twin of :meth:`omega0`."""
        out = np.zeros(self.n_runs)
        if self.n_moving:
            u = np.asarray(u, dtype=float)
            out[np.asarray(self.moving_index)] = float(self.vel_scale) * u[self.n_unknowns - self.n_moving:]
        return out

    def unpack_np(self, u):
        """NumPy twin of :meth:`unpack` for results (no JAX dispatch outside jit)."""
        u = np.asarray(u, dtype=float)
        P, R = self.n_physical, self.n_runs
        specs = self.base.parameter_specs()
        values = {n: float(from_unconstrained(specs[n], u[i], np)) for i, n in enumerate(self.free)}
        i = P
        lo, hi = np.asarray(self.release_lo), np.asarray(self.release_hi)
        if self.release_free:
            t_release = lo + (hi - lo) / (1.0 + np.exp(-u[i : i + R]))
            i += R
        else:
            t_release = lo
        theta0_enc = np.asarray(self.hold) + float(self.theta0_step) * u[i : i + R]
        i += R
        offset = np.asarray(self.offset0) + float(self.offset_scale) * u[i : i + self.n_setups]
        return values, t_release, theta0_enc, offset

    def free_values_np(self, U) -> dict[str, np.ndarray]:
        """Free physical parameter values of each row of ``U`` ``(L, n)``: name → ``(L,)``."""
        U = np.atleast_2d(np.asarray(U, dtype=float))
        specs = self.base.parameter_specs()
        return {
            n: np.asarray(from_unconstrained(specs[n], U[:, i], np), dtype=float)
            for i, n in enumerate(self.free)
        }

    def values_np(self, u) -> dict[str, float]:
        """All parameter values (fixed and fitted) at ``u``, as floats."""
        fixed = {k: float(v) for k, v in self.base.values().items()}
        return {**fixed, **self.unpack_np(u)[0]}

    def model(self, u) -> Model:
        values, *_ = self.unpack(u)
        return self.base.replace(**values) if values else self.base

    def band_limit(self):
        """How far [log units] to search for the stick band's edges: twice the largest
        excursion from the spring zero in the log (the band cannot extend past where the
        log shows the gear sliding; a fixed 1 rad would not fit a log in mrad or degrees)."""
        off = self.offset0[self.setup_index][:, None]
        return 2.0 * jnp.max(jnp.abs(self.theta - off))

    def derived(self, u) -> dict:
        """The model's derived quantities at ``u`` (:meth:`hdid.Model.derived`), the stick
        band searched within :meth:`band_limit`."""
        return self.model(u).derived(self.band_limit())

    def derived_and_jacobian(self, u):
        """``(values, ∂values/∂u_physical)``: :meth:`derived` and its Jacobian in the
        physical unknowns (forward mode; the nuisance unknowns held at ``u``'s)."""
        P = self.n_physical

        def quantities(up):
            return self.derived(jnp.concatenate([up, u[P:]]))

        return quantities(u[:P]), jax.jacfwd(quantities)(u[:P])

    # -- forward model ----------------------------------------------------------------
    def simulate(self, u, times=None, full_output: bool = False):
        """Simulated WG angle of every run ``(R, T)``, spring-zero frame (no offset); with a
        reading component (:attr:`hdid.Model.reading`) the state at the instants the
        readings show (e.g. a sample-and-hold device's last sample before each time)."""
        _, t_release, theta0_enc, offset = self.unpack(u)
        model, times = self.model(u), self.times if times is None else times
        if model.reading is not None:  # the instants the readings show (a device's samples)
            times = model.reading.sample_times(times)
        return simulate_runs(
            per_run(model, self.n_runs), times,
            theta0_enc - offset[self.setup_index], t_release,
            added_inertia=self.added_inertia, max_substep=self.max_substep,
            full_output=full_output, omega0=self.omega0(u) if self.n_moving else None,
        )

    def predict(self, u, times=None):
        """Predicted encoder readings ``(R, T)`` (or at ``times`` ``(R, T')``)."""
        *_, offset = self.unpack(u)
        return self.simulate(u, times) + offset[self.setup_index][:, None]

    def data_residuals(self, u):
        return (self.weight * (self.predict(u) - self.theta) / self.sigma).ravel()

    def prior_residuals(self, u):
        z = (u[: self.n_physical] - self.prior_mean) / self.prior_sd
        return jnp.where(self.prior_on, z, 0.0)

    def residuals(self, u):
        return jnp.concatenate([self.data_residuals(u), self.prior_residuals(u)])

    # -- structured Jacobian ----------------------------------------------------------
    def _local(self, u):
        """Per-run unknowns ``(R, P+3)``: physical, release, start angle, own offset (and,
        with runs that start moving, ``(R, P+4)``: their initial velocity, 0 elsewhere)."""
        P, R = self.n_physical, self.n_runs
        i = P + (R if self.release_free else 0)
        tr = u[P : P + R] if self.release_free else jnp.zeros(R)
        th0 = u[i : i + R]
        off = u[i + R : i + R + self.n_setups][self.setup_index]
        phys = jnp.broadcast_to(u[:P], (R, P))
        cols = [phys, tr[:, None], th0[:, None], off[:, None]]
        if self.n_moving:
            vel = jnp.zeros(R).at[self.moving_index].set(u[self.n_unknowns - self.n_moving:])
            cols.append(vel[:, None])
        return jnp.concatenate(cols, axis=1)

    def _runs_residuals(self, local):
        """Data residuals ``(R, T)`` from per-run unknowns ``local`` ``(R, P+3)``."""
        return self.weight * (self._runs_predict(local) - self.theta) / self.sigma

    def predict_many(self, U):
        """Predicted encoder readings ``(L, R, T)`` of many unknown vectors ``U`` ``(L, n)``.

        The ``L·R`` runs are integrated in *one* :func:`simulate_runs` loop instead of
        ``vmap`` over the vectors: under ``vmap`` the loop's event branch (a
        ``lax.cond`` on "any run has an event in this substep") turns into a select that
        runs at every substep; here it stays a branch. Same numbers to rounding
        (tested); 1.6–2.1× faster for 9–36 vectors (docs/decisions/posterior-moves.md).
        """
        L, R = U.shape[0], self.n_runs
        local = jax.vmap(self._local)(U).reshape(L * R, -1)

        def tile(a):
            return jnp.tile(a, (L,) + (1,) * (a.ndim - 1))

        runs = lambda p: (p.times, p.theta, p.weight, p.setup_index, p.added_inertia,  # noqa: E731
                          p.hold, p.release_lo, p.release_hi)
        # (runs that start moving: their velocity is column P+3 of `local`, and each
        # tiled run reads it from there; `moving_index` is not used by _runs_predict)
        tiled = eqx.tree_at(runs, self, tuple(tile(a) for a in runs(self)))
        return tiled._runs_predict(local).reshape(L, R, -1)

    def _runs_predict(self, local):
        """Predicted readings ``(R, T)`` from per-run unknowns ``local`` ``(R, P+3)``."""
        P, R = self.n_physical, self.n_runs
        specs = self.base.parameter_specs()
        values = {n: from_unconstrained(specs[n], local[:, k]) for k, n in enumerate(self.free)}
        models = per_run(self.base, R)
        models = models.replace(**values) if values else models
        if self.release_free:
            t_release = interval_from_u(local[:, P], self.release_lo, self.release_hi)
        else:
            t_release = self.release_lo
        theta0_enc = self.hold + self.theta0_step * local[:, P + 1]
        off = self.offset0[self.setup_index] + self.offset_scale * local[:, P + 2]
        times = self.times if models.reading is None else models.reading.sample_times(self.times)
        pred = simulate_runs(
            models, times, theta0_enc - off, t_release,
            added_inertia=self.added_inertia, max_substep=self.max_substep,
            omega0=self.vel_scale * local[:, P + 3] if self.n_moving else None,
        )
        return pred + off[:, None]

    def data_residuals_and_jacobian(self, u):
        """Data residuals ``(R·T,)`` and their Jacobian ``(R·T, n_unknowns)``.

        Each run depends only on the shared physical parameters and its own release,
        start angle and set-up offset: forward mode over those ``P + 3`` local unknowns,
        the tangent of local unknown ``j`` set in every run at once (runs do not
        interact, so run ``r``'s output tangent is its derivative by its own ``j``),
        then scattered into the full matrix — instead of carrying every unknown's
        tangent through every run's simulation.
        """
        P, R = self.n_physical, self.n_runs
        T = self.times.shape[1]
        local = self._local(u)
        L = local.shape[1]
        basis = jnp.broadcast_to(jnp.eye(L)[:, None, :], (L, R, L))
        r, tangents = jax.vmap(
            lambda t: jax.jvp(self._runs_residuals, (local,), (t,)), out_axes=(None, 0)
        )(basis)
        jac_local = jnp.moveaxis(tangents, 0, -1)  # (R, T, P+3)
        idx = jnp.arange(R)
        rel = P if self.release_free else None
        th0 = P + (R if self.release_free else 0)
        off = th0 + R
        J = jnp.zeros((R, T, self.n_unknowns))
        J = J.at[:, :, :P].set(jac_local[:, :, :P])
        if rel is not None:
            J = J.at[idx, :, rel + idx].set(jac_local[:, :, P])
        J = J.at[idx, :, th0 + idx].set(jac_local[:, :, P + 1])
        J = J.at[idx, :, off + self.setup_index].add(jac_local[:, :, P + 2])
        if self.n_moving:
            m = self.moving_index
            vel = self.n_unknowns - self.n_moving
            J = J.at[m, :, vel + jnp.arange(self.n_moving)].set(jac_local[m, :, P + 3])
        return r.reshape(-1), J.reshape(R * T, self.n_unknowns)

    def residuals_and_jacobian(self, u):
        r, J = self.data_residuals_and_jacobian(u)
        P = self.n_physical
        rp = self.prior_residuals(u)
        Jp = jnp.zeros((P, self.n_unknowns)).at[:, :P].set(
            jnp.diag(jnp.where(self.prior_on, 1.0 / self.prior_sd, 0.0))
        )
        return jnp.concatenate([r, rp]), jnp.concatenate([J, Jp], axis=0)


def per_run(model: Model, n_runs: int) -> Model:
    """``model`` with a leading run axis on every leaf (one copy per run)."""
    return jax.tree_util.tree_map(lambda x: jnp.broadcast_to(x, (n_runs,) + jnp.shape(x)), model)


def build_problem(
    prep: Prepared,
    base: Model,
    free: tuple[str, ...],
    offset0: np.ndarray,
    max_substep: float,
    release_fixed: bool,
    priors: dict[str, tuple[float, float]],
    offset_scale: float = 0.01,
    vel_scale: float = 1.0,
) -> Problem:
    mean = np.array([priors[n][0] if n in priors else 0.0 for n in free])
    sd = np.array([priors[n][1] if n in priors else 1.0 for n in free])
    on = np.array([n in priors for n in free], dtype=bool)
    # Fixed values as arrays, not Python floats: filter_jit would treat floats as static
    # and recompile for every new inertia= / fix= value.
    base = jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=float), base)
    moving = (np.zeros(prep.n_runs, dtype=bool) if prep.moving_start is None
              else np.asarray(prep.moving_start, dtype=bool))
    return Problem(
        base=base,
        times=jnp.asarray(prep.times),
        theta=jnp.asarray(prep.theta),
        weight=jnp.asarray(prep.weight),
        setup_index=jnp.asarray(prep.setup_index),
        added_inertia=jnp.asarray(prep.added_inertia),
        hold=jnp.asarray(prep.hold),
        release_lo=jnp.asarray(prep.release_lo),
        release_hi=jnp.asarray(prep.release_hi),
        offset0=jnp.asarray(offset0, dtype=float),
        step=jnp.asarray(prep.resolution),
        prior_mean=jnp.asarray(mean, dtype=float),
        prior_sd=jnp.asarray(sd, dtype=float),
        prior_on=jnp.asarray(on),
        free=tuple(free),
        release_free=not release_fixed,
        max_substep=max_substep,
        offset_scale=jnp.asarray(offset_scale, dtype=float),
        moving_index=jnp.asarray(np.flatnonzero(moving), dtype=int),
        vel_scale=jnp.asarray(vel_scale, dtype=float),
        omega_guess=jnp.asarray(np.zeros(prep.n_runs) if prep.omega_guess is None
                                else prep.omega_guess, dtype=float),
        n_moving=int(np.sum(moving)),
        theta0_scale=(None if prep.quantized else jnp.asarray(
            max(prep.resolution, 1e-3 * float(np.max(np.abs(prep.theta - np.median(prep.rest))))),
            dtype=float)),
    )


def with_jacobian(fn, fn_and_jac):
    """``fn`` whose JVP uses a materialised Jacobian from ``fn_and_jac(u) -> (r, J)``.

    optimistix linearises the residual function; forward-mode through the simulator's
    while_loop cannot be linearised directly, and a materialised forward-mode Jacobian
    (all tangents in one pass) is also the fastest way for a few dozen unknowns.
    """

    @jax.custom_jvp
    def wrapped(u):
        return fn(u)

    @wrapped.defjvp
    def _jvp(primals, tangents):
        (u,), (du,) = primals, tangents
        r, jac = fn_and_jac(u)
        return r, jac @ du

    return wrapped
