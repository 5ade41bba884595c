"""The base fit against the rounding floor a correct model leaves on *this* log, reported
by :func:`hdid.diagnose`, and a warning calibrated on clean logs
(``docs/decisions/floor-threshold.md``). The verdict rules and the BIC are not touched.

The BIC floors every model at the white-noise floor ``n − k``
(:func:`hdid._diagnosis._ladder.bic_value`). An encoder's rounding errors are correlated
where the angle moves less than a step between samples, and a correct model's fit leaves
less than that: ``F``, measured on the log (:func:`hdid._diagnosis._floor.fit_floor`;
0.4–0.95 × ``n − k`` on 250 Hz logs). A base fit between ``F`` and ``n − k`` is "at the
floor" for the BIC while leaving more than a correct model does. :class:`FloorCheck`
reports the base's ``χ²``, ``F`` with its sd over the grid's phase, ``χ²/F`` and ``n − k``.

How far above ``F`` may a correct model's fit land? ``calibration/floor_thresholds.py``
fits the base model to clean logs simulated from it (as the false-alarm calibration,
:mod:`hdid._diagnosis._rates`, makes them) and the threshold per design is an order
statistic of their ``χ²/F`` (:func:`choose`): the ``j``-th largest of ``N``, ``j`` the
largest for which the probability ``p`` that a new clean log exceeds it is ≤ ``TARGET``
with 95 % confidence. The footing: the ``N`` clean ratios and a new clean log's are
exchangeable, so ``p`` of the ``j``-th largest is distributed as Beta(``j``,
``N + 1 − j``) over the calibration's draws (mean ``j/(N + 1)``), and its 95 % quantile
is exactly the one-sided Clopper–Pearson bound of ``j − 1`` exceedances in ``N`` logs
(:func:`hdid._diagnosis._rates.upper_bound`). When the verdict names no effect
(``NO_EFFECT``) and the base's ratio is above the threshold of the nearest measured design
(:func:`hdid._diagnosis._rates.nearest`), a warning says so; far from every measured
design the ratio is reported without a warning, and a note says why.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from ._rates import TARGET, nearest, upper_bound


@dataclass(frozen=True)
class FloorThreshold:
    design: str
    #: sample rate [Hz] and runs of the design's logs (what :func:`threshold_for` matches)
    rate_hz: float
    runs: int
    #: clean logs measured, and how many of them are above the threshold (``j − 1``)
    logs: int
    above: int
    threshold: float
    measured: str

    @property
    def upper(self) -> float:
        """One-sided 95 % bound of the false-warning rate per clean log."""
        return upper_bound(self.above, self.logs)

    @property
    def mean_rate(self) -> float:
        """The false-warning rate's mean over calibrations, ``j/(N + 1)``."""
        return (self.above + 1) / (self.logs + 1)

    def to_dict(self) -> dict[str, Any]:
        return {"design": self.design, "rate_hz": self.rate_hz, "runs": self.runs,
                "threshold": self.threshold, "clean_logs": self.logs,
                "clean_logs_above": self.above, "false_warning_mean": self.mean_rate,
                "false_warning_upper_95": self.upper, "measured": self.measured}


#: Thresholds per design: GENERATED between the markers by ``python
#: calibration/floor_thresholds.py --threshold`` from ``calibration/results/floor_thresholds.json``
#: — never typed by hand (a test checks the two agree).
# BEGIN GENERATED
ROWS = (
    {'design': 'paper', 'rate_hz': 250.0, 'runs': 4, 'logs': 400, 'above': 12, 'threshold': 1.3408, 'measured': 'measured 2026-11-24 (src 28be8a8392665403) and 2026-11-25 (src cea2cacf40d19195), seeds 5000–5199, 7000–7199'},
    {'design': 'rich', 'rate_hz': 1000.0, 'runs': 8, 'logs': 400, 'above': 12, 'threshold': 1.1183, 'measured': 'measured 2026-11-24 (src 28be8a8392665403) and 2026-11-25 (src cea2cacf40d19195), seeds 5000–5199, 7000–7199'},
)
# END GENERATED
THRESHOLDS: tuple[FloorThreshold, ...] = tuple(FloorThreshold(**row) for row in ROWS)

#: The verdicts that name no effect: the warning is theirs (a named effect is the
#: candidates' business, and its own warnings say when it leaves the residual above floor).
NO_EFFECT = ("adequate", "unexplained")


