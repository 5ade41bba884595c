"""Residual views of a fit: where does the model fail, and is what is left white noise?

Everything here starts from a :class:`~hdid.FitResult` and is read-only. The central
object is the *residual frame* (:func:`residual_frame`): one row per logged sample with
the measurement, the model, the model's state (WG angle from the spring zero, velocity,
output-side deflection) and the phase of the motion. On top of it:

* :func:`whiteness` — is the residual of the *moving* samples white and at the
  quantization floor (Ljung–Box on the pooled autocorrelation, RMS vs ``step/√12``)?
* :func:`spectrum` — pooled periodogram of the moving residual with a white-noise band.
* :func:`residual_features` — numbers describing the residual's *structure* (correlation
  with sign(ω), θ, |θ|, ω; energy near rest; rest-point error; a periodic term in θ) that
  point to the missing effect.
* :func:`plot_residuals`, :func:`plot_rest_approach` — figures.

Why only the moving samples are tested: before the release and after the stick the
encoder reads one constant count, so every sample of such a stretch carries the *same*
rounding error — they are one observation repeated, not independent draws (the fit's
weights already count them as one, see :mod:`hdid._prepare`). Including them would make
any model look strongly autocorrelated.
"""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pandas as pd

#: Two-sided 95 % normal quantile for the ACF band ±1.96/√n.
Z95 = 1.959963984540054
#: Ljung–Box p-value below which the residual is declared not white.
WHITE_ALPHA = 0.01
#: Largest RMS of the moving residual, in units of the quantization floor ``step/√12``,
#: still called "at the floor". For ``n`` independent rounding errors (uniform on
#: ±step/2) the mean square has relative sd ``√(0.8/n)`` (fourth moment 9/5·σ⁴), so the
#: RMS ratio has sd ``≈ √(0.2/n)``: 0.11 for the ~17 moving samples of a 250 Hz,
#: 4-release log, 0.035 for 160 samples at 1 kHz. 1.3 is then ≥ 2.7 sd above 1 — a
#: false alarm rate < 0.5 % for the smallest designs — while a missing effect worth half
#: a count RMS (ratio √(1 + 0.5²/0.289²) ≈ 2) is flagged. A fitted model absorbs some
#: of the noise (the fit has ~4 unknowns per run), which only lowers the ratio.
AT_FLOOR_RATIO = 1.3
#: Default fine simulation rate, in samples per logged sample period, used to find the
#: model's stick instant (then refined by linear extrapolation of ω to zero).
FINE_PER_SAMPLE = 50
#: Lomb–Scargle grid in θ_wg: angular frequencies [1/rad] (= order per WG revolution).
LS_ORDERS = (2.0, 300.0)
LS_POINTS = 3000
#: Window around the model's stick instant shown by :func:`plot_rest_approach` [s].
REST_WINDOW = (-0.1, 0.05)

PHASES = ("hold", "moving", "stuck")
#: The residual figure shows the ACF only when the shortest moving stretch gives at least
#: this many lags (``whiteness``'s ``max_lag = n_min // 4``, i.e. ≥ 12 moving samples per
#: run): a one- or two-lag ACF of a 250 Hz log (4–5 moving samples per run) is dominated
#: by the fit's own projection (expected lag-1 value ≈ −0.5) and says nothing by eye.
MIN_ACF_LAGS = 3
#: ... and the spectrum only when the longest moving stretch gives at least this many
#: frequency bins (``N // 2``): two or three points are no spectrum.
MIN_SPECTRUM_BINS = 8


# ---------------------------------------------------------------------------------------
# the frame
# ---------------------------------------------------------------------------------------
#: Attribute of a :class:`~hdid.FitResult` under which :mod:`hdid._refit` leaves the JAX
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

    from . import _programs

    dense = _parts(result).get("dense") if result is not None else None
    if dense is not None and np.array_equal(np.asarray(times), np.asarray(problem.times)):
        return tuple(np.asarray(x) for x in dense)

    theta, omega, stuck = _programs.call("dense", _dense, problem, jnp.asarray(u),
                                         jnp.asarray(times, dtype=float))
    return np.asarray(theta), np.asarray(omega), np.asarray(stuck)


