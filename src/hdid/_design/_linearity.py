"""Where the linearised prediction is not honest, and why.

A Fisher standard error is the spread of the fits only where the model's readings are
close to linear in the parameters over that spread. Three checks per candidate and
parameter, each from the candidate's own prediction:

* **stick events** — the simulator is moved to ±2 predicted std along the parameter
  (the others and the nuisances following it, as the fit would: the covariance's
  column), and the readings are compared with the linear prediction
  ``θ₀ + J·δ``. A relative departure above :data:`NONLINEAR` (in the fit's own
  weighted norm) means the std is not the spread; when a run's rest point then moves
  more than half an encoder count beyond the linear guess, the swing stops a different
  number of times (a stick event changes: the rest point is discontinuous there).
* **bounds** — a parameter on an interval whose ±2 std leaves it (the spread is cut).
* **size** — a positive (log-transformed) parameter whose predicted std exceeds
  :data:`LOG_NORMAL` of its value: its fits spread log-normally, not as ``±std``.
"""

from __future__ import annotations

import math

import numpy as np

from . import _stack
from ._fisher import Prediction

#: Relative departure of the ±2σ readings from the linear prediction above which the
#: linearised std is not the fits' spread (a 25 % error in the std: the design tool's
#: own acceptance criterion).
NONLINEAR = 0.25
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
        # δ is 2 std along the parameter's covariance column: δᵀFδ = 4, the linear
        # readings (with the prior rows) move by 2 in the weighted norm; the departure
        # is measured against that
        num = math.sqrt(float(np.sum((w * (true - lin)) ** 2)))
        ratio = num / 2.0
        jump = bool(np.any(np.abs(true[:, -1] - lin[:, -1]) > REST_JUMP_COUNTS * e.resolution))
        key = (id(p), n)
        old = worst.get(key, (0.0, False))
        worst[key] = (max(old[0], ratio), old[1] or jump)
    for p, n, k in plans:
        key = (id(p), n)
        if key not in worst:
            continue
        ratio, jump = worst.pop(key)
        if ratio > NONLINEAR:
            why = ("a stop changes: a rest point jumps" if jump
                   else "the readings are curved over that range")
            p.honesty.append(f"{n}: readings at ±2 std depart {_pct(ratio)} from linear "
                             f"({why})")


def _pct(x: float) -> str:
    return f"{100 * x:.0f} %" if x < 10 else f"{x:.0f}x"