def choose(ratios, target: float = TARGET) -> tuple[float, int] | None:
    """``(threshold, above)``: the ``j``-th largest of the clean ``ratios``, ``j`` the largest
    with ``upper_bound(j − 1, N) ≤ target`` (``above = j − 1`` ratios exceed it); ``None``
    when even the largest cannot show it (fewer than 59 logs at 5 %)."""
    r = sorted((float(x) for x in ratios), reverse=True)
    j = 0
    while j < len(r) and upper_bound(j, len(r)) <= target:
        j += 1
    return (r[j - 1], j - 1) if j else None


def threshold_for(rate_hz: float, runs: int,
                  measured: tuple[FloorThreshold, ...] | None = None) -> FloorThreshold | None:
    """The threshold of the measured design nearest the log, or ``None``."""
    return nearest(rate_hz, runs, THRESHOLDS if measured is None else measured)


@dataclass(frozen=True)
class FloorCheck:
    """The base fit's χ² against the measured floor ``F`` and the white one ``n − k``."""

    chi2: float
    floor: float
    floor_sd: float
    n: float
    k: int
    threshold: FloorThreshold | None

    @property
    def n_minus_k(self) -> float:
        return max(self.n - self.k, 1.0)  # the BIC's floor (bic_value)

    @property
    def ratio(self) -> float:
        return self.chi2 / self.floor

    @property
    def exceeded(self) -> bool | None:
        return None if self.threshold is None else bool(self.ratio > self.threshold.threshold)

    def to_dict(self) -> dict[str, Any]:
        return {"chi2": self.chi2, "floor": self.floor, "floor_sd": self.floor_sd,
                "chi2_over_floor": self.ratio, "n_effective": self.n, "n_unknowns": self.k,
                "n_minus_k": self.n_minus_k, "exceeded": self.exceeded,
                "threshold": self.threshold.to_dict() if self.threshold else None}

    def warnings(self, verdict: str) -> list[str]:
        if not (self.exceeded and verdict in NO_EFFECT):
            return []
        t = self.threshold
        return [f"the verdict names no effect, but the base fit leaves χ² {self.chi2:.1f} = "
                f"{self.ratio:.2f}× the rounding floor a correct model leaves on this log "
                f"(F = {self.floor:.1f}), above {t.threshold:.2f}, what clean logs of the "
                f"{t.design} design exceed with probability ≤ {100 * t.upper:.1f} % "
                "(one-sided 95 %): something is likely missing that no candidate was credited "
                "with (an effect outside the library, or one its penalty held back)"]

    def notes(self) -> list[str]:
        if self.threshold is not None:
            return []
        return [f"the base's χ²/F ({self.ratio:.2f}) is reported without a warning: how far "
                "above F a correct model lands was not measured for a design near this log's "
                "(sample rate, number of runs)"]


def floor_check(fit, rate_hz: float, runs: int,
                measured: tuple[FloorThreshold, ...] | None = None) -> FloorCheck | None:
    """:class:`FloorCheck` of a :class:`~hdid._fitting._refit.StructureFit`; ``None``
    where the floor cannot be computed (non-finite residuals or Jacobian)."""
    from ._floor import fit_floor

    try:
        F, sd = fit_floor(fit.setup, fit.u)
    except Exception:  # a reported number must not stop the diagnosis (a structure
        return None  # without weighted encoder samples: no such log yet)
    if not (math.isfinite(F) and F > 0):
        return None
    return FloorCheck(float(fit.cost), F, sd, float(fit.n_effective), int(fit.n_unknowns),
                      threshold_for(rate_hz, runs, measured))


def floor_text(d: dict[str, Any]) -> str:
    """The report's line from :meth:`FloorCheck.to_dict`."""
    t = d.get("threshold")
    cal = (f"; clean logs of the {t['design']} design exceed {t['threshold']:.2f}× with "
           f"probability ≤ {100 * t['false_warning_upper_95']:.1f} % (one-sided 95 %, "
           f"{t['clean_logs']} logs)" if t else "; no clean-log threshold near this design")
    return (f"base χ² {d['chi2']:.1f} = {d['chi2_over_floor']:.2f}× the rounding floor a "
            f"correct model leaves here (F {d['floor']:.1f} ± {d['floor_sd']:.1f} over the "
            f"grid's phase; the BIC's white-noise floor n − k = {d['n_minus_k']:.1f}){cal}")
