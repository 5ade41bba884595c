"""Covariance from a Fisher matrix that may be singular, and the test for a quantity
the data do not determine (its gradient leans into the null space). NumPy only."""

from __future__ import annotations

import numpy as np


def _covariance(fisher: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pseudo-inverse of a Fisher matrix and the basis of its null space.

    A plain pseudo-inverse gives directions the data cannot see zero variance — exactly
    backwards (e.g. the joint scale of every torque and the inertia in free motion).
    Callers treat any quantity with a component along ``null`` as undetermined
    (infinite variance); quantities orthogonal to it (like ``k1/inertia``) keep the
    pseudo-inverse variance, which is then the right one.
    """
    a = 0.5 * (fisher + fisher.T)
    w, v = np.linalg.eigh(a)
    tol = max(float(w.max()), 0.0) * 1e-10 if w.size else 0.0
    ok = w > tol
    inv = np.where(ok, 1.0 / np.where(ok, w, 1.0), 0.0)
    return (v * inv) @ v.T, v[:, ~ok]


#: A quantity whose gradient has more than this relative component in the null space
#: of the Fisher matrix is undetermined. Genuine components are O(0.1–1) (the free-motion
#: scale direction has equal weights 1/√6 on six log-parameters); numerical mixing
#: between near-null eigenvectors is orders of magnitude smaller.
NULL_COMPONENT = 1e-2


def _undetermined(g: np.ndarray, null: np.ndarray) -> bool:
    if null.size == 0:
        return False
    norm = np.linalg.norm(g)
    return bool(norm > 0 and np.linalg.norm(g @ null) > NULL_COMPONENT * norm)


def scaled_covariance(fisher: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """:func:`_covariance` after Jacobi scaling: ``(cov, null_s, d)``.

    Which directions the data do not see is a question of correlation, not of units:
    ``fisher / (d dᵀ)`` with ``d = √diag(fisher)`` has a unit diagonal, so its eigenvalue
    cut compares directions by how far the data tell them apart. Unscaled, the cut also
    compares the unknowns' sensitivities, which span many orders — a driven log's inertia
    against an output-friction sign flip, or a log-parameter that ran towards 0 (its
    column is the value times the physical sensitivity: a free-motion fit's viscous
    ``c_v`` at 1e-12 N m s) — and a pseudo-inverse that drops such a direction holds it
    fixed: every parameter it trades with gets its conditional variance (a sweep log:
    ``tau_c`` +20.8 % from its truth at a reported ±0.13 %, ``c_v → 0`` taking the
    viscous loss into the sliding level). Unknowns the data do not touch at all (a zero
    column) stay exactly null. ``null_s`` is the null basis in the *scaled* unknowns:
    test a gradient ``g`` as ``g / d`` (:func:`undetermined_scaled`); :func:`null_in_u`
    maps it back.
    """
    d = np.sqrt(np.clip(np.diag(fisher), 0.0, None))
    d = np.where(d > 0, d, 1.0)
    cov_s, null_s = _covariance(fisher / np.outer(d, d))
    return cov_s / np.outer(d, d), null_s, d


def undetermined_scaled(g: np.ndarray, null_s: np.ndarray, d: np.ndarray) -> bool:
    """Whether a quantity with gradient ``g`` (unscaled unknowns) has a component along a
    null direction of :func:`scaled_covariance` — tested in the scaled space, where the
    null basis is orthonormal (in the unscaled space a null direction's physical
    components can be 1e-5 of its nuisance components and slip under any threshold)."""
    return _undetermined(g / d, null_s)


def null_in_u(null_s: np.ndarray, d: np.ndarray) -> np.ndarray:
    """An orthonormal basis of the null directions of :func:`scaled_covariance` in the
    unscaled unknowns (a scaled null vector ``v`` is the direction ``v / d``)."""
    if null_s.size == 0:
        return null_s
    q, _ = np.linalg.qr(null_s / d[:, None])
    return q
