"""Ranking candidates by what the user wants determined.

Scores are logarithms of standard-error ratios to the log's own design (negative:
better), so they do not depend on the parameters' units:

* ``"targets"`` — the mean of ``ln(std / std of this log)`` over the named targets
  (parameters, or derived quantities: ``band`` is the stick band's half-width,
  ``frequency`` the natural frequency): the geometric mean of their std ratios;
* ``"separate"`` — minus the smaller expected ``2·ln LR`` between two fitted models
  (:mod:`hdid._design._separate`): the design that tells them apart best first;
* ``"d"`` (D-optimality) — ``ln det`` of the fit's free parameters' covariance (in the
  optimiser's space, nuisances marginalised) less this log's, over ``2·p``: the ratio of
  the volumes of the confidence ellipsoids as a geometric-mean std ratio.

A candidate that leaves a target undetermined (infinite std) scores ``+inf``.
"""

from __future__ import annotations

import math

from .._errors import HdidError
from ._fisher import Prediction

#: Short names a user may give for derived quantities.
ALIASES = {
    "band": "stick_band_halfwidth_rad",
    "stick_band": "stick_band_halfwidth_rad",
    "frequency": "natural_frequency_hz",
    "natural_frequency": "natural_frequency_hz",
    "fn": "natural_frequency_hz",
}

CRITERIA = ("targets", "d", "separate")


def resolve_targets(targets, parameters, derived) -> tuple[str, ...]:
    """Targets as the names the predictions use; a one-line error for an unknown one."""
    if targets is None:
        return ()
    if isinstance(targets, str):
        targets = [t for t in targets.split(",")]
    out = []
    for t in targets:
        t = str(t).strip()
        if not t:
            continue
        name = ALIASES.get(t, t)
        if name not in parameters and name not in derived:
            raise HdidError(
                f"target {t!r}: not a parameter or derived quantity of this model; choose "
                f"from {', '.join([*parameters, *derived, *ALIASES])}")
        out.append(name)
    if not out:
        raise HdidError("targets: give at least one name, e.g. --target tau_c,band")
    return tuple(dict.fromkeys(out))


def std_of(p: Prediction, name: str) -> float:
    if name in p.std:
        return p.std[name]
    return p.derived_std.get(name, math.inf)


def score(p: Prediction, ref: Prediction, criterion: str, targets) -> float:
    if p.error is not None:
        return math.inf
    if criterion == "separate":  # the smaller expected 2 ln LR of the pair, negated
        sep = min(p.separation) if p.separation else math.nan
        ok = p.separation is not None and all(math.isfinite(x) for x in p.separation)
        return -sep if ok else math.inf  # a direction not evaluated: last
    if criterion == "d":
        n = sum(1 for _ in ref.names if _ in p.names) or 1
        if not (math.isfinite(p.logdet) and math.isfinite(ref.logdet)):
            return math.inf if not math.isfinite(p.logdet) else -math.inf
        return (p.logdet - ref.logdet) / (2 * n)
    logs = []
    for t in targets:
        a, b = std_of(p, t), std_of(ref, t)
        if not math.isfinite(a):
            return math.inf
        if not math.isfinite(b):
            logs.append(-math.inf)
            continue
        if a <= 0 or b <= 0:
            continue
        logs.append(math.log(a / b))
    return sum(logs) / len(logs) if logs else math.nan


def rank(preds: list[Prediction], criterion: str, targets) -> list[tuple[int, float]]:
    """``(index, score)`` best first; candidates that failed or score NaN last."""
    if criterion not in CRITERIA:
        raise HdidError(f"criterion {criterion!r}: choose one of {', '.join(CRITERIA)}")
    if criterion == "targets" and not targets:
        raise HdidError("criterion 'targets' needs targets (e.g. --target tau_c,band)")
    ref = preds[0]
    scored = [(i, score(p, ref, criterion, targets)) for i, p in enumerate(preds)]
    return sorted(scored, key=lambda x: (math.isnan(x[1]), x[1] if not math.isnan(x[1]) else 0.0))
