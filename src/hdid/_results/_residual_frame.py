"""The residual frame of a fit: measured against model, sample by sample.

:func:`residual_frame` gives one row per logged sample with the measurement, the model,
the model's state (WG angle from the spring zero, velocity, output-side deflection) and
the phase of the motion; :func:`stick_times` the model's stick instant of every run. The
whiteness test, the spectrum, the features (:mod:`hdid._results._whiteness`) and the figures
(:mod:`hdid._results._residual_plots`) all read this frame.
"""

from __future__ import annotations

import numpy as np
import pandas as pd


#: Default fine simulation rate, in samples per logged sample period, used to find the
#: model's stick instant (then refined by linear extrapolation of ω to zero).
FINE_PER_SAMPLE = 50

PHASES = ("hold", "moving", "stuck")


# ---------------------------------------------------------------------------------------
# the frame
# ---------------------------------------------------------------------------------------
#: Attribute of a :class:`~hdid.FitResult` under which :mod:`hdid._fitting._refit` leaves the JAX
#: parts its analysis computed (``u``, the data Jacobian, the simulation at the log's
#: times and on :func:`stick_times`'s grid ``(grid, (θ, ω, stuck))``), so that the residual frame and the whiteness test reuse them instead of
#: running a program of their own per model structure.
PARTS = "_jax_parts"


def _parts(result) -> dict:
    """The JAX parts left on ``result`` (:data:`PARTS`) if computed at its ``u``, else {}."""
    parts = getattr(result, PARTS, None)
    if parts and np.array_equal(np.asarray(parts["u"]), np.asarray(result.u)):
        return parts
    return {}


def _state_at(problem, u, times, result=None):
    """Model WG angle from the spring zero, velocity and stuck flag at ``times`` (R, T')."""
    import jax.numpy as jnp

    from .._problems import _programs

    dense = _parts(result).get("dense") if result is not None else None
    if dense is not None and np.array_equal(np.asarray(times), np.asarray(problem.times)):
        return tuple(np.asarray(x) for x in dense)

    theta, omega, stuck = _programs.call("dense", _dense, problem, jnp.asarray(u),
                                         jnp.asarray(times, dtype=float))
    return np.asarray(theta), np.asarray(omega), np.asarray(stuck)


def _dense(problem, u, times):
    """:func:`hdid._fitting._identifiability._dense` (the same program), through the program
    store (:mod:`hdid._problems._programs`: a later process loads it instead of tracing)."""
    return problem.simulate(u, times, full_output=True)


def _data_jacobian(problem, u):
    r, J = problem.data_residuals_and_jacobian(u)
    return J, r


def fine_times(times, release, n_samples, sample_period: float,
               fine_per_sample: int = FINE_PER_SAMPLE) -> np.ndarray:
    """The grid :func:`stick_times` simulates on ``(R, m)``: from each run's release
    (``release`` [s]) to its last sample, ``fine_per_sample`` points per sample period."""
    times = np.asarray(times)
    dt = sample_period / fine_per_sample
    rel = np.asarray(release, dtype=float)
    ends = np.array([times[i, n - 1] for i, n in enumerate(n_samples)])
    m = int(np.ceil(np.max(ends - rel) / dt)) + 2
    return rel[:, None] + dt * np.arange(m)[None, :]


def stick_times(result, fine_per_sample: int = FINE_PER_SAMPLE) -> np.ndarray:
    """The model's stick instant of every run [s] (NaN where it never sticks in the log).

    The fitted model is simulated on a grid ``fine_per_sample`` times finer than the log,
    from each run's release to its last sample; the stick lies between the last fine
    point still moving and the first one stuck, where ω is extrapolated linearly to 0.
    """
    prob = result.problem
    times = np.asarray(prob.times)
    dt = result.sample_period / fine_per_sample
    ends = np.array([times[i, r.n_samples - 1] for i, r in enumerate(result.runs)])
    fine = fine_times(times, [r.release_time for r in result.runs],
                      [r.n_samples for r in result.runs], result.sample_period, fine_per_sample)
    cached = _parts(result).get("dense_fine")
    # (the analysis made its grid from the same release instants, unpacked in NumPy:
    # equal to rounding, 1e-12 s ≪ the 1e-5 s spacing)
    if cached is not None and cached[0].shape == fine.shape and np.allclose(
            cached[0], fine, rtol=0.0, atol=1e-12):
        _, omega, stuck = (np.asarray(x) for x in cached[1])
    else:
        _, omega, stuck = _state_at(prob, result.u, fine)
    out = np.full(len(result.runs), np.nan)
    for i in range(len(result.runs)):
        # Index 0 is the release itself (stuck is False there by construction).
        hit = np.flatnonzero(stuck[i, 1:] & (fine[i, 1:] <= ends[i] + dt))
        if hit.size == 0:
            continue
        k = int(hit[0]) + 1
        t_prev = fine[i, k - 1]
        if k >= 3 and omega[i, k - 1] != 0 and omega[i, k - 2] != omega[i, k - 1]:
            # ω(t) is close to linear over the last fine steps before the stop.
            frac = omega[i, k - 1] / (omega[i, k - 2] - omega[i, k - 1])
            out[i] = t_prev + dt * float(np.clip(frac, 0.0, 1.0))
        else:
            out[i] = t_prev if k == 1 else fine[i, k]
    return out


