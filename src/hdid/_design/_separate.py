"""How well a candidate experiment would tell two fitted models apart.

Given two fits of one log by different models ``A`` and ``B`` (two diagnose candidates:
a ripple and a kinematic error, backlash and hysteresis), a candidate's noise-free
readings under ``A`` are fitted by ``B``. The expected ``2·ln LR`` in ``A``'s favour is
that fit's χ² — linearised at ``B``'s fitted values, the part of the readings'
difference ``W (θ_A − θ_B)/σ`` that ``B``'s Jacobian (physical parameters and every
run's nuisances) cannot absorb:

    2 ln LR_A≻B ≈ |r|² − |Q Qᵀ r|²,   r = W (θ_A − θ_B)/σ,   J_B = Q R.

The separation of the pair is the smaller of the two directions (data from ``A`` fitted
by ``B``, and from ``B`` by ``A``): with noise the expected value adds nothing (it is a
noncentrality). Linearised at ``B``'s optimum for the *log*: a design that moves ``B``'s
best approximation far from it overstates the separation; a ``check`` by simulation is
the remedy (not done here).
"""

from __future__ import annotations

import math

import numpy as np

from . import _stack
from ._candidates import Experiment
from ._fisher import as_log, max_substep, parameter_names, readings


def separation(fit_a, fit_b, experiments: list[Experiment]) -> list[tuple[float, float]]:
    """``(2 ln LR with A true, with B true)`` for every experiment (NaN where a design
    gives no usable log)."""
    ta = _trajectories(fit_a, experiments)
    tb = _trajectories(fit_b, experiments)
    out = []
    for i, e in enumerate(experiments):
        out.append((_lr(fit_b, e, ta[i][0], tb[i]), _lr(fit_a, e, tb[i][0], ta[i])))
    return out


def _trajectories(fit, experiments):
    """Per experiment ``(θ (R, n), J (R, n, P+3), names)`` of ``fit``'s model."""
    free, every = parameter_names(fit)
    groups: dict[float, list[tuple[int, Experiment]]] = {}
    for i, e in enumerate(experiments):
        groups.setdefault(float(e.rate), []).append((i, e))
    out = [None] * len(experiments)
    for cands in groups.values():
        st = _stack.stack(cands, fit, every, max_substep(fit))
        theta, J = _stack.evaluate(st)
        for pos, e in cands:
            rows = st.index[pos]
            cols = [every.index(n) for n in free] + [len(every) + k for k in range(3)]
            out[pos] = (theta[rows, :e.n_samples], J[rows, :e.n_samples][:, :, cols], free)
    return out


def _lr(fit_fitted, e: Experiment, theta_true, fitted) -> float:
    """Expected 2 ln LR when ``theta_true`` is fitted by the model of ``fitted``."""
    from .._errors import HdidError
    from .._simulation._prepare import prepare

    theta_fit, J, names = fitted
    if not (np.all(np.isfinite(theta_true)) and np.all(np.isfinite(J))):
        return math.nan
    quantized = bool(fit_fitted.resolution_known)
    try:
        prep = prepare(as_log(e, readings(e, theta_true, quantized), e.name, quantized))
    except HdidError:
        return math.nan
    w = prep.weight[:, :e.n_samples]
    sigma = e.resolution / math.sqrt(12.0)
    P, R, setups = len(names), e.n_runs, e.setup_names
    n_unk = P + 2 * R + len(setups)
    m = e.n_samples
    A = np.zeros((R * m, n_unk))
    r = np.zeros(R * m)
    for j in range(R):
        rows = slice(j * m, (j + 1) * m)
        wj = w[j][:, None] / sigma
        A[rows, :P] = wj * J[j][:, :P]
        A[rows, P + j] = wj[:, 0] * J[j][:, P]
        A[rows, P + R + j] = wj[:, 0] * J[j][:, P + 1]
        A[rows, P + 2 * R + setups.index(e.setups[j])] = wj[:, 0] * J[j][:, P + 2]
        r[rows] = w[j] * (theta_true[j] - theta_fit[j]) / sigma
    scale = np.linalg.norm(A, axis=0)
    keep = scale > 0
    # the projection onto J_B's column space from its SVD (a rank-deficient J_B — an
    # undetermined direction — must not add directions of its own, as a plain QR would)
    U, sv, _ = np.linalg.svd(A[:, keep] / scale[keep], full_matrices=False)
    U = U[:, sv > 1e-10 * sv.max()] if sv.size else U[:, :0]
    return float(r @ r - np.sum((U.T @ r) ** 2))
