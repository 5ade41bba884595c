"""The free-motion fit done "the way a user would without hdid": scipy only (``solve_ivp`` LSODA,
tanh-smoothed friction, ``least_squares``), the baseline that ``fit_speed.py`` imports."""

import contextlib
import math
import time
from collections.abc import Mapping, Sequence

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

#: Fitted shared parameters, in this order (all positive, fitted as logarithms).
PARAM_NAMES = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v")

#: Default physical bounds: the Stribeck exponent in a plausible range (on quantized 250 Hz data an unbounded fit
#: drifts to δ ≫ 10, a step-shaped Stribeck curve fitting the rest readings' rounding, in hundreds of iterations).
DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {"delta": (0.25, 4.0)}


class _TooStiff(Exception):
    """Raised inside the right-hand side to abandon a pathological integration."""


#: Right-hand-side calls after which a solve is abandoned: a 0.5 s run needs ≈ 800; a first
#: trust-region step can jump to k2 ~ 1e13 and would stall LSODA for minutes.
MAX_RHS_CALLS = 50_000


def simulate_run_scipy(time_s: np.ndarray, *, theta0: float, t_release: float,
                       params: Mapping[str, float], inertia: float, ratio: float = 100.0,
                       eps: float = 1e-4) -> np.ndarray:
    """Physical WG angle [rad] at the sorted times ``time_s`` [s] of one release from ``theta0`` (from the spring's
    zero) at ``t_release``, with ``params`` (``k1, k2, tau_c, tau_s, v_s, delta, c_v``), the WG ``inertia`` [kg m²],
    gear ``ratio`` and the ``tanh`` sign smoothing at velocity ``eps`` [rad/s]; LSODA at rtol 1e-6, atol 1e-9.
    NaN after the release if the integration failed or ran over :data:`MAX_RHS_CALLS`."""
    k1, k2, tc, ts, vs, dl, cv = (float(params[n]) for n in PARAM_NAMES)
    N, inv_i, tanh, exp, calls = float(ratio), 1.0 / float(inertia), math.tanh, math.exp, [0]

    def rhs(_t, y):
        calls[0] += 1
        if calls[0] > MAX_RHS_CALLS:
            raise _TooStiff
        th, w = y
        d = th / N
        fr = tanh(w / eps) * (tc + (ts - tc) * exp(-(abs(w / vs) ** dl))) + cv * w
        return [w, (-(k1 * d + k2 * d * d * d) / N - fr) * inv_i]

    t = np.asarray(time_s, dtype=float)
    out, after, sol = np.full(t.shape, float(theta0)), t > t_release, None
    if np.any(after):
        with contextlib.suppress(_TooStiff):
            sol = solve_ivp(rhs, (float(t_release), float(t[-1])), [float(theta0), 0.0],
                            method="LSODA", rtol=1e-6, atol=1e-9, t_eval=t[after])
        out[after] = sol.y[0] if sol is not None and sol.status >= 0 and sol.y.shape[1] == after.sum() else np.nan
    return out


def runs_from_dataframe(df) -> list[dict]:
    """Split a ``run,setup,time,theta`` log (radians) into the ``runs`` of :func:`fit_scipy`: ``theta0_enc`` is
    the first reading, ``t_release0`` half a sample after the last one still reading the held value (noiseless,
    quantized logs)."""
    runs = []
    for run_id, g in df.groupby("run", sort=True):
        g = g.sort_values("time")
        t, th = g["time"].to_numpy(float), g["theta"].to_numpy(float)
        moved, dt = np.flatnonzero(th != th[0]), float(np.median(np.diff(t)))
        k = int(moved[0]) - 1 if moved.size else len(t) - 1
        runs.append({"run": run_id, "time": t, "theta": th, "setup": str(g["setup"].iloc[0]),
                     "t_release0": float(t[k] + 0.5 * dt), "theta0_enc": float(th[0])})
    return runs


def guess_offsets(runs: Sequence[Mapping]) -> dict[str, float]:
    """Crude per-set-up encoder offset: the midpoint between rest readings of opposite releases (one direction
    only: their mean, off by up to the stick band's half-width)."""
    out: dict[str, float] = {}
    for setup in dict.fromkeys(str(r["setup"]) for r in runs):
        finals = {+1: [], -1: []}
        for r in (r for r in runs if str(r["setup"]) == setup):
            th = float(np.asarray(r["theta"], float)[-1])
            finals[1 if th > r["theta0_enc"] else -1].append(th)
        out[setup] = (0.5 * (np.mean(finals[1]) + np.mean(finals[-1])) if finals[1] and finals[-1]
                      else float(np.mean(finals[1] + finals[-1])))
    return out


