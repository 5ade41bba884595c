"""Warnings on whether a fitted value can be trusted as stated: a standard error that is not
finite, a parameter run off to 0/∞ or onto its interval's bound, a breakaway below Coulomb
friction, and standard errors linearised at a Stribeck shape the log does not determine
(the levels', and any parameter's whose variance runs along that shape). Called by
:mod:`._identifiability` at the optimum."""

from __future__ import annotations

import math

import numpy as np

from .._problems._problem import Problem
from ..effects import StribeckFriction

#: Two parameters (or one and a set) correlated above this are "strongly correlated".
HIGH_CORRELATION = 0.95

#: An interval parameter within this fraction of its interval's width from an end is
#: "at its bound".
AT_BOUND = 1e-3


def _trust_warnings(problem: Problem, u, params, std_u, values) -> list[str]:
    """A result that is not trustworthy says so: non-finite standard errors, parameters
    run off to 0/∞ or onto an interval bound, breakaway below Coulomb friction."""
    out = []
    specs = problem.base.parameter_specs()
    u = np.asarray(u, dtype=float)
    nan = [n for n, p in params.items() if not p.fixed and not np.isfinite(p.std)]
    if nan:
        out.append(
            "no finite standard error for " + ", ".join(nan) + ": the data do not "
            "determine them at this optimum (fix them, give a prior, or log a richer test)"
        )
    for i, n in enumerate(problem.free):
        t = specs[n].transform
        if isinstance(t, tuple):
            _, lo, hi = t
            x = values[n]
            if min(x - lo, hi - x) < AT_BOUND * (hi - lo):
                out.append(f"{n} = {x:.4g} is at the bound of its range ({lo:g}, {hi:g}): "
                           "the optimum lies outside what the model allows")
        elif t == "log" and not (1e-200 < values[n] < 1e200):
            out.append(f"{n} = {values[n]:.4g} ran towards 0 or infinity: the effect is not "
                       "supported by the data (try the model without it)")
    if "tau_s" in values and "tau_c" in values and values["tau_s"] < values["tau_c"]:
        out.append(
            f"tau_s = {values['tau_s']:.4g} < tau_c = {values['tau_c']:.4g}: the fitted friction "
            "falls below its sliding level at rest (negative Stribeck rise); the data prefer a "
            "lower breakaway than sliding friction — check the model (e.g. remove stribeck's "
            "rise by fixing tau_s = tau_c)"
        )
    return out


def _shape_warnings(problem: Problem, flags: dict[str, str], cov, std_u) -> list[str]:
    """A Stribeck law's levels (``tau_c``, ``tau_s``) get standard errors linearised at its
    fitted shape (``v_s``, ``delta``); where the log does not determine that shape, the
    likelihood is far from Gaussian along it and the levels' errors are too small (an
    independent csf20 paper-design log: v_s 0.63 ± 0.83 against a true 3.6, tau_c 3.8
    standard errors from the truth at a fit below the truth's own residual).

    Any other determined parameter whose variance runs mostly along the law's undetermined
    parameters (multiple correlation above ``HIGH_CORRELATION`` in the covariance of the
    unknowns, ``cov``) has the same doubt: its standard error is the shape's linearised
    spread carried over (a world-test log with ``v_s`` far above the peak speed: ``c_v``
    traded with the Stribeck slope, multiple correlation 0.996, and sat 8.8 of its
    standard errors from the truth)."""
    out = []
    free = list(problem.free)
    for law in problem.base.effects:
        if type(law) is not StribeckFriction:
            continue
        names = [p.name for p in law.parameters]
        levels = [n for n in names[:2] if n in problem.free and n not in flags]
        shape = [n for n in names[2:4] if n in problem.free and n in flags]
        if levels and shape:
            out.append(
                f"{', '.join(levels)}: standard errors assume the Stribeck shape "
                f"({', '.join(shape)}), which this log does not determine, and may be too "
                "small — sample the posterior (--posterior) for intervals over the shape"
            )
        if not shape:
            continue
        loose = [n for n in names if n in flags and n in free and math.isfinite(std_u[free.index(n)])]
        for name, r2 in _carried(free, cov, std_u, flags, loose, exclude=set(names)):
            out.append(
                f"{name}: {100 * r2:.0f} % of its variance runs along the Stribeck law's "
                f"undetermined {', '.join(loose)} (multiple correlation {math.sqrt(r2):.3f} > "
                f"{HIGH_CORRELATION}): its standard error is that shape's linearised spread "
                f"carried over ({1 / math.sqrt(max(1 - r2, 1e-300)):.3g}× its error at a "
                "fixed shape) and is too small by as much as the shape's real spread is "
                "wider — sample the posterior (--posterior) for intervals over the shape"
            )
    return out


def _carried(free: list[str], cov, std_u, flags, along: list[str], exclude: set[str]):
    """``(name, R²)`` for each determined free parameter (not flagged, finite std, not in
    ``exclude``) whose squared multiple correlation with the parameters ``along`` exceeds
    ``HIGH_CORRELATION²``: ``R² = c_xSᵀ C_SS⁺ c_xS / c_xx`` from the covariance ``cov`` of
    the unknowns (the fraction of its variance explained by ``along``; the remainder
    ``1 − R²`` is its variance at fixed ``along``)."""
    s = [free.index(n) for n in along]
    if not s:
        return []
    C = np.asarray(cov, dtype=float)[:len(free), :len(free)]
    d = np.sqrt(np.clip(np.diag(C), 1e-300, None))
    R = C / np.outer(d, d)  # correlations: the pseudo-inverse's cut is then unit-free
    rss_pinv = np.linalg.pinv(R[np.ix_(s, s)], hermitian=True)
    out = []
    for i, name in enumerate(free):
        if name in exclude or name in flags or not math.isfinite(std_u[i]) or C[i, i] <= 0:
            continue
        r2 = min(max(float(R[i, s] @ rss_pinv @ R[i, s]), 0.0), 1.0)
        if r2 > HIGH_CORRELATION**2:
            out.append((name, r2))
    return out
