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
