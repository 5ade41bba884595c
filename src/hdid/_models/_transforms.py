"""Maps between physical parameter values and the unconstrained space the optimiser sees."""

from __future__ import annotations

import contextlib

import jax.numpy as jnp
import numpy as np

from ..effects import Parameter


def to_unconstrained(spec: Parameter, value):
    t = spec.transform
    if t == "log":
        return np.log(value)
    if t == "identity":
        return np.asarray(value, dtype=float) / spec.scale
    kind, lo, hi = t
    if kind != "interval":
        raise ValueError(f"parameter {spec.name!r}: unknown transform {t!r}")
    p = (np.asarray(value, dtype=float) - lo) / (hi - lo)
    p = np.clip(p, 1e-9, 1 - 1e-9)
    return np.log(p) - np.log1p(-p)


def from_unconstrained(spec: Parameter, u, xp=jnp):
    """Physical value at ``u``; ``xp=numpy`` evaluates outside JAX (no dispatch).

    A start that ran off (``u`` beyond ±709) maps to the limit its value ran to — ∞ or 0
    for a log-parameter, an end of an interval — without NumPy's overflow warning (the
    records of every start, :class:`~hdid._results._summaries.StartSummary`, hold
    diverged ones)."""
    t = spec.transform
    if t == "identity":
        return spec.scale * u
    with _quiet_overflow(xp):
        if t == "log":
            return xp.exp(u)
        _, lo, hi = t
        return lo + (hi - lo) / (1.0 + xp.exp(-u))


def _quiet_overflow(xp):
    """``exp`` overflowing to ∞ is the limit the maps need (module doc); JAX never warns."""
    return np.errstate(over="ignore") if xp is np else contextlib.nullcontext()


def derivative(spec: Parameter, u) -> np.ndarray:
    """``d value / d u`` at ``u`` (for standard errors by the delta method): ∞ for a
    log-parameter run to ∞, 0 at an interval's end (overflow quiet, as above)."""
    t = spec.transform
    u = np.asarray(u, dtype=float)
    if t == "identity":
        return np.full_like(u, spec.scale)
    with np.errstate(over="ignore"):
        if t == "log":
            return np.exp(u)
        _, lo, hi = t
        s = 1.0 / (1.0 + np.exp(-u))
    return (hi - lo) * s * (1 - s)


def _sigmoid(u):
    return 1.0 / (1.0 + jnp.exp(-u))


def interval_to_u(value, lo, hi):
    """Inverse of :func:`interval_from_u`; 0 where the interval is a point (``lo == hi``:
    a run that starts in motion has its release at its first sample)."""
    lo, hi = np.asarray(lo, dtype=float), np.asarray(hi, dtype=float)
    width = hi - lo
    safe = np.where(width > 0, width, 1.0)
    p = np.clip((np.asarray(value, dtype=float) - lo) / safe, 1e-6, 1 - 1e-6)
    return np.where(width > 0, np.log(p) - np.log1p(-p), 0.0)


def interval_from_u(u, lo, hi):
    return lo + (hi - lo) * _sigmoid(u)

