"""Per-parameter, per-run and per-start summaries of a fit: plain data (no JAX)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np


@dataclass
class ParameterEstimate:
    name: str
    value: float
    std: float
    unit: str
    fixed: bool
    doc: str = ""
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        return {
            "value": self.value,
            "unit": self.unit,
            "std": None if self.fixed else self.std,
            "fixed": self.fixed,
            **({"note": self.note} if self.note else {}),
        }


@dataclass
class RunSummary:
    name: str
    setup: str
    n_samples: int
    release_time: float
    release_time_std: float
    theta0: float
    offset: float
    rms_rad: float
    rest_logged: float
    rest_model: float
    stuck_at_end: bool
    peak_speed: float

    def to_dict(self) -> dict[str, Any]:
        return {k: getattr(self, k) for k in self.__dataclass_fields__}


@dataclass
class StartSummary:
    """What the multi-start local fits found."""

    costs: np.ndarray
    converged: np.ndarray
    steps: np.ndarray
    values: dict[str, np.ndarray]
    best: int

    @classmethod
    def from_solutions(cls, problem, U, costs, ok, steps, best) -> StartSummary:
        values = problem.free_values_np(U)
        return cls(np.asarray(costs), np.asarray(ok), np.asarray(steps), values, int(best))

    def same_minimum(self, dchi2: float = 1.0) -> np.ndarray:
        """Starts whose χ² is within ``dchi2`` of the best: statistically the same optimum
        (χ² is in units of the quantization variance, so Δχ² = 1 is one standard error)."""
        c = self.costs
        return np.isfinite(c) & (c - c[self.best] < dchi2)

    def spread(self) -> dict[str, float]:
        """Largest relative deviation from the best among starts that reached its cost."""
        same = self.same_minimum()
        out = {}
        for n, v in self.values.items():
            ref = v[self.best]
            out[n] = float(np.max(np.abs(v[same] - ref)) / abs(ref)) if ref else 0.0
        return out

    def to_dict(self) -> dict[str, Any]:
        return {
            "n_starts": int(len(self.costs)),
            "n_within_dchi2_1_of_best": int(self.same_minimum().sum()),
            "dchi2_to_best": [float(c - self.costs[self.best]) for c in self.costs],
            "costs": [float(c) for c in self.costs],
            "converged": [bool(x) for x in self.converged],
            "iterations": [int(s) for s in self.steps],
            "relative_spread_at_best_cost": self.spread(),
            "best": int(self.best),
            "parameter_values": {n: [float(x) for x in v] for n, v in self.values.items()},
        }
