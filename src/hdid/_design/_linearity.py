"""Where the linearised prediction is not honest, and why.

A Fisher standard error is the spread of the fits only where the model's readings are
close to linear in the parameters over that spread. Three checks per candidate and
parameter, each from the candidate's own prediction:

* **curvature and stick events** — the simulator is moved to ±2 predicted std along the
  parameter (the others and the nuisances following it, as the fit would: the
  covariance's column). Linearised, the data's χ² grows there by ``|W J δ|²/σ²`` (4 less
  the prior rows' share); simulated, by ``|W (θ(u+δ) − θ(u))|²/σ²``. The square root of
  their ratio is how much narrower (> 1) or wider (< 1) the likelihood really is along
  that direction (Bates & Watts' check of a linearisation along a line): beyond
  :data:`NONLINEAR` either way the std is not the spread. When a run's rest point then
  moves more than half an encoder count beyond the linear guess, the swing stops a
  different number of times (a stick event changes: the rest point is discontinuous).
* **bounds** — a parameter on an interval whose ±2 std leaves it (the spread is cut).
* **size** — a positive (log-transformed) parameter whose predicted std exceeds
  :data:`LOG_NORMAL` of its value: its fits spread log-normally, not as ``±std``.
"""

from __future__ import annotations

import math

import numpy as np

from . import _stack
from ._fisher import Prediction

#: Factor by which the likelihood's width along a parameter's direction may differ from
#: the linearised one at ±2 std before the std is called not the spread (25 %: the
#: design check's own acceptance criterion).
NONLINEAR = 1.25
#: Predicted std above this fraction of a positive parameter's value: log-normal spread.
LOG_NORMAL = 0.3
#: A rest point that moves this many encoder counts beyond its linear guess: a stop changed.
REST_JUMP_COUNTS = 0.5


def check(fit, preds: list[Prediction], every: tuple[str, ...]) -> None:
    """Fill each prediction's ``honesty`` list (one line per parameter that fails)."""
    specs = fit.model.parameter_specs()
    values = fit.model.float_values()
    groups: dict[int, list[Prediction]] = {}
    for p in preds:
        if p.error is None and p.stack_rows is not None:
            groups.setdefault(id(p.stack_rows[0]), []).append(p)
        if p.error is not None:
            continue
        for n in p.names:
            s = p.std[n]
            if not math.isfinite(s):
                continue
            t = specs[n].transform
            if isinstance(t, tuple):
                _, lo, hi = t
                if values[n] - 2 * s < lo or values[n] + 2 * s > hi:
                    p.honesty.append(f"{n}: ±2 std leaves its range ({lo:g}, {hi:g})")
            elif t == "log" and s > LOG_NORMAL * values[n]:
                p.honesty.append(f"{n}: std {100 * s / values[n]:.0f} % of the value "
                                 "(log-normal spread)")
    for members in groups.values():
        _events(members, every)


def _events(preds: list[Prediction], every: tuple[str, ...]) -> None:
    st = preds[0].stack_rows[0]
    Pall = len(every)
    K = 2 * max(len(p.names) for p in preds)
    local0 = st.local
    locs = np.broadcast_to(local0, (K,) + local0.shape).copy()
    plans = []
    for p in preds:
        rows = p.stack_rows[1]
        e = p.experiment
        P, R = len(p.names), e.n_runs
        cols = [every.index(n) for n in p.names]
        setups = e.setup_names
        for i, n in enumerate(p.names):
            c = p.full_cov[:, i]
            if not (math.isfinite(c[i]) and c[i] > 0 and np.all(np.isfinite(c))):
                continue
            d = 2.0 * c / math.sqrt(c[i])
            for sgn, k in ((1.0, 2 * i), (-1.0, 2 * i + 1)):
                for j, r in enumerate(rows):
                    locs[k, r, cols] += sgn * d[:P]
                    locs[k, r, Pall] += sgn * d[P + j]
                    locs[k, r, Pall + 1] += sgn * d[P + R + j]
                    locs[k, r, Pall + 2] += sgn * d[P + 2 * R + setups.index(e.setups[j])]
                plans.append((p, n, k))
    if not plans:
        return
    theta0, J = _stack.evaluate(st)
    moved = _stack.trajectories(st, locs)
    worst: dict[tuple[int, str], tuple[float, bool]] = {}
    for p, n, k in plans:
        rows = p.stack_rows[1]
        e = p.experiment
        m = e.n_samples
        dl = locs[k, rows] - local0[rows]                       # (R, P+3)
        lin = theta0[rows, :m] + np.einsum("rtj,rj->rt", J[rows, :m], dl)
        true = moved[k, rows, :m]
        w = np.stack(p.weights) / p.sigma
        lin_chi2 = float(np.sum((w * (lin - theta0[rows, :m])) ** 2))
        with np.errstate(over="ignore", invalid="ignore"):  # a diverging simulation: inf
            true_chi2 = float(np.sum((w * (true - theta0[rows, :m])) ** 2))
        if not math.isfinite(true_chi2):
            true_chi2 = math.inf
        if lin_chi2 < 0.04:  # the prior, not the data, sets this direction (< 1 % of Δχ² 4)
            continue
        ratio = max(math.sqrt(true_chi2 / lin_chi2), 1e-12)
        with np.errstate(invalid="ignore"):
            jump = bool(np.any(~(np.abs(true[:, -1] - lin[:, -1])
                                 <= REST_JUMP_COUNTS * e.resolution)))
        key = (id(p), n)
        old = worst.get(key, (1.0, False))
        far = ratio if abs(math.log(ratio)) > abs(math.log(old[0])) else old[0]
        worst[key] = (far, old[1] or jump)
    for p, n, k in plans:
        key = (id(p), n)
        if key not in worst:
            continue
        ratio, jump = worst.pop(key)
        if not 1.0 / NONLINEAR <= ratio <= NONLINEAR:
            why = ("a stop changes: a rest point jumps" if jump
                   else "the readings are curved over that range")
            p.honesty.append(f"{n}: the likelihood at ±2 std is {_times(ratio)} the "
                             f"linearised one ({why})")


def _times(r: float) -> str:
    if not math.isfinite(r):
        return "far steeper (the simulation diverges there) than"
    if r >= 1.0:
        return f"{r:.2g}x as steep as"
    return f"{1 / r:.2g}x flatter than"