#: ``least_squares``' relative finite-difference step (absolute below 1: 0.1 ms for release times, 0.1 mrad for
#: angles; ≈ 0.05 % for the log-parameters). LSODA at rtol 1e-6 makes the default ``sqrt(eps_machine)`` useless;
#: 1e-3 gave worse fits (coarser, biased Jacobian), 3e-3 sent the first step to absurd parameters.
DIFF_STEP = 1e-4


def fit_scipy(runs: list[dict], x0: dict, inertia: float, ratio: float = 100.0, *,
              eps: float = 1e-4, max_nfev: int | None = 200) -> dict:
    """Fit the free-motion model to all ``runs`` of a log (:func:`runs_from_dataframe`) with scipy only, from ``x0``
    (positive ``k1, k2, tau_c, tau_s, v_s, delta, c_v``, fitted as logarithms; ``k1`` and ``tau_c`` within a few tens
    of percent: a wrong number of reversals is a local minimum), ``inertia`` [kg m²] fixed, ``eps`` the ``tanh``
    smoothing velocity [rad/s]. Returns ``params``, ``runs`` (``t_release``, ``theta0``, ``theta0_enc``),
    ``offsets``, ``nfev``, ``n_simulations``, ``wall_s``, ``rms`` [rad], ``success``."""
    t_start = time.perf_counter()
    if missing := [n for n in PARAM_NAMES if n not in x0] or [n for n in PARAM_NAMES if float(x0[n]) <= 0]:
        raise ValueError(f"x0 lacks {missing} or they are not > 0 (log-space fit)")
    n_runs, n_p, setups = len(runs), len(PARAM_NAMES), list(dict.fromkeys(str(r["setup"]) for r in runs))
    offsets0 = guess_offsets(runs)
    run_setup = [setups.index(str(r["setup"])) for r in runs]
    times = [np.asarray(r["time"], float) for r in runs]
    y_all = np.concatenate([np.asarray(r["theta"], float) for r in runs])
    x_init = np.concatenate([np.log([float(x0[n]) for n in PARAM_NAMES]),
                             np.asarray([r["t_release0"] for r in runs], float),
                             np.asarray([r["theta0_enc"] for r in runs], float),
                             np.asarray([offsets0[s] for s in setups], float)])
    counters = {"sims": 0}

    def unpack(x):  # params, release times, encoder start angles, set-up offsets
        return (dict(zip(PARAM_NAMES, np.exp(x[:n_p]))), x[n_p:n_p + n_runs], x[n_p + n_runs:n_p + 2 * n_runs],
                x[n_p + 2 * n_runs:])

    def model(x):
        params, t_rel, th_enc, offs = unpack(x)
        out = []
        for i in range(n_runs):
            off = offs[run_setup[i]]
            out.append(off + simulate_run_scipy(times[i], theta0=th_enc[i] - off, t_release=t_rel[i],
                                                params=params, inertia=inertia, ratio=ratio, eps=eps))
            counters["sims"] += 1
        return np.concatenate(out)

    def residuals(x):
        r = model(x) - y_all
        return np.where(np.isfinite(r), r, 1.0)  # a failed solve is a large residual

    lo, hi = np.full(x_init.shape, -np.inf), np.full(x_init.shape, np.inf)
    for name, (b_lo, b_hi) in DEFAULT_BOUNDS.items():
        j = PARAM_NAMES.index(name)
        lo[j], hi[j] = math.log(b_lo), math.log(b_hi)
    x_init = np.clip(x_init, np.nextafter(lo, np.inf), np.nextafter(hi, -np.inf))
    res = least_squares(residuals, x_init, method="trf", x_scale="jac", jac="2-point",
                        diff_step=DIFF_STEP, bounds=(lo, hi), max_nfev=max_nfev)
    params, t_rel, th_enc, offs = unpack(res.x)
    r_final = model(res.x) - y_all
    return {"params": {**{n: float(v) for n, v in params.items()}, "inertia": float(inertia)},
            "runs": [{"t_release": float(t_rel[i]), "theta0": float(th_enc[i] - offs[run_setup[i]]),
                      "theta0_enc": float(th_enc[i])} for i in range(n_runs)],
            "offsets": {s: float(offs[j]) for j, s in enumerate(setups)}, "nfev": int(res.nfev),
            "n_simulations": counters["sims"], "wall_s": time.perf_counter() - t_start,
            "rms": float(np.sqrt(np.mean(r_final**2))), "success": bool(res.success)}


if __name__ == "__main__":
    print(__doc__)
