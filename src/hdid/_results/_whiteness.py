"""Is what is left white noise at the quantization floor? The whiteness test (Ljung–Box on
the moving samples' pooled autocorrelation against the fitted model's own expected ACF,
RMS against ``step/√12``), the residual spectrum, and the residual's structural features
that point to a missing effect. All read a :func:`hdid._results._residuals.residual_frame`."""

from __future__ import annotations

import math
from dataclasses import asdict, dataclass
from typing import Any

import numpy as np
import pandas as pd

from ._residual_frame import _data_jacobian, _frame, _moving_runs, _parts


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
#: Lomb–Scargle grid in θ_wg: angular frequencies [1/rad] (= order per WG revolution).
LS_ORDERS = (2.0, 300.0)
LS_POINTS = 3000


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

    from .._problems import _programs

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