def _dense(problem, u, times):
    """:func:`hdid._identifiability._dense` (the same program), through the program
    store (:mod:`hdid._programs`: a later process loads it instead of tracing)."""
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


# ---------------------------------------------------------------------------------------
# whiteness
# ---------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Whiteness:
    """Outcome of :func:`whiteness` (see there for the definitions)."""

    n: int
    max_lag: int
    lags: np.ndarray
    acf: np.ndarray
    band: float
    q: float
    p_value: float
    rms_moving_rad: float
    floor_rad: float
    rms_ratio: float
    white: bool
    at_floor: bool
    adequate: bool
    acf_null: np.ndarray | None = None
    rms_null_rad: float = float("nan")

    def to_dict(self) -> dict[str, Any]:
        d = asdict(self)
        for k in ("lags",):
            d[k] = [int(x) for x in self.lags]
        for k in ("acf", "acf_null"):
            v = getattr(self, k)
            d[k] = None if v is None else [float(x) for x in v]
        for k in ("white", "at_floor", "adequate"):
            d[k] = bool(d[k])
        return d


def _acf(r: np.ndarray, max_lag: int) -> np.ndarray:
    r = r - r.mean()
    den = float(np.sum(r**2))
    if den == 0.0:
        return np.zeros(max_lag)
    return np.array([np.sum(r[:-k] * r[k:]) / den if k < r.size else 0.0
                     for k in range(1, max_lag + 1)])


def _null_moving_cov(result, frame: pd.DataFrame) -> list[np.ndarray]:
    """Covariance [rad²] of each run's moving residual if the log were the fitted model
    plus ideal rounding: the linearised fit's residual-maker applied to quantization
    errors, in time order per run (runs as in :func:`_moving_runs`).

    The fit's weighted residuals are ``ε − J (JᵀJ + Λ)⁻¹ Jᵀ ε`` to first order (``J``
    the data Jacobian, ``Λ`` the weak priors' precision); ``ε`` has unit variance on
    every moving sample, while all samples of a constant stretch of the log with the
    model at rest (hold, stuck) share one rounding error.
    """
    import jax.numpy as jnp

    from . import _programs

    prob = result.problem
    jr = _parts(result).get("jacobian")
    J, _ = map(np.asarray, jr if jr is not None else _programs.call(
        "jacobian", _data_jacobian, prob, jnp.asarray(result.u)))
    R, T = np.asarray(prob.times).shape
    P = prob.n_physical
    prior = np.zeros(J.shape[1])
    prior[:P] = np.where(np.asarray(prob.prior_on), 1.0 / np.asarray(prob.prior_sd) ** 2, 0.0)
    A = J.T @ J + np.diag(prior)
    K = J @ np.linalg.pinv(A, rcond=1e-13, hermitian=True)
    w = np.asarray(prob.weight).reshape(-1)
    meas = np.asarray(prob.theta)
    # Independent rounding errors → samples (L: N × m, entries = weights).
    cols = np.full(R * T, -1)
    m = 0
    for i, run in enumerate(result.runs):
        g = frame[frame["run"] == run.name]
        still = (g["phase"] != "moving").to_numpy()
        for t in range(run.n_samples):
            shared = t > 0 and still[t] and still[t - 1] and meas[i, t] == meas[i, t - 1]
            if not shared:
                m += 1
            cols[i * T + t] = m - 1
    rows = np.flatnonzero(cols >= 0)
    L = np.zeros((R * T, m))
    L[rows, cols[rows]] = w[rows]
    JtL = J.T @ L
    sigma = float(prob.sigma)
    out = []
    for i, run in enumerate(result.runs):
        g = frame[frame["run"] == run.name]
        idx = np.flatnonzero((g["phase"] == "moving").to_numpy())
        if idx.size < 2:
            continue
        idx = idx[np.argsort(g["t"].to_numpy()[idx])]
        S = i * T + idx
        ws = np.where(w[S] > 0, w[S], 1.0)
        MS = L[S] - K[S] @ JtL  # weighted residual rows as a map of the errors
        MS = MS / ws[:, None] * sigma  # back to rad (residual_rad = −σ r_w / w)
        out.append(MS @ MS.T)
    return out


