"""The measured false-alarm rate of :func:`hdid.diagnose`'s verdict rules.

A false alarm is a verdict other than ``adequate`` on a clean log: one simulated from a
fitted base model (hdid's simulator, the design's release angles, rate and length, a
random sub-sample release instant per run, rounded to the design's encoder), so the base
model is exactly right. ``calibration/diagnose_rates.py`` measures it per design and
writes ``calibration/results/diagnose_rates.{json,md}``; the numbers below are
generated from there (with the source they were measured on) and :func:`false_alarm` reports
the design nearest a log's, or says that none was measured near it.

The interval is the exact (Clopper–Pearson) 95 % binomial interval of ``k`` alarms in
``n`` logs. Whether the rate meets the 5 % target is a one-sided question: it is shown
(at 95 %) when the one-sided exact upper bound (:func:`upper_bound`) is ≤ 5 % — 0 alarms
in ≥ 59 logs, 1 in ≥ 93; the warnings say when it is not (0 of 46: 6.3 %).
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True)
class DesignRate:
    design: str
    #: sample rate [Hz] and number of runs of the design's logs
    rate_hz: float
    runs: int
    alarms: int
    logs: int
    lo: float
    hi: float
    measured: str

    @property
    def upper(self) -> float:
        """The one-sided exact 95 % upper bound of the rate: "≤ 5 %" is shown (at 95 %)
        when this is ≤ 5 % (1 alarm in 93 logs: 4.9999 %; 0 in 59: 4.95 %)."""
        return upper_bound(self.alarms, self.logs)

    def to_dict(self) -> dict:
        return {"design": self.design, "rate_hz": self.rate_hz, "runs": self.runs,
                "false_alarms": self.alarms, "clean_logs": self.logs,
                "rate": self.alarms / self.logs if self.logs else math.nan,
                "interval_95": [self.lo, self.hi], "upper_95": self.upper,
                "measured": self.measured}

    def text(self) -> str:
        return (f"false alarms on clean logs of the {self.design} design ({self.rate_hz:g} Hz, "
                f"{self.runs} runs): {self.alarms} of {self.logs} "
                f"({100 * self.alarms / self.logs:.0f} %, 95 % interval "
                f"{100 * self.lo:.1f}–{100 * self.hi:.1f} %, one-sided 95 % upper bound "
                f"{100 * self.upper:.1f} %; {self.measured})")


#: The measured rates, per design: GENERATED between the markers by ``python
#: calibration/diagnose_rates.py --measured`` from
#: ``calibration/results/diagnose_rates.json`` — never typed by hand (a test checks
#: the two agree).
# BEGIN GENERATED
ROWS = (
    {'design': 'paper', 'rate_hz': 250.0, 'runs': 4, 'alarms': 1, 'logs': 96, 'lo': 0.0003, 'hi': 0.0567, 'measured': 'measured 2026-11-24, src 4dda7eb49ff9b674'},
    {'design': 'rich', 'rate_hz': 1000.0, 'runs': 8, 'alarms': 0, 'logs': 60, 'lo': 0.0, 'hi': 0.0596, 'measured': 'measured 2026-11-24, src cf421ca8738f881c'},
)
# END GENERATED
MEASURED: tuple[DesignRate, ...] = tuple(DesignRate(**row) for row in ROWS)

#: A log is "near" a measured design when its sample rate is within this factor of the
#: design's and its number of runs within this factor too (the rule's behaviour depends
#: on the effective observations per run and the runs: n and k of the BIC).
NEAR_FACTOR = 2.0

#: The issue's target: at most this rate of false alarms per clean log.
TARGET = 0.05


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact binomial interval of ``k`` successes in ``n`` trials."""
    from scipy.stats import beta

    a = 1 - level
    lo = 0.0 if k == 0 else float(beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def upper_bound(k: int, n: int, level: float = 0.95) -> float:
    """Exact one-sided upper confidence bound of a binomial rate (``k`` of ``n``)."""
    from scipy.stats import beta

    return 1.0 if k >= n else float(beta.ppf(level, k + 1, n - k))


def nearest(rate_hz: float, runs: int, measured):
    """The measured design (any row with ``rate_hz``, ``runs`` and ``logs``) nearest a log
    of ``runs`` runs at ``rate_hz``, within ``NEAR_FACTOR`` on both; ``None`` if none is."""

    def dist(d) -> float:
        return abs(math.log(rate_hz / d.rate_hz)) + abs(math.log(max(runs, 1) / d.runs))

    # (a tolerance: a 500 Hz log's rate from its time stamps is 499.99999999999955 Hz,
    # exactly a factor 2 from the rich design's, and must not fall out by rounding)
    lim = math.log(NEAR_FACTOR) + 1e-9
    near = [d for d in measured if d.logs > 0
            and abs(math.log(rate_hz / d.rate_hz)) <= lim
            and abs(math.log(max(runs, 1) / d.runs)) <= lim]
    return min(near, key=dist) if near else None


def false_alarm(rate_hz: float, runs: int,
                measured: tuple[DesignRate, ...] | None = None) -> DesignRate | None:
    """The measured design nearest a log of ``runs`` runs at ``rate_hz`` (within
    ``NEAR_FACTOR`` on both: :func:`nearest`), or ``None``."""
    return nearest(rate_hz, runs, MEASURED if measured is None else measured)
