"""Ranking candidates by what the user wants determined.

Scores are logarithms of standard-error ratios to the log's own design (negative:
better), so they do not depend on the parameters' units:

* ``"targets"`` — the mean of ``ln(std / std of this log)`` over the named targets
  (parameters, or derived quantities: ``band`` is the stick band's half-width,
  ``frequency`` the natural frequency): the geometric mean of their std ratios;
* ``"separate"`` — minus the smaller expected ``2·ln LR`` between two fitted models
  (:mod:`hdid._design._separate`): the design that tells them apart best first. A value
  whose rival was fitted only locally is an upper bound — the design separates the pair
  *at most* that well (3–25× the realised 2·ln LR on confusable pairs) — so the values
  (the rival fitted globally) rank first, then the upper bounds, then the linearised
  values, each tier largest first, as :func:`hdid.diagnose` ranks its separating
  experiments; :func:`separation_warnings` says where a bound above the top value was
  left unverified;
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

#: How a separation was computed (``Prediction.separation_kind``), most trusted first:
#: the rank tier of ``criterion="separate"`` (module docstring).
SEPARATION_KINDS = ("rival fitted globally", "upper bound", "linearised")


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

    def tier(i: int) -> int:  # "separate": values, then upper bounds, then the rest
        if criterion != "separate":
            return 0
        kind = preds[i].separation_kind
        return SEPARATION_KINDS.index(kind) if kind in SEPARATION_KINDS else len(SEPARATION_KINDS)

    return sorted(scored, key=lambda x: (math.isnan(x[1]), math.isinf(x[1]) and x[1] > 0,
                                         tier(x[0]), x[1] if not math.isnan(x[1]) else 0.0))


def separation_warnings(preds: list[Prediction], rival_fits: int) -> list[str]:
    """What the ``"separate"`` ranking cannot vouch for: no value at all (every candidate
    ranked by an upper bound or a linearisation), or candidates whose upper bound exceeds
    the top value but whose rival was not fitted globally within ``rival_fits`` (ranked
    below every value: a bound says only "at most")."""
    def lam(p):
        ok = p.error is None and p.separation is not None and all(math.isfinite(x) for x in p.separation)
        return min(p.separation) if ok else math.nan

    values = [lam(p) for p in preds if p.separation_kind == SEPARATION_KINDS[0]]
    values = [v for v in values if math.isfinite(v)]
    bounds = [(lam(p), p.experiment.name) for p in preds if p.separation_kind != SEPARATION_KINDS[0]]
    bounds = sorted(((v, n) for v, n in bounds if math.isfinite(v)), reverse=True)
    if not bounds:
        return []
    if not values:
        return [f"no candidate's rival was fitted globally (rival_fits={rival_fits}): the ranking "
                "is by local upper bounds ('<=') or linearised values, each only an 'at most'; "
                "the top candidate may separate the pair far less (rival_fits > 0 fits the "
                "largest, or confirm by simulation: check=)"]
    top = max(values)
    above = [(v, n) for v, n in bounds if v > top]
    if not above:
        return []
    names = ", ".join(repr(n) for _, n in above[:5]) + (", ..." if len(above) > 5 else "")
    return [f"{len(above)} candidate(s) ({names}) have upper bounds up to {above[0][0]:.3g} above "
            f"the top globally fitted value {top:.3g}, but their rival was not fitted globally "
            f"within rival_fits={rival_fits}: a bound is only an 'at most', so they rank below "
            "every fitted value (raise rival_fits to fit them)"]
