"""The evidence scale of :func:`hdid.diagnose` and the model ladder: the BIC with the
noise variance profiled out but floored at the quantization variance, and
:func:`model_ladder` (fit each model in turn, tabulate RMS and BIC)."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from ..effects._candidate import Candidate
from .._fitting._fit import fit


def _chi2(result) -> float:
    """χ² at the optimum (data and priors) in units of the quantization variance."""
    return float(result.starts.costs[result.starts.best])


def bic_value(chi2: float, n: float, k: int) -> float:
    """``n·ln(max(χ², n − k)/n) + k·ln n``: the BIC with the noise variance profiled out
    but never below the quantization floor.

    ``χ²`` is in units of the quantization variance ``σ_q² = step²/12``, the noise a
    correct model leaves on a rounded log; a correct model's least-squares fit leaves
    ``E χ² = n − k`` (its ``k`` unknowns absorb part of the rounding). A fit that goes
    below that is fitting the rounding, and the likelihood with a profiled σ would
    reward it without bound (``n·ln`` of a ratio of two tiny numbers): below the floor
    the variance is held at it, so improvements there are no evidence.
    """
    n = float(n)
    floor_chi2 = max(n - k, 1.0)
    return n * math.log(max(chi2, floor_chi2) / n) + k * math.log(n)


def bic(result, extra_parameters: int = 0) -> float:
    """Bayesian information criterion of a fit (:func:`bic_value`).

    ``n`` is the effective number of observations (hold and stuck tail each count once,
    as in the fit's weights) and ``k`` the fitted unknowns (physical parameters, release
    instants, start angles, offsets) plus any discrete settings scanned to get there.
    """
    return bic_value(_chi2(result), result.n_effective, result.n_unknowns + extra_parameters)


def _ladder_step(name: str, fit, cand: Candidate | None) -> dict[str, Any]:
    """A ladder row from a FitResult or a refit (:class:`~hdid._fitting._refit.StructureFit`); the
    BIC includes the cost of ``cand``'s scan."""
    if hasattr(fit, "starts"):  # FitResult
        chi2, n, k, rms = _chi2(fit), fit.n_effective, fit.n_unknowns, fit.rms_residual_rad
    else:
        chi2, n, k, rms = fit.cost, fit.n_effective, fit.n_unknowns, fit.rms_rad()
    return {
        "model": name,
        "effects": list(fit.model.effect_names),
        "rms_rad": rms,
        "bic": bic_value(chi2, n, k) + (cand.penalty(n) if cand is not None else 0.0),
        "n_unknowns": k,
    }


def model_ladder(log, models: Sequence, *, labels: Sequence[str] | None = None, **fit_options):
    """Fit each model in turn and tabulate RMS and BIC: the error falling as effects are added.

    Returns a list of dicts ``{model, effects, rms_rad, bic, n_unknowns, result}``.
    """
    out = []
    for i, m in enumerate(models):
        r = fit(log, m, **fit_options)
        name = labels[i] if labels else " + ".join(m.effect_names)
        out.append({**_ladder_step(name, r, None), "result": r})
    return out
