"""The rounding floor of a fit, measured on the log in hand: the χ² a *correct* model's
least-squares fit leaves on an encoder log. Reported by :func:`hdid.diagnose` beside the
white-noise floor ``n − k`` its BIC uses (:func:`hdid._diagnosis._ladder.bic_value`,
unchanged), and the base fit's ``χ²/F`` checked against clean logs
(:mod:`hdid._diagnosis._excess`).

An encoder reading is the true angle rounded to the grid: ``θ = Q(y)``. With the grid's
phase against the truth unknown (uniform over one step ``s``), the rounding error
``e = y − Q(y)`` of every sample has variance ``σ_q² = s²/12`` — but the errors of two
samples are *not* independent: they are the sawtooth ``saw(x) = x − s·round(x/s)`` at
``y_i + c`` and ``y_j + c`` for the one phase ``c``, and where the angle moves less than a
step between samples (near every reversal, in the slow creep to rest, at 250 Hz over
much of a swing) they are nearly equal. A least-squares fit with ``k`` unknowns absorbs
``k·σ_q²`` of white noise (the textbook ``E χ² = n − k``); of this correlated error its
smooth directions (start angles, offsets, release instants, stiffness) absorb far more.
Measured (``docs/decisions/floor-threshold.md``): a correct model leaves 0.37–0.95 ×
``n − k`` on the independent suite's 250 Hz logs (median 0.7), ~0.9 on the calibration's,
0.83–1.0 on 1 kHz logs; the white floor ``n − k`` hides every fit between the two.

So the floor is computed, not assumed: from a fit's own optimum (its residuals ``r`` and
Jacobian ``J``, all rows, the priors' included), the trajectory it predicts at the
weighted samples (``ŷ = θ + r·σ_q/w``) is taken as the truth, rounded with ``M`` grid
phases ``c`` spread evenly over one step, and the linearised refit is done for each:
``χ²(c) = min_δ ‖w·saw(ŷ + c)/σ_q + Jδ‖²`` (the data rows; the prior rows' residual 0).
Its mean over the phases, ``F``, is the expected χ² of a correct model with this fit's
unknowns, weights and trajectory (on white noise the same computation gives
``tr(I − H) = n − k``; on a log read on no grid, whose noise is white, that is the floor).
The spread of ``χ²(c)`` over the phases is large at 250 Hz (sd 0.3–0.9 ``F``; 0.02–0.27
at 1 kHz), and the nonlinear fit is not its linearisation: how far above ``F`` a clean
log's fit may land is measured on simulated clean logs (``calibration/floor_thresholds.py``),
not taken from this spread.

The BIC does *not* use ``F`` (flooring every BIC at ``F`` was tried, ``docs/decisions/floor-threshold.md``: wrong verdicts
and false alarms both rose on the independent suite and the calibration; not adopted).
"""

from __future__ import annotations

import math

import numpy as np

#: Grid phases over one step (a midpoint rule for the mean over the phase: the sawtooth's
#: autocovariance is a quadratic in the phase difference, so 64 points give the mean to
#: ~1e-4 of itself).
PHASES = 64
#: Singular values of the Jacobian below this fraction of the largest are no direction
#: of the refit (as :func:`hdid._fitting._refit.gauss_newton_step`'s ``rcond``).
RCOND = 1e-10


def saw(x: np.ndarray, step: float) -> np.ndarray:
    """Rounding error ``x − step·round(x/step)`` (in ``[−step/2, step/2]``)."""
    return x - step * np.round(x / step)


def projected_floor(yhat, w, J, sigma: float, step: float, data_rows,
                    phases: int = PHASES) -> tuple[float, float]:
    """Mean and standard deviation over grid phases of ``min_δ ‖e(c) + Jδ‖²``.

    ``yhat``: predicted readings at the weighted samples; ``w`` their weights; ``J`` the
    Jacobian of all residual rows (data and priors); ``data_rows`` the rows of ``J`` those
    samples are. Pure NumPy (no program)."""
    J = np.asarray(J, dtype=float)
    c = (np.arange(phases) + 0.5) / phases * step
    E = np.zeros((phases, J.shape[0]))
    E[:, data_rows] = np.asarray(w)[None, :] * saw(np.asarray(yhat)[None, :] + c[:, None],
                                                   step) / sigma
    U, S, _ = np.linalg.svd(J, full_matrices=False)
    U = U[:, S > RCOND * (S[0] if S.size else 0.0)]
    left = E - (E @ U) @ U.T
    chi2 = np.sum(left**2, axis=1)
    return float(np.mean(chi2)), float(np.std(chi2))


def white_floor(J, w2_sum: float) -> float:
    """``n − rank(J)``: the floor of white noise (a log read on no grid)."""
    S = np.linalg.svd(np.asarray(J, dtype=float), compute_uv=False)
    rank = int(np.sum(S > RCOND * (S[0] if S.size else 0.0)))
    return max(w2_sum - rank, 1.0)


def fit_floor(setup, u) -> tuple[float, float]:
    """The floor (mean, sd over grid phases; :func:`projected_floor`) of the fit ``u`` of
    ``setup`` (a :class:`~hdid._fitting._fit._Setup`), from the residuals and Jacobian of
    its structure's Levenberg–Marquardt program (no program of its own)."""
    from .._fitting._refit import residuals_and_jacobian

    p, prep = setup.problem, setup.prep
    r, J = residuals_and_jacobian(p, u)
    w = np.asarray(p.weight, dtype=float).ravel()
    n_data = w.size
    if not (np.all(np.isfinite(r)) and np.all(np.isfinite(J))):
        return math.nan, math.nan
    if not prep.quantized:
        return white_floor(J, float(np.sum(w**2))), 0.0
    rows = np.flatnonzero(w > 0)
    sigma = float(p.sigma)
    yhat = np.asarray(p.theta, dtype=float).ravel()[rows] + r[:n_data][rows] * sigma / w[rows]
    return projected_floor(yhat, w[rows], J, sigma, sigma * math.sqrt(12.0), rows)