def _expected_acf(cov: np.ndarray, max_lag: int) -> np.ndarray:
    n = cov.shape[0]
    C = np.eye(n) - 1.0 / n
    G = C @ cov @ C
    tr = float(np.trace(G))
    return np.array([np.trace(G, offset=k) / tr if k < n else 0.0 for k in range(1, max_lag + 1)])


def whiteness(
    result, max_lag: int | None = None, *, frame: pd.DataFrame | None = None
) -> Whiteness:
    """Ljung–Box and quantization-floor test of the residual while the gear moves.

    Only ``moving`` samples are used: the hold before the release and the stuck tail read
    one constant count each, so all their samples share a single quantization error and
    are not independent observations (they would look perfectly autocorrelated whatever
    the model). Per run the residual's mean is removed and its autocorrelation
    ``c_i(k) = Σ r_t r_{t+k} / Σ r_t²`` computed; runs are pooled weighted by their
    number of moving samples ``n_i``; ``n = Σ n_i``.

    A *fitted* residual is not white even when the model is right: removing each run's
    mean biases ``c_i(k)`` by about ``−1/n_i``, and the fit's own unknowns (release,
    start angle, offset per run, shared physics) project part of the noise away. With
    only ~4 moving samples per run at 250 Hz both are large (the pooled lag-1 ACF of a
    correct model is ≈ −0.5). So Q is computed on ``acf − acf_null``, where ``acf_null``
    is the ACF expected if the log were the fitted model plus ideal rounding, from the
    linearised fit (its Jacobian at the optimum; see :func:`_null_moving_cov`). Given a
    frame instead of a result, no such correction is possible and ``acf_null`` is 0.

    Parameters
    ----------
    result:
        A :class:`~hdid.FitResult` (or a frame from :func:`residual_frame`).
    max_lag:
        Largest lag; default ``min(10, n_min // 4)`` (at least 1), ``n_min`` the shortest
        moving stretch — at 250 Hz the gear stops within ~5 samples, so this is 1 and
        the test has little power: ``at_floor`` then carries most of the verdict.
    frame:
        The result's :func:`residual_frame`, if already computed.

    Returns
    -------
    Whiteness
        ``acf`` at ``lags`` 1…max_lag with the white-noise ``band = 1.96/√n`` (around
        ``acf_null``); Ljung–Box ``q = n(n+2) Σ (acf_k − acf_null_k)²/(n−k)`` and its
        ``p_value`` from χ²(max_lag); ``rms_moving_rad`` (mean *not* removed),
        ``floor_rad = step/√12``, ``rms_ratio``; ``rms_null_rad``, the RMS expected for a
        correct model (below the floor: the fit absorbs part of the noise);
        ``white = p ≥ 0.01``, ``at_floor = rms_ratio ≤ 1.3`` (:data:`AT_FLOOR_RATIO`
        explains the margin), ``adequate = white and at_floor``.

    Notes
    -----
    Rounding a smooth signal that moves less than about one count per sample is not
    white either (the error changes slowly); the moving phase of a free-motion test
    moves tens of counts per sample except at the reversals.
    """
    from scipy.stats import chi2

    is_frame = isinstance(result, pd.DataFrame)
    frame = _frame(result) if frame is None else frame
    step = float(frame.attrs.get("resolution_rad", getattr(result, "resolution_rad", np.nan)))
    runs = _moving_runs(frame)
    floor = step / math.sqrt(12.0)
    if not runs:
        nan = float("nan")
        return Whiteness(0, 0, np.zeros(0, int), np.zeros(0), nan, nan, nan, nan, floor,
                         nan, False, False, False)
    lengths = np.array([r.size for r in runs])
    n = int(lengths.sum())
    if max_lag is None:
        max_lag = min(10, int(lengths.min()) // 4)
    max_lag = max(1, int(max_lag))
    acfs = np.array([_acf(r, max_lag) for r in runs])
    acf = (lengths[:, None] * acfs).sum(axis=0) / n
    lags = np.arange(1, max_lag + 1)
    rms_null = float("nan")
    if is_frame:
        acf_null = np.zeros(max_lag)
    else:
        covs = _null_moving_cov(result, frame)
        expected = np.array([_expected_acf(c, max_lag) for c in covs])
        acf_null = (lengths[:, None] * expected).sum(axis=0) / n
        rms_null = float(np.sqrt(sum(np.trace(c) for c in covs) / n))
    q = float(n * (n + 2) * np.sum((acf - acf_null) ** 2 / np.maximum(n - lags, 1)))
    p = float(chi2.sf(q, max_lag))
    rms = float(np.sqrt(np.mean(np.concatenate(runs) ** 2)))
    ratio = rms / floor
    white = p >= WHITE_ALPHA
    at_floor = ratio <= AT_FLOOR_RATIO
    return Whiteness(
        n=n, max_lag=max_lag, lags=lags, acf=acf, band=Z95 / math.sqrt(n), q=q, p_value=p,
        rms_moving_rad=rms, floor_rad=floor, rms_ratio=float(ratio), white=bool(white),
        at_floor=bool(at_floor), adequate=bool(white and at_floor), acf_null=acf_null,
        rms_null_rad=rms_null,
    )


@dataclass(frozen=True)
class Spectrum:
    """Pooled periodogram of the moving residual (see :func:`spectrum`)."""

    frequency: np.ndarray
    power: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    level: float
    dof: float

    def __iter__(self):  # ``f, p, lo, hi = spectrum(fit)``
        return iter((self.frequency, self.power, self.lower, self.upper))


def spectrum(result) -> Spectrum:
    """Pooled one-sided periodogram [rad²/Hz] of the moving residual, with a white band.

    Every run's moving residual (mean removed) is transformed on the common frequency
    grid ``k·fs/N`` (``N`` the longest moving stretch, ``k = 1 … N/2``; shorter runs are
    zero-padded), ``P_i(f) = 2|Σ r_t e^{−2πi f t}|² / (fs n_i)``, and the runs are
    averaged weighted by ``n_i``. White noise of the pooled variance ``σ²`` has
    ``E P = 2σ²/fs`` (``level``) and each ``P_i`` is ``level·χ²₂/2``; the weighted mean is
    treated as ``level·χ²_ν/ν`` with ``ν = 2(Σn_i)²/Σn_i²`` (``dof``), giving the 95 %
    band ``lower``/``upper``.

    Returns
    -------
    Spectrum
        ``frequency`` [Hz], ``power``, ``lower``, ``upper``, ``level``, ``dof``; iterable
        as ``(frequency, power, lower, upper)``.
    """
    from scipy.stats import chi2

    frame = _frame(result)
    fs = 1.0 / float(frame.attrs["sample_period"])
    runs = [r - r.mean() for r in _moving_runs(frame)]
    if not runs:
        e = np.zeros(0)
        return Spectrum(e, e, e, e, float("nan"), float("nan"))
    lengths = np.array([r.size for r in runs], dtype=float)
    N = int(lengths.max())
    k = np.arange(1, N // 2 + 1)
    freq = k * fs / N
    power = np.zeros(k.size)
    for r in runs:
        t = np.arange(r.size)
        ft = np.exp(-2j * np.pi * np.outer(k / N, t)) @ r
        power += r.size * 2.0 * np.abs(ft) ** 2 / (fs * r.size)
    power /= lengths.sum()
    var = float(np.sum([np.sum(r**2) for r in runs]) / lengths.sum())
    level = 2.0 * var / fs
    nu = 2.0 * lengths.sum() ** 2 / np.sum(lengths**2)
    lo = level * chi2.ppf(0.025, nu) / nu
    hi = level * chi2.ppf(0.975, nu) / nu
    return Spectrum(freq, power, np.full(k.size, lo), np.full(k.size, hi), level, float(nu))


# ---------------------------------------------------------------------------------------
# structure of the residual
# ---------------------------------------------------------------------------------------
def _corr(x: np.ndarray, y: np.ndarray) -> float:
    x = np.asarray(x, float)
    y = np.asarray(y, float)
    if x.size < 3 or np.std(x) == 0 or np.std(y) == 0:
        return float("nan")
    return float(np.corrcoef(x, y)[0, 1])


def _sinusoid_share(x: np.ndarray, y: np.ndarray, w: float) -> float:
    """Share of the variance of ``y`` explained by ``a + b sin(w x) + c cos(w x)``."""
    A = np.column_stack([np.ones_like(x), np.sin(w * x), np.cos(w * x)])
    coef, *_ = np.linalg.lstsq(A, y, rcond=None)
    tss = float(np.sum((y - y.mean()) ** 2))
    return float(1.0 - np.sum((y - A @ coef) ** 2) / tss) if tss > 0 else float("nan")


def residual_features(frame: pd.DataFrame) -> dict[str, float]:
    """Numbers describing the structure of a residual, to tell which effect is missing.

    Correlations are Pearson coefficients over the ``moving`` samples of all runs
    (about ±2/√n for a white residual of ``n`` samples). Keys:

    ``corr_sign_omega``
        residual vs sign(ω): a missing or mis-sized Coulomb/Stribeck friction level.
    ``corr_theta``
        residual vs θ_wg: a missing odd (linear/cubic) spring term.
    ``corr_abs_theta``
        residual vs |θ_wg|: a missing even part (asymmetry between the two sides).
    ``corr_omega``
        residual vs ω: a missing viscous (velocity-proportional) term.
    ``near_rest_energy_share``
        Σr² over the last 20 % of each run's moving time / Σr² over all moving samples
        (≈ the share of samples there, about 0.2, for a white residual): friction shape
        near zero velocity (Stribeck) shows up as error concentrated near rest.
    ``stuck_mean_counts``
        mean over runs of each run's mean stuck-phase residual [counts] (rest-point error;
        for a run where the model never sticks, over the log's final constant stretch).
    ``stuck_signed_counts``
        the same with each run's error multiplied by sign(θ0): > 0 when the logged rest
        lies further towards the release side than the model's (too little friction).
    ``stuck_sign_agreement``
        share of runs whose rest-point error has the sign of θ0 (θ0 = θ_wg at the hold).
    ``theta_peak_order``
        angular frequency [1/rad] (= periods per WG revolution) of the largest
        Lomb–Scargle peak of the moving residual vs θ_wg over orders 2…300: a
        position-periodic effect (cogging, WG ripple).
    ``theta_peak_share``
        share of the moving residual's variance explained by a sinusoid at that order.
    ``n_moving``
        number of moving samples the statistics use.
    """
    from scipy.signal import lombscargle

    nan = float("nan")
    mov = frame[frame["phase"] == "moving"]
    r = mov["residual_rad"].to_numpy(float)
    th = mov["theta_wg"].to_numpy(float)
    om = mov["omega"].to_numpy(float)
    nz = om != 0
    out: dict[str, float] = {
        "corr_sign_omega": _corr(r[nz], np.sign(om[nz])),
        "corr_theta": _corr(r, th),
        "corr_abs_theta": _corr(r, np.abs(th)),
        "corr_omega": _corr(r, om),
    }
    # Energy near rest: last 20 % of each run's moving time span.
    num = den = 0.0
    for _, g in mov.groupby("run", sort=False, observed=True):
        ts = g["t_since_release"].to_numpy(float)
        rr = g["residual_rad"].to_numpy(float)
        end = g["t_to_stick"].to_numpy(float)
        span = ts.max() if not np.all(np.isfinite(end)) else float(ts[0] - end[0])
        num += float(np.sum(rr[ts >= 0.8 * span] ** 2))
        den += float(np.sum(rr**2))
    out["near_rest_energy_share"] = num / den if den > 0 else nan
    # Rest-point error.
    errs, signs = [], []
    for _, g in frame.groupby("run", sort=False, observed=True):
        g = g.sort_values("t")
        hold = g[g["phase"] == "hold"]
        rest = g[g["phase"] == "stuck"]
        if rest.empty:
            # The model never sticks: use the log's final constant stretch instead.
            after = g[g["phase"] != "hold"]
            meas = after["measured"].to_numpy(float)
            if meas.size == 0:
                continue
            moved = np.flatnonzero(meas != meas[-1])
            rest = after.iloc[int(moved[-1]) + 1 if moved.size else 0:]
        theta0 = float(hold["theta_wg"].iloc[0]) if not hold.empty else float(g["theta_wg"].iloc[0])
        errs.append(float(rest["residual_counts"].mean()))
        signs.append(float(np.sign(theta0)))
    if errs:
        e, s = np.array(errs), np.array(signs)
        out["stuck_mean_counts"] = float(e.mean())
        out["stuck_signed_counts"] = float(np.mean(e * s))
        out["stuck_sign_agreement"] = float(np.mean(np.sign(e) == s))
    else:
        out["stuck_mean_counts"] = out["stuck_signed_counts"] = out["stuck_sign_agreement"] = nan
    # Periodic term in θ_wg.
    if r.size >= 5 and np.ptp(th) > 0 and np.std(r) > 0:
        w = np.linspace(*LS_ORDERS, LS_POINTS)
        p = lombscargle(th, r - r.mean(), w)
        k = int(np.argmax(p))
        out["theta_peak_order"] = float(w[k])
        out["theta_peak_share"] = _sinusoid_share(th, r, float(w[k]))
    else:
        out["theta_peak_order"] = out["theta_peak_share"] = nan
    out["n_moving"] = float(r.size)
    return out


# ---------------------------------------------------------------------------------------
# figures
# ---------------------------------------------------------------------------------------
def _figure(path, **kw):
    """A new figure: pyplot's when shown (no ``path``), else a bare one (no backend)."""
    from ._plot import _new_figure

    if path is None:
        import matplotlib.pyplot as plt

        return _new_figure(plt, **kw)
    return _new_figure(None, **kw)


def plot_residuals(result, path=None, *, axes=None):
    """Residual [counts] against time, WG angle, velocity and output deflection; ACF; spectrum.

    The ACF is drawn only with at least ``MIN_ACF_LAGS`` lags and the spectrum with at
    least ``MIN_SPECTRUM_BINS`` frequency bins. A log with fewer moving samples per run
    (250 Hz: 4–5) gets what it can support instead: the distribution of the pooled
    moving residual against ideal rounding, and each run's moving RMS against the
    floor with the range ideal rounding gives for that run's sample count.

    Parameters
    ----------
    result:
        A :class:`~hdid.FitResult`.
    path:
        Save the figure here if given.
    axes:
        Six matplotlib axes (any shape, read row-major) to draw into; a new 2×3 figure
        otherwise.

    Returns
    -------
    matplotlib.figure.Figure
    """
    frame = residual_frame(result)
    wt = whiteness(result, frame=frame)
    sp = spectrum(frame)
    if axes is None:
        axes = _figure(path, figsize=(13, 7)).subplots(2, 3)
    axes = np.asarray(axes).ravel()
    if axes.size != 6:
        raise ValueError(f"axes: need 6 axes, got {axes.size}")
    fig = axes[0].figure
    ax_t, ax_th, ax_om, ax_def, ax_acf, ax_sp = axes
    colors = {"hold": "0.6", "moving": "C0", "stuck": "C3"}
    for name, g in frame.groupby("run", sort=False, observed=True):
        ax_t.plot(g["t_since_release"], g["residual_counts"], ".-", ms=3, lw=0.6,
                  label=f"run {name}")
    mov = frame[frame["phase"] == "moving"]
    for ax, col, lab in ((ax_th, "theta_wg", "WG angle from spring zero (model) [rad]"),
                         (ax_om, "omega", "WG velocity (model) [rad/s]"),
                         (ax_def, "deflection_out", "output deflection θ_wg/N [mrad]")):
        scale = 1e3 if col == "deflection_out" else 1.0
        for ph in PHASES:
            g = frame[frame["phase"] == ph]
            if len(g):
                ax.plot(scale * g[col], g["residual_counts"], ".", ms=3.5, color=colors[ph],
                        label=ph)
        ax.set_xlabel(lab)
    for ax in (ax_t, ax_th, ax_om, ax_def):
        for y in (-0.5, 0.5):
            ax.axhline(y, color="k", lw=0.6, ls="--")
        ax.axhline(0.0, color="k", lw=0.4)
        ax.set_ylabel("measured − model [counts]")
    ax_t.set_xlabel("time since release [s]")
    ax_t.set_title("residual vs time (±½ count dashed)", fontsize=9)
    ax_t.legend(fontsize=7)
    ax_th.legend(fontsize=7)
    ax_th.set_title("vs WG angle", fontsize=9)
    ax_om.set_title("vs velocity", fontsize=9)
    ax_def.set_title(f"vs output deflection ({len(mov)} moving samples)", fontsize=9)
    if wt.n and wt.max_lag >= MIN_ACF_LAGS:
        null = np.zeros(wt.max_lag) if wt.acf_null is None else wt.acf_null
        ax_acf.bar(wt.lags, 2 * wt.band, bottom=null - wt.band, width=0.8, color="0.85",
                   label="95 % white band")
        ax_acf.bar(wt.lags, wt.acf, width=0.35, color="C0", label="ACF")
        ax_acf.plot(wt.lags, null, "_", ms=18, mew=2, color="k", label="expected, correct model")
        ax_acf.set_xticks(wt.lags)
        ax_acf.legend(fontsize=7)
        ax_acf.axhline(0, color="k", lw=0.5)
        ax_acf.set_xlabel("lag [samples]")
        ax_acf.set_ylabel("ACF of moving residual")
        ax_acf.set_title(
            f"Ljung–Box Q={wt.q:.2f}, p={wt.p_value:.3g}; RMS/floor {wt.rms_ratio:.2f}",
            fontsize=9,
        )
    else:
        _plot_rounding_histogram(ax_acf, frame, wt)
    if sp.frequency.size >= MIN_SPECTRUM_BINS:
        ax_sp.fill_between(sp.frequency, sp.lower, sp.upper, color="0.85", label="white 95 %")
        ax_sp.plot(sp.frequency, sp.power, "o-", ms=3, color="C0", label="periodogram")
        ax_sp.set_yscale("log")
        ax_sp.legend(fontsize=7)
        ax_sp.set_xlabel("frequency [Hz]")
        ax_sp.set_ylabel("power [rad²/Hz]")
        ax_sp.set_title("spectrum of moving residual", fontsize=9)
    else:
        _plot_run_rms(ax_sp, frame, sp.frequency.size)
    verdict = "adequate" if wt.adequate else "NOT adequate"
    fig.suptitle(
        f"{result.source}: residuals — {verdict} (white={wt.white}, at floor={wt.at_floor})",
        fontsize=10,
    )
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig


def _plot_rounding_histogram(ax, frame: pd.DataFrame, wt) -> None:
    """What a log too short per run for an ACF still supports: the distribution of the
    pooled moving residual [counts] against ideal rounding (uniform on ±½ count)."""
    mov = frame.loc[frame["phase"] == "moving", "residual_counts"].to_numpy(dtype=float)
    if mov.size:
        lim = max(1.0, float(np.ceil(np.max(np.abs(mov)) * 2) / 2))
        ax.hist(mov, bins=np.arange(-lim, lim + 1e-9, 0.25), density=True, color="C0",
                alpha=0.7, label=f"moving residual ({mov.size} samples)")
    ax.plot([-0.5, -0.5, 0.5, 0.5], [0, 1, 1, 0], color="k", lw=1.2,
            label="ideal rounding (uniform ±½ count)")
    ax.set_xlabel("measured − model [counts]")
    ax.set_ylabel("density")
    ax.legend(fontsize=7)
    lags = wt.max_lag if wt.n else 0
    ax.set_title(
        f"no ACF: {lags} lag(s) per run carry no evidence; RMS/floor {wt.rms_ratio:.2f}",
        fontsize=9,
    )


def _plot_run_rms(ax, frame: pd.DataFrame, n_bins: int) -> None:
    """Per-run RMS of the moving residual against the floor ``1/√12`` count, with the
    95 % range of ``n`` ideal rounding errors (RMS² ~ σ²·χ²ₙ/n as a normal proxy:
    ``σ²(1 ± 1.96·√(0.8/n))``, the uniform's fourth moment) — in place of a spectrum that
    would have ``n_bins`` points."""
    from scipy.stats import norm

    z = norm.ppf(0.975)
    floor = 1.0 / math.sqrt(12.0)
    names, rms, lo, hi = [], [], [], []
    mov = frame[frame["phase"] == "moving"]
    for name, g in mov.groupby("run", sort=False, observed=True):
        r = g["residual_counts"].to_numpy(dtype=float)
        if r.size == 0:
            continue
        names.append(str(name))
        rms.append(math.sqrt(float(np.mean(r**2))))
        half = z * math.sqrt(0.8 / r.size)
        lo.append(floor * math.sqrt(max(1.0 - half, 0.0)))
        hi.append(floor * math.sqrt(1.0 + half))
    x = np.arange(len(names))
    if names:
        ax.bar(x, np.array(hi) - np.array(lo), bottom=lo, width=0.8, color="0.85",
               label="95 % range, ideal rounding")
        ax.plot(x, rms, "o", color="C0", label="moving RMS")
        ax.set_xticks(x, names, rotation=30, ha="right", fontsize=7)
    ax.axhline(floor, color="k", lw=0.8, ls="--", label="floor 1/√12 count")
    ax.set_ylim(bottom=0.0)
    ax.set_ylabel("RMS [counts]")
    ax.legend(fontsize=7)
    ax.set_title(f"no spectrum ({n_bins} frequency bin(s)): RMS per run", fontsize=9)


def plot_rest_approach(result, path=None, *, ax=None, window: tuple[float, float] = REST_WINDOW):
    """Residual [counts] vs time to the model's stick instant, per run, around rest.

    Parameters
    ----------
    result:
        A :class:`~hdid.FitResult`.
    path:
        Save the figure here if given.
    ax:
        Axes to draw into; a new figure otherwise.
    window:
        ``(before, after)`` the stick instant [s].

    Returns
    -------
    matplotlib.figure.Figure
    """
    frame = residual_frame(result)
    if ax is None:
        fig = _figure(path, figsize=(6.5, 3.6))
        ax = fig.subplots()
    else:
        fig = ax.figure
    drawn = 0
    for name, g in frame.groupby("run", sort=False, observed=True):
        s = g[(g["t_to_stick"] >= window[0]) & (g["t_to_stick"] <= window[1])]
        if len(s):
            ax.plot(s["t_to_stick"], s["residual_counts"], "o-", ms=3, lw=0.7, label=f"run {name}")
            drawn += 1
    ax.axvline(0.0, color="k", lw=0.8, ls=":")
    for y in (-0.5, 0.5):
        ax.axhline(y, color="k", lw=0.6, ls="--")
    ax.set_xlim(*window)
    ax.set_xlabel("time relative to the model's stick [s]")
    ax.set_ylabel("measured − model [counts]")
    ax.set_title("approach to rest" + ("" if drawn else " (the model never sticks)"), fontsize=9)
    if drawn:
        ax.legend(fontsize=7)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=110)
    return fig