def residual_frame(result) -> pd.DataFrame:
    """Measured vs model, sample by sample, with the model's state and the motion phase.

    Parameters
    ----------
    result:
        A :class:`~hdid.FitResult`.

    Returns
    -------
    pandas.DataFrame
        One row per logged sample of every run (padding excluded), columns:

        ``run``, ``setup``
            Run and set-up names.
        ``t`` [s], ``t_since_release`` [s]
            Log time and time since the fitted release.
        ``t_to_stick`` [s]
            Time relative to the model's stick instant of the run (:func:`stick_times`);
            NaN if the model never sticks within the log.
        ``measured``, ``model`` [rad]
            Encoder reading as logged and the model's prediction in the same frame.
        ``residual_rad``, ``residual_counts``
            ``measured − model``, in rad and in encoder steps.
        ``theta_wg`` [rad], ``omega`` [rad/s], ``deflection_out`` [rad]
            Model WG angle from the spring zero, its velocity (from the simulator, not
            from differencing data) and the output-side deflection ``θ_wg / ratio``.
        ``phase``
            ``"hold"`` before the release, ``"moving"`` from the release to the model's
            stick, ``"stuck"`` afterwards.
        ``weight``
            The fit's weight of the sample (hold and stuck stretches share one).
    """
    prob = result.problem
    times = np.asarray(prob.times)
    meas = np.asarray(prob.theta)
    weight = np.asarray(prob.weight)
    theta_wg, omega, _ = _state_at(prob, result.u, times, result)
    t_stick = stick_times(result)
    ratio = float(result.model.ratio)
    step = float(result.resolution_rad)
    parts = []
    for i, run in enumerate(result.runs):
        n = run.n_samples
        t = times[i, :n]
        model = theta_wg[i, :n] + run.offset
        res = meas[i, :n] - model
        ts = t_stick[i]
        phase = np.where(
            t < run.release_time, "hold", np.where(np.isfinite(ts) & (t >= ts), "stuck", "moving")
        )
        parts.append(
            pd.DataFrame(
                {
                    "run": run.name,
                    "setup": run.setup,
                    "t": t,
                    "t_since_release": t - run.release_time,
                    "t_to_stick": t - ts,
                    "measured": meas[i, :n],
                    "model": model,
                    "residual_rad": res,
                    "residual_counts": res / step,
                    "theta_wg": theta_wg[i, :n],
                    "omega": omega[i, :n],
                    "deflection_out": theta_wg[i, :n] / ratio,
                    "phase": pd.Categorical(phase, categories=PHASES),
                    "weight": weight[i, :n],
                }
            )
        )
    frame = pd.concat(parts, ignore_index=True)
    frame["phase"] = pd.Categorical(frame["phase"], categories=PHASES)
    frame.attrs.update(
        resolution_rad=step, sample_period=float(result.sample_period), ratio=ratio,
        source=result.source,
    )
    return frame


def _frame(obj) -> pd.DataFrame:
    return obj if isinstance(obj, pd.DataFrame) else residual_frame(obj)


def _moving_runs(frame: pd.DataFrame) -> list[np.ndarray]:
    """Moving residuals [rad] per run, in time order (runs with < 2 samples dropped)."""
    mov = frame[frame["phase"] == "moving"]
    out = []
    for _, g in mov.groupby("run", sort=False, observed=True):
        r = g.sort_values("t")["residual_rad"].to_numpy(dtype=float)
        if r.size >= 2:
            out.append(r)
    return out
