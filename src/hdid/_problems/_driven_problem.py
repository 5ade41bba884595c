"""Least-squares problems of driven logs, alone or jointly with free-motion logs."""

from __future__ import annotations

import math
from dataclasses import dataclass

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from .. import _config  # noqa: F401
from .._simulation._driven import DrivenJoint, simulate_driven, substeps_for_times
from ._base import AbstractProblem
from .._models._transforms import from_unconstrained
from ..effects import order_of_magnitude

#: Scale of the fitted initial WG velocity of a run in the optimiser's space [rad/s].
OMEGA0_SCALE = 1.0


#: Length of a simulation window [s] (multiple shooting). An open-loop simulation from
#: the logged torque drifts: a 5 % inertia error moves the WG by radians within a
#: second, far outside the basin of a local fit. Each window restarts from its own
#: fitted angle and velocity; 0.2 s is 50 samples at 250 Hz for 2 unknowns, several
#: mechanical time constants (I/c_v ≈ 0.04 s), and short enough to keep the start
#: values in the basin.
DEFAULT_WINDOW = 0.2


@dataclass(frozen=True)
class DrivenData:
    """A driven log as padded ``(windows, samples)`` arrays.

    Every run is cut into windows of about ``DEFAULT_WINDOW`` seconds (multiple
    shooting: each window is simulated from its own fitted start). ``theta`` is the
    motor (WG) angle, ``theta_out`` the output angle (``None`` when the log has no
    output encoder), torques in N m. ``direction0`` is the output friction's sign at
    each window's start, from the data (used only when the window starts at rest).
    Padding repeats the last time step with zero weight. Times are the logged ones
    (jittered or gapped steps included; the inputs are held or interpolated between
    them); ``sample_period`` (the median step) only sets the window length in samples.
    """

    source: str
    run_names: tuple[str, ...]
    times: np.ndarray
    theta: np.ndarray
    motor_torque: np.ndarray
    load_torque: np.ndarray
    theta_out: np.ndarray | None
    weight: np.ndarray
    step: float
    output_step: float | None
    sample_period: float
    direction0: np.ndarray
    omega0: np.ndarray
    moving0: np.ndarray
    run_of_window: np.ndarray
    window_names: tuple[str, ...]
    first_row: tuple[int, ...] = ()
    #: ``"given"``, ``"estimated"`` (the readings' grid) or ``"estimated"`` from the
    #: noise about a local polynomial when the readings lie on no grid.
    step_source: str = "given"
    #: Speed scale of the log (a power of ten near its 95th-percentile speed), in the
    #: log's units per second: the optimiser's unit for the fitted window velocities.
    omega_scale: float = OMEGA0_SCALE
    #: The log's notes (:attr:`hdid.Log.notes`, e.g. runs split at a break in time).
    log_notes: tuple[str, ...] = ()

    @property
    def n_runs(self) -> int:
        """Number of simulation windows (rows of the arrays)."""
        return self.times.shape[0]

    @property
    def has_output(self) -> bool:
        return self.theta_out is not None

    @property
    def sigma(self) -> float:
        """Quantization σ of the motor encoder [rad]."""
        return self.step / math.sqrt(12.0)

    def sigma_kinematic(self, ratio: float) -> float:
        """σ of the measured kinematic error ``θ_out + θ/N`` [rad]: both encoders round."""
        out = (self.output_step or 0.0) ** 2 / 12.0
        return math.sqrt(out + (self.step / ratio) ** 2 / 12.0)

    @classmethod
    def from_log(cls, log, window: float = DEFAULT_WINDOW) -> DrivenData:
        from .._errors import LogError

        runs = log.runs
        missing = [r.name for r in runs if getattr(r, "motor_torque", None) is None]
        if missing:
            raise LogError(
                f"{log.source}: run(s) {missing} have no motor torque; a driven fit needs a "
                "'motor_torque' (or 'motor_current' with --torque-constant) column"
            )
        if not window > 0:
            raise ValueError(f"window = {window!r}: must be > 0 s (e.g. {DEFAULT_WINDOW})")
        has_out = all(getattr(r, "theta_out", None) is not None for r in runs)
        dt = float(log.sample_period)
        per = max(8, int(round(window / dt)))
        pieces = []  # (run index, slice) — the last piece of a run absorbs a short rest
        for i, r in enumerate(runs):
            n = r.n_samples
            starts = list(range(0, max(n - per // 2, 1), per))
            for k, a in enumerate(starts):
                b = starts[k + 1] if k + 1 < len(starts) else n
                pieces.append((i, a, b))
        W = len(pieces)
        speed_of_run = [_smooth_speed(r.theta, r.time) for r in runs]
        T = max(b - a for _, a, b in pieces)
        times = np.zeros((W, T))
        theta, tau_d, tau_l, out, w = (np.zeros((W, T)) for _ in range(5))
        d0, om0, mov = np.zeros(W), np.zeros(W), np.zeros(W)
        names = []
        for j, (i, a, b) in enumerate(pieces):
            r = runs[i]
            n = b - a
            t = r.time[a:b]
            times[j, :n] = t
            times[j, n:] = t[-1] + dt * np.arange(1, T - n + 1)
            theta[j, :n], theta[j, n:] = r.theta[a:b], r.theta[b - 1]
            tau_d[j, :n] = r.motor_torque[a:b]
            lt = r.load_torque if getattr(r, "load_torque", None) is not None else np.zeros(r.n_samples)
            tau_l[j, :n], tau_l[j, n:] = lt[a:b], lt[b - 1]
            if has_out:
                out[j, :n], out[j, n:] = r.theta_out[a:b], r.theta_out[b - 1]
            w[j, :n] = 1.0
            # A window whose first two readings agree starts at rest (a moving WG
            # changes the 4000-count encoder within a 4 ms sample above 0.4 rad/s, and
            # Stribeck friction does not let it creep slower): its velocity is 0, not fitted.
            mov[j] = float(n > 1 and r.theta[a + 1] != r.theta[a])
            om0[j] = speed_of_run[i][a] * mov[j]
            # The output friction's sign at the start: the direction of the encoder's
            # last change (the fit then takes it from the previous window's simulation).
            changed = np.nonzero(np.diff(r.theta[: a + 1]))[0]
            d0[j] = np.sign(np.diff(r.theta[: a + 1])[changed[-1]]) if changed.size else 0.0
            names.append(f"{r.name}@{t[0]:.3g}s")
        step, step_source = log.resolution, getattr(log, "resolution_source", None) or "given"
        if step is None:
            step = _noise_step([r.theta for r in runs], [r.time for r in runs])
            step_source = "estimated"
        speeds = np.concatenate([np.abs(v) for v in speed_of_run])
        omega_scale = order_of_magnitude(float(np.percentile(speeds, 95)) if speeds.size else 1.0)
        return cls(
            source=log.source, run_names=tuple(r.name for r in runs), times=times,
            theta=theta, motor_torque=tau_d, load_torque=tau_l,
            theta_out=out if has_out else None, weight=w, step=float(step),
            output_step=getattr(log, "output_resolution", None), sample_period=dt,
            direction0=d0, omega0=om0, moving0=mov, run_of_window=np.array([p[0] for p in pieces]),
            step_source=step_source, omega_scale=omega_scale,
            log_notes=tuple(getattr(log, "notes", ())),
            window_names=tuple(names),
            first_row=tuple(getattr(r, "first_row", 0) for r in runs),
        )


def _noise_step(thetas, times) -> float:
    """An equivalent encoder step ``√12·σ`` for readings on no grid (interpolated or
    analog): ``σ`` from the scatter about a 7-point local cubic (Savitzky–Golay at a
    uniform period, least squares at the logged times otherwise), robustly (median
    absolute deviation) and corrected for the fit's own share of the noise (for white
    noise the residual variance is ``σ²·(1 − h₀)``, ``h₀`` the filter's centre weight).
    A smooth trajectory sampled fast leaves almost nothing but noise there, so this is
    an upper bound of the sensor's floor in the log's own units."""
    from scipy.signal import savgol_coeffs

    res = []
    for th, t in zip(thetas, times):
        th = np.asarray(th, dtype=float)
        if th.size >= 7:
            res.append(th - local_cubic(np.asarray(t, dtype=float), th, 7)[0])
    if not res:
        return 1.0
    r = np.concatenate(res)
    h0 = float(savgol_coeffs(7, 3)[3])
    sigma = 1.4826 * float(np.median(np.abs(r - np.median(r)))) / math.sqrt(1.0 - h0)
    if not sigma > 0:
        spans = [np.ptp(np.asarray(t, dtype=float)) for t in thetas]
        sigma = 1e-9 * max(max(spans), 1e-300)
    return sigma * math.sqrt(12.0)


def _smooth_speed(theta: np.ndarray, time: np.ndarray) -> np.ndarray:
    """Local-cubic speed of a logged angle at the logged times — for starting values and
    signs only."""
    w = min(7, theta.size - (1 - theta.size % 2))
    if w < 5:
        return np.zeros_like(theta)
    return local_cubic(np.asarray(time, dtype=float), np.asarray(theta, dtype=float), w)[1]


def local_cubic(t: np.ndarray, y: np.ndarray, window: int,
                second: bool = False) -> tuple[np.ndarray, ...]:
    """Value and first derivative (and with ``second`` the second derivative) of a cubic
    fitted by least squares to ``window`` (odd) samples about each sample (the first and
    last windows serve the edges).

    At a uniform period this is the Savitzky–Golay filter (``mode="interp"``), and that is
    what runs; at jittered or gapped times the same fit is made at the logged times.
    """
    from scipy.signal import savgol_filter

    steps = np.diff(t)
    h = float(np.median(steps))
    if np.all(np.abs(steps - h) <= 1e-6 * h):
        out = (savgol_filter(y, window, 3), savgol_filter(y, window, 3, deriv=1, delta=h))
        return out + (savgol_filter(y, window, 3, deriv=2, delta=h),) if second else out
    n, half = y.size, window // 2
    centre = np.clip(np.arange(n), half, n - 1 - half)
    idx = centre[:, None] + np.arange(-half, half + 1)[None, :]
    x = (t[idx] - t[:, None]) / h  # about each sample, in periods
    V = x[..., None] ** np.arange(4)  # (n, window, 4)
    coef = np.einsum("nkw,nw->nk", np.linalg.pinv(V), y[idx])
    out = (coef[:, 0], coef[:, 1] / h)
    return out + (2.0 * coef[:, 2] / h**2,) if second else out


class DrivenProblem(AbstractProblem):
    """Residuals of one driven log for a :class:`DrivenJoint` whose ``free`` parameters
    are fitted.

    Unknowns ``u``: the free parameters (transformed), then per window the true WG angle
    at its first sample (in encoder steps from the logged one) and its velocity
    (in units of the log's speed scale ``omega_scale``). Residuals, all in units of their quantization σ:

    * WG angle: simulated (eq. 9, from the logged torque, per window) − logged;
    * output: the kinematic error ``θ_out + θ/N`` logged − modelled
      (``T_k⁻¹(τ_l + τ_fout·s) + θ̃_p(θ)``). Eq. 8 is algebraic in ``θ``, so the logged
      motor angle is used there: the positional error is then not blurred by the
      simulation's small angle errors; ``s`` comes from the simulation.

    then weak-prior rows.
    """

    base: DrivenJoint
    times: Float[Array, "W T"]
    theta: Float[Array, "W T"]
    motor_torque: Float[Array, "W T"]
    load_torque: Float[Array, "W T"]
    theta_out: Float[Array, "W T"]
    weight: Float[Array, "W T"]
    direction0: Float[Array, " W"]
    moving0: Float[Array, " W"]
    step: Float[Array, ""]
    sigma_kin: Float[Array, ""]
    omega_scale: Float[Array, ""]
    #: Multiplies the quantization σ of the WG residuals: 1, or the residual scatter in
    #: units of σ once a fit shows the model error dominates (so that the solver's
    #: statistical stop and the weak priors work in units of the real scatter).
    noise_scale: Float[Array, ""]
    prior_mean: Float[Array, " P"]
    prior_sd: Float[Array, " P"]
    prior_on: Array
    free: tuple[str, ...] = eqx.field(static=True)
    sim_index: tuple[int, ...] = eqx.field(static=True)
    kin_index: tuple[int, ...] = eqx.field(static=True)
    has_output: bool = eqx.field(static=True)
    substeps: int = eqx.field(static=True)
    input_hold: str = eqx.field(static=True, default="zoh")

    @property
    def n_runs(self) -> int:
        """Number of simulation windows."""
        return self.times.shape[0]

    @property
    def n_physical(self) -> int:
        return len(self.free)

    @property
    def n_unknowns(self) -> int:
        return self.n_physical + 2 * self.n_runs

    @property
    def sigma(self):
        return self.noise_scale * self.step / jnp.sqrt(12.0)

    def labels(self, window_names) -> list[str]:
        return (list(self.free) + [f"theta0[{n}]" for n in window_names]
                + [f"omega0[{n}]" for n in window_names])

    # -- layout ---------------------------------------------------------------------
    def _values(self, names, u, xp=jnp):
        specs = self.base.parameter_specs()
        return {n: from_unconstrained(specs[n], u[i], xp) for i, n in zip(range(len(u)), names)}

    def unpack(self, u, xp=jnp):
        P, R = self.n_physical, self.n_runs
        values = self._values(self.free, u[:P], xp)
        theta0 = self.theta[:, 0] + self.step * u[P : P + R]
        omega0 = self.moving0 * self.omega_scale * u[P + R : P + 2 * R]
        return values, theta0, omega0

    def joint(self, u) -> DrivenJoint:
        values, *_ = self.unpack(u)
        return self.base.replace(**values) if values else self.base

    def values_np(self, u) -> dict[str, float]:
        u = np.asarray(u, dtype=float)
        values = self._values(self.free, u[: self.n_physical], np)
        fixed = self.base.float_values()
        return {**fixed, **{k: float(v) for k, v in values.items()}}

    # -- forward model --------------------------------------------------------------
    def _simulate_window(self, joint, t, td, tl, th0, om0, d0):
        return simulate_driven(
            joint, t, td, tl, th0, om0, output_direction0=d0, substeps=self.substeps,
            full_output=True, input_hold=self.input_hold,
        )

    def simulate(self, u):
        values, theta0, omega0 = self.unpack(u)
        joint = self.base.replace(**values) if values else self.base
        run = jax.vmap(lambda *a: self._simulate_window(joint, *a))
        sim = run(self.times, self.motor_torque, self.load_torque, theta0, omega0, self.direction0)
        return joint, sim

    def _kin_residuals(self, u, direction):
        joint = self.joint(u)
        measured = self.theta_out + self.theta / joint.ratio
        model = joint.kinematic_error(self.theta, self.load_torque, direction)
        return (self.weight * (measured - model) / self.sigma_kin).ravel()

    def prior_residuals(self, u):
        z = (u[: self.n_physical] - self.prior_mean) / self.prior_sd
        return jnp.where(self.prior_on, z, 0.0)

    def residuals(self, u):
        _, sim = self.simulate(u)
        parts = [(self.weight * (sim["theta"] - self.theta) / self.sigma).ravel()]
        if self.has_output:
            parts.append(self._kin_residuals(u, jax.lax.stop_gradient(sim["output_direction"])))
        parts.append(self.prior_residuals(u))
        return jnp.concatenate(parts)

    def residuals_and_jacobian(self, u):
        """Residuals and their Jacobian, block-structured like the free-motion problem:
        each window depends only on the parameters the WG simulation sees and on its own
        start angle and velocity, so forward mode carries ``P_sim + 2`` tangents per
        window (vmapped), not every unknown through every window; the output rows are
        algebraic and see only the spring, output friction and positional error."""
        P, W = self.n_physical, self.n_runs
        sim_phys = [i for i in self.sim_index if i < P]
        ps = len(sim_phys)
        names = tuple(self.free[i] for i in sim_phys)
        local = jnp.concatenate([
            jnp.broadcast_to(u[jnp.asarray(sim_phys, dtype=int)], (W, ps)),
            u[P : P + W, None], u[P + W : P + 2 * W, None],
        ], axis=1)
        base = self.joint(u)

        def one(loc, t, th, td, tl, wt, th_first, d0, mov):
            vals = self._values(names, loc[:ps])
            joint = base.replace(**vals) if vals else base
            th0 = th_first + self.step * loc[ps]
            om0 = mov * self.omega_scale * loc[ps + 1]
            sim = self._simulate_window(joint, t, td, tl, th0, om0, d0)
            r = wt * (sim["theta"] - th) / self.sigma
            return r, (r, sim["output_direction"])

        J_loc, (r_wg, direction) = jax.vmap(jax.jacfwd(one, has_aux=True))(
            local, self.times, self.theta, self.motor_torque, self.load_torque, self.weight,
            self.theta[:, 0], self.direction0, self.moving0,
        )
        T = self.times.shape[1]
        n = self.n_unknowns
        idx = jnp.arange(W)
        J = jnp.zeros((W, T, n))
        if ps:
            J = J.at[:, :, jnp.asarray(sim_phys)].set(J_loc[:, :, :ps])
        J = J.at[idx, :, P + idx].set(J_loc[:, :, ps])
        J = J.at[idx, :, P + W + idx].set(J_loc[:, :, ps + 1])
        rs, Js = [r_wg.reshape(-1)], [J.reshape(W * T, n)]
        if self.has_output:
            direction = jax.lax.stop_gradient(direction)
            kidx = jnp.asarray(self.kin_index, dtype=int)

            def kin(uk):
                return self._kin_residuals(u.at[kidx].set(uk), direction)

            rk = kin(u[kidx])
            Jk = jax.jacfwd(kin)(u[kidx])
            rs.append(rk)
            Js.append(jnp.zeros((rk.shape[0], n)).at[:, kidx].set(Jk))
        rs.append(self.prior_residuals(u))
        Js.append(jnp.zeros((P, n)).at[:, :P].set(
            jnp.diag(jnp.where(self.prior_on, 1.0 / self.prior_sd, 0.0))))
        return jnp.concatenate(rs), jnp.concatenate(Js, axis=0)


def build_driven_problem(
    data: DrivenData, base: DrivenJoint, free: tuple[str, ...],
    priors: dict[str, tuple[float, float]], max_substep: float | None = None,
    input_hold: str = "zoh",
) -> DrivenProblem:
    spring_names = {p.name for p in base.spring.parameters}
    pos_names = set(base.positional.names())
    P = len(free)
    sim_index = tuple(
        [i for i, n in enumerate(free) if n not in spring_names and n not in pos_names]
        + list(range(P, P + 2 * data.n_runs))
    )
    kin_index = tuple(
        i for i, n in enumerate(free) if n in spring_names or n in pos_names or n == "tau_fout"
    )
    mean = np.array([priors[n][0] if n in priors else 0.0 for n in free])
    sd = np.array([priors[n][1] if n in priors else 1.0 for n in free])
    on = np.array([n in priors for n in free], dtype=bool)
    base = jax.tree_util.tree_map(lambda x: jnp.asarray(x, dtype=float), base)
    out = data.theta_out if data.has_output else np.zeros_like(data.theta)
    return DrivenProblem(
        base=base,
        times=jnp.asarray(data.times),
        theta=jnp.asarray(data.theta),
        motor_torque=jnp.asarray(data.motor_torque),
        load_torque=jnp.asarray(data.load_torque),
        theta_out=jnp.asarray(out),
        weight=jnp.asarray(data.weight),
        direction0=jnp.asarray(data.direction0, dtype=float),
        moving0=jnp.asarray(data.moving0, dtype=float),
        step=jnp.asarray(data.step),
        sigma_kin=jnp.asarray(data.sigma_kinematic(base.ratio)),
        omega_scale=jnp.asarray(float(data.omega_scale)),
        noise_scale=jnp.asarray(1.0),
        prior_mean=jnp.asarray(mean, dtype=float),
        prior_sd=jnp.asarray(sd, dtype=float),
        prior_on=jnp.asarray(on),
        free=tuple(free),
        sim_index=sim_index,
        kin_index=kin_index,
        has_output=data.has_output,
        substeps=substeps_for_times(data.times, max_substep),
        input_hold=input_hold,
    )


class JointProblem(AbstractProblem):
    """Several problems sharing physical parameters: residuals stacked, unknowns mapped.

    ``index[i]`` lists, for each unknown of part ``i``, its position in the joint vector;
    parts that name the same physical parameter share its entry. Each shared
    parameter's weak prior should be counted once (the builder switches the others off).
    """

    parts: tuple
    index: tuple[Array, ...]
    n_unknowns: int = eqx.field(static=True)

    def residuals(self, u):
        return jnp.concatenate([p.residuals(u[i]) for p, i in zip(self.parts, self.index)])

    def residuals_and_jacobian(self, u):
        rs, Js = [], []
        for p, i in zip(self.parts, self.index):
            r, J = p.residuals_and_jacobian(u[i])
            rs.append(r)
            Js.append(jnp.zeros((r.shape[0], self.n_unknowns)).at[:, i].add(J))
        return jnp.concatenate(rs), jnp.concatenate(Js, axis=0)
