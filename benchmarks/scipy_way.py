"""The free-motion fit done "the way a user would without hdid": scipy only.

Model (same physics as hdid; angles at the wave generator, WG)::

    I·θ̈ = −T_k(θ/N)/N − τ_f(ω),   T_k(d) = k1·d + k2·d³
    τ_f(ω) = tanh(ω/ε)·(τ_c + (τ_s − τ_c)·exp(−|ω/v_s|^δ)) + c_v·ω

i.e. the friction sign is smoothed with ``tanh(ω/ε)`` and stiction is only the Stribeck curve
(there is no exact stick state).  ``ε`` defaults to ``1e-4`` rad/s: with the CSF-8 numbers a
"stuck" WG then creeps at ``ε·atanh(F/τ_s) ≲ 1e-4`` rad/s, i.e. about 4e-5 rad (0.03 encoder
count) over a 0.5 s record, while LSODA (which switches to its stiff BDF mode near ω = 0) stays
at ≈ 5 ms per 0.5 s run.  ``ε = 1e-3`` creeps by ≈ 4e-4 rad (a quarter count), ``1e-2`` by a
few counts.

Each run is integrated with :func:`scipy.integrate.solve_ivp` (LSODA, rtol 1e-6, atol 1e-9)
from its release instant, starting at rest; :func:`scipy.optimize.least_squares` (``"trf"``,
``x_scale="jac"``, 2-point finite-difference Jacobian with ``diff_step=1e-4``; ``delta``
bounded to [0.25, 4]) fits all runs of a log jointly:

* shared physical parameters ``k1, k2, tau_c, tau_s, v_s, delta, c_v`` in log space
  (inertia fixed, since free motion only fixes parameter/inertia ratios);
* per run: release time ``t_release`` and start angle (as the encoder-frame reading during
  the hold, ``theta0_enc``);
* per set-up: encoder offset (the encoder reads ``θ_phys + offset``), so the physical start
  angle of a run is ``theta0_enc − offset``.

Residuals are model minus logged readings at every sample (the model is not quantized),
unweighted by default; ``collapse_tail=True`` weights each run's stuck tail as one observation.
A right-hand-side call cap turns pathological trial points (LSODA stalling on absurd, very
stiff parameters) into large residuals instead of minutes-long solves.
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp
from scipy.optimize import least_squares

__all__ = ["PARAM_NAMES", "DEFAULT_BOUNDS", "simulate_run_scipy", "runs_from_dataframe",
           "guess_offsets", "fit_scipy"]

#: Fitted shared parameters, in this order (all positive, fitted as logarithms).
PARAM_NAMES = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v")

#: Default physical bounds: the Stribeck exponent is kept in a plausible range (on quantized
#: 250 Hz data an unbounded fit drifts to δ ≫ 10, a step-shaped Stribeck curve that fits the
#: rounding of the rest readings, and needs hundreds of iterations to get there).
DEFAULT_BOUNDS: dict[str, tuple[float, float]] = {"delta": (0.25, 4.0)}


class _TooStiff(Exception):
    """Raised inside the right-hand side to abandon a pathological integration."""


def simulate_run_scipy(
    time_s: np.ndarray,
    *,
    theta0: float,
    t_release: float,
    params: Mapping[str, float],
    inertia: float,
    ratio: float = 100.0,
    eps: float = 1e-4,
    rtol: float = 1e-6,
    atol: float = 1e-9,
    max_rhs_calls: int = 50_000,
) -> np.ndarray:
    """Physical WG angle of one release with tanh-smoothed Stribeck friction (LSODA).

    Parameters
    ----------
    time_s : numpy.ndarray
        Sorted sample times [s].
    theta0 : float
        Physical start angle (from the spring's zero) [rad].
    t_release : float
        Release instant [s]; the angle is ``theta0`` up to it.
    params : mapping
        ``k1, k2, tau_c, tau_s, v_s, delta, c_v``.
    inertia : float
        WG inertia [kg m²].
    ratio : float, optional
        Gear ratio ``N``.
    eps : float, optional
        Velocity scale of the ``tanh`` sign smoothing [rad/s].
    rtol, atol : float, optional
        LSODA tolerances.
    max_rhs_calls : int, optional
        Give up (return NaN after the release) once the right-hand side has been evaluated this
        many times.  A normal 0.5 s run needs ≈ 800; trial points with absurd parameters (a
        first trust-region step can jump to k2 ~ 1e13) would otherwise stall LSODA for minutes.

    Returns
    -------
    numpy.ndarray
        Angle at ``time_s`` (NaN after the release if the integration failed).
    """
    k1 = float(params["k1"])
    k2 = float(params["k2"])
    tc = float(params["tau_c"])
    ts = float(params["tau_s"])
    vs = float(params["v_s"])
    dl = float(params["delta"])
    cv = float(params["c_v"])
    N = float(ratio)
    inv_i = 1.0 / float(inertia)
    tanh = math.tanh
    exp = math.exp

    calls = [0]

    def rhs(_t, y):
        calls[0] += 1
        if calls[0] > max_rhs_calls:
            raise _TooStiff
        th = y[0]
        w = y[1]
        d = th / N
        fr = tanh(w / eps) * (tc + (ts - tc) * exp(-(abs(w / vs) ** dl))) + cv * w
        return [w, (-(k1 * d + k2 * d * d * d) / N - fr) * inv_i]

    t = np.asarray(time_s, dtype=float)
    out = np.full(t.shape, float(theta0))
    after = t > t_release
    if not np.any(after):
        return out
    try:
        sol = solve_ivp(rhs, (float(t_release), float(t[-1])), [float(theta0), 0.0],
                        method="LSODA", rtol=rtol, atol=atol, t_eval=t[after])
    except _TooStiff:
        out[after] = np.nan
        return out
    if sol.status < 0 or sol.y.shape[1] != int(after.sum()):
        out[after] = np.nan
        return out
    out[after] = sol.y[0]
    return out


def runs_from_dataframe(df, counts_per_rev: int | None = None) -> list[dict]:
    """Split a ``run,setup,time,theta`` log into the ``runs`` list of :func:`fit_scipy`.

    ``theta0_enc`` is the first reading; ``t_release0`` is half a sample after the last sample
    that still reads the held value (meant for noiseless, quantized logs; with noisy readings
    pass your own guesses).

    Parameters
    ----------
    df : pandas.DataFrame
        Log with columns ``run, setup, time, theta``.
    counts_per_rev : int, optional
        If given, ``theta`` is in counts and is converted to radians.

    Returns
    -------
    list of dict
    """
    runs = []
    for run_id, g in df.groupby("run", sort=True):
        g = g.sort_values("time")
        t = g["time"].to_numpy(float)
        th = g["theta"].to_numpy(float)
        if counts_per_rev:
            th = th * (2.0 * math.pi / counts_per_rev)
        moved = np.flatnonzero(th != th[0])
        dt = float(np.median(np.diff(t)))
        k = int(moved[0]) - 1 if moved.size else len(t) - 1
        runs.append({"run": run_id, "time": t, "theta": th, "setup": str(g["setup"].iloc[0]),
                     "t_release0": float(t[k] + 0.5 * dt), "theta0_enc": float(th[0])})
    return runs


def guess_offsets(runs: Sequence[Mapping]) -> dict[str, float]:
    """Crude per-set-up encoder offset: the midpoint between rest readings of opposite releases.

    For a set-up whose runs all move the same way, the mean rest reading is used (error up to
    the stick band's half-width).
    """
    out: dict[str, float] = {}
    for setup in dict.fromkeys(str(r["setup"]) for r in runs):
        rs = [r for r in runs if str(r["setup"]) == setup]
        finals = {+1: [], -1: []}
        for r in rs:
            th = np.asarray(r["theta"], float)
            direction = 1 if th[-1] > r["theta0_enc"] else -1
            finals[direction].append(float(th[-1]))
        if finals[1] and finals[-1]:
            out[setup] = 0.5 * (np.mean(finals[1]) + np.mean(finals[-1]))
        else:
            out[setup] = float(np.mean(finals[1] + finals[-1]))
    return out


def fit_scipy(
    runs: list[dict],
    x0: dict,
    inertia: float,
    ratio: float = 100.0,
    *,
    eps: float = 1e-4,
    diff_step: float = 1e-4,
    max_nfev: int | None = 200,
    bounds: Mapping[str, tuple[float, float]] | None = None,
    collapse_tail: bool = False,
    verbose: int = 0,
) -> dict:
    """Fit the free-motion model to all runs of a log with scipy only.

    Parameters
    ----------
    runs : list of dict
        One per release: ``"time"`` (array, s), ``"theta"`` (array, encoder rad), ``"setup"``
        (str), ``"t_release0"`` (starting guess of the release instant, s) and
        ``"theta0_enc"`` (starting guess of the held reading, rad).
    x0 : dict
        Starting values (the *contract*): all of ``k1, k2, tau_c, tau_s, v_s, delta, c_v``,
        strictly positive physical values (they are fitted as logarithms).  Optionally
        ``"offsets"``: ``{setup: rad}`` starting encoder offsets (default
        :func:`guess_offsets`), ``"t_release"`` and ``"theta0_enc"``: per-run lists overriding
        the runs' own guesses.  Starting values should be "good": within a few tens of percent
        for ``k1`` and ``tau_c`` (a wrong number of reversals is a local minimum), release times
        within a sample.
    inertia : float
        Fixed WG inertia [kg m²].
    ratio : float, optional
        Gear ratio ``N``.
    eps : float, optional
        ``tanh`` smoothing velocity [rad/s] (see module docstring).
    diff_step : float, optional
        Relative finite-difference step of ``least_squares`` (absolute for values below 1:
        0.1 ms for release times, 0.1 mrad for angles; ≈ 0.05 % for the log-parameters).
        LSODA at rtol 1e-6 makes the default ``sqrt(eps_machine)`` step useless; 1e-3 gave
        worse fits (coarser, biased Jacobian), 3e-3 sent the first step to absurd parameters.
    max_nfev : int, optional
        Iteration cap passed to ``least_squares``.
    bounds : mapping of str to (float, float), optional
        Physical ``(low, high)`` bounds of some shared parameters (default
        :data:`DEFAULT_BOUNDS`: only ``delta`` in [0.25, 4]; pass ``{}`` for none).  Starting
        values outside are clipped into them.
    collapse_tail : bool, optional
        If True, the trailing samples of each run that repeat its final reading (the stuck
        tail) are weighted ``1/sqrt(n_tail)``, so the tail counts as one observation instead of
        ``n_tail``.  Default False: plain, unweighted least squares "as a user would" — on
        quantized logs its cost is then dominated by the rounding of the rest readings.
    verbose : int, optional
        ``least_squares`` verbosity.

    Returns
    -------
    dict
        ``params`` (fitted physical parameters and the fixed ``inertia``), ``runs`` (per run:
        ``t_release``, ``theta0`` physical, ``theta0_enc``), ``offsets`` (by set-up), ``nfev``
        (least_squares' count of residual evaluations, Jacobian ones excluded), ``njev``,
        ``n_residual_calls`` (all residual evaluations, finite differences included),
        ``n_simulations`` (single-run ODE solves), ``wall_s``, ``cost``
        (``0.5·Σ (weight·residual)²``, rad²), ``rms`` (unweighted, rad), ``success``,
        ``message``.
    """
    t_start = time.perf_counter()
    missing = [n for n in PARAM_NAMES if n not in x0]
    if missing:
        raise ValueError(f"x0 lacks {missing}")
    if any(float(x0[n]) <= 0 for n in PARAM_NAMES):
        raise ValueError("starting physical parameters must be > 0 (log-space fit)")
    n_runs = len(runs)
    setups = list(dict.fromkeys(str(r["setup"]) for r in runs))
    offsets0 = dict(guess_offsets(runs))
    offsets0.update({str(k): float(v) for k, v in (x0.get("offsets") or {}).items()})
    t_rel0 = list(x0.get("t_release") or [r["t_release0"] for r in runs])
    th_enc0 = list(x0.get("theta0_enc") or [r["theta0_enc"] for r in runs])
    run_setup = [setups.index(str(r["setup"])) for r in runs]
    times = [np.asarray(r["time"], float) for r in runs]
    data = [np.asarray(r["theta"], float) for r in runs]
    y_all = np.concatenate(data)
    weights = []
    for th in data:
        w = np.ones(th.shape)
        if collapse_tail:
            changed = np.flatnonzero(th != th[-1])
            first_tail = int(changed[-1]) + 1 if changed.size else 0
            n_tail = th.size - first_tail
            if n_tail > 1:
                w[first_tail:] = 1.0 / math.sqrt(n_tail)
        weights.append(w)
    w_all = np.concatenate(weights)

    n_p = len(PARAM_NAMES)
    x_init = np.concatenate([
        np.log([float(x0[n]) for n in PARAM_NAMES]),
        np.asarray(t_rel0, float),
        np.asarray(th_enc0, float),
        np.asarray([offsets0[s] for s in setups], float),
    ])
    counters = {"calls": 0, "sims": 0}

    def unpack(x):
        params = dict(zip(PARAM_NAMES, np.exp(x[:n_p])))
        t_rel = x[n_p:n_p + n_runs]
        th_enc = x[n_p + n_runs:n_p + 2 * n_runs]
        offs = x[n_p + 2 * n_runs:]
        return params, t_rel, th_enc, offs

    def model(x):
        params, t_rel, th_enc, offs = unpack(x)
        out = []
        for i in range(n_runs):
            off = offs[run_setup[i]]
            th = simulate_run_scipy(times[i], theta0=th_enc[i] - off, t_release=t_rel[i],
                                    params=params, inertia=inertia, ratio=ratio, eps=eps)
            counters["sims"] += 1
            out.append(th + off)
        return np.concatenate(out)

    def residuals(x):
        counters["calls"] += 1
        r = (model(x) - y_all) * w_all
        return np.where(np.isfinite(r), r, 1.0)  # a failed solve is a large residual

    lo = np.full(x_init.shape, -np.inf)
    hi = np.full(x_init.shape, np.inf)
    for name, (b_lo, b_hi) in (DEFAULT_BOUNDS if bounds is None else bounds).items():
        j = PARAM_NAMES.index(name)
        lo[j], hi[j] = math.log(b_lo), math.log(b_hi)
    x_init = np.clip(x_init, np.nextafter(lo, np.inf), np.nextafter(hi, -np.inf))
    res = least_squares(residuals, x_init, method="trf", x_scale="jac", jac="2-point",
                        diff_step=diff_step, bounds=(lo, hi), max_nfev=max_nfev,
                        verbose=verbose)
    params, t_rel, th_enc, offs = unpack(res.x)
    r_final = model(res.x) - y_all
    out_params = {n: float(v) for n, v in params.items()}
    out_params["inertia"] = float(inertia)
    wall = time.perf_counter() - t_start
    return {
        "params": out_params,
        "runs": [{"t_release": float(t_rel[i]), "theta0": float(th_enc[i] - offs[run_setup[i]]),
                  "theta0_enc": float(th_enc[i])} for i in range(n_runs)],
        "offsets": {s: float(offs[j]) for j, s in enumerate(setups)},
        "nfev": int(res.nfev),
        "njev": int(res.njev) if res.njev is not None else None,
        "n_residual_calls": counters["calls"],
        "n_simulations": counters["sims"],
        "wall_s": wall,
        "cost": float(res.cost),
        "rms": float(np.sqrt(np.mean(r_final**2))),
        "success": bool(res.success),
        "message": str(res.message),
    }


def _demo(path: Path) -> None:
    import json

    import pandas as pd

    df = pd.read_csv(path)
    runs = runs_from_dataframe(df)
    truth_all = json.loads((path.parent / "truth.json").read_text())
    truth = truth_all[path.name]
    p_true = truth["params"]
    # a "good" start: every parameter off by 10-50 %
    factors = {"k1": 1.1, "k2": 0.7, "tau_c": 1.2, "tau_s": 0.85, "v_s": 1.5, "delta": 1.3,
               "c_v": 1.4}
    x0 = {n: p_true[n] * factors[n] for n in PARAM_NAMES}
    fit = fit_scipy(runs, x0, inertia=p_true["inertia"], ratio=truth["ratio"])
    print(f"scipy way on {path.name}: {len(runs)} runs, wall {fit['wall_s']:.2f} s, "
          f"nfev {fit['nfev']}, residual calls {fit['n_residual_calls']}, "
          f"ODE solves {fit['n_simulations']}, success {fit['success']}")
    print(f"rms residual {fit['rms']:.3e} rad ({fit['rms'] / truth['step_rad']:.3f} counts)")
    print(f"{'param':>8} {'start':>12} {'fit':>12} {'truth':>12} {'fit/truth':>9}")
    for n in PARAM_NAMES:
        print(f"{n:>8} {x0[n]:12.5g} {fit['params'][n]:12.5g} {p_true[n]:12.5g} "
              f"{fit['params'][n] / p_true[n]:9.3f}")
    for s, v in fit["offsets"].items():
        print(f"offset {s}: fit {v:+.5f}  truth {truth['offsets'][s]:+.5f}")
    for r_fit, r_true in zip(fit["runs"], truth["runs"]):
        print(f"run {r_true['run']}: t_release fit {r_fit['t_release']:.5f} truth "
              f"{r_true['t_release']:.5f}; theta0 fit {r_fit['theta0']:+.5f} truth "
              f"{r_true['theta0']:+.5f}")


if __name__ == "__main__":
    import sys

    default = Path(__file__).resolve().parent.parent / "data" / "synthetic" / "csf8_paper.csv"
    if {"-h", "--help"} & set(sys.argv[1:]):
        sys.exit(print(__doc__))
    _demo(Path(sys.argv[1]) if len(sys.argv) > 1 else default)
