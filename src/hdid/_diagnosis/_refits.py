"""A candidate's refits and its record: starts from the current optimum and the base grid
(:func:`_candidate_fits`), the current model's reverse starts from candidates' optima
(:func:`_base_starts`), and the BIC bookkeeping of :func:`hdid._diagnosis._diagnose.diagnose`."""

from __future__ import annotations

import math

from ._candidates import _candidate_setups, _scan_fits
from ._ladder import bic_value
from ._result import CandidateResult


def _own_optimum(fits):
    """A candidate's own optimum: its best finite refit (``None`` if it has none)."""
    if isinstance(fits, Exception) or not fits:
        return None
    ok = [f for f in fits if f.finite]
    return min(ok, key=lambda f: f.cost) if ok else None


def sf_key(by_key, sf) -> str:
    """The candidate key whose refits hold ``sf``."""
    return next(k for k, v in by_key.items() if not isinstance(v, Exception)
                and any(f is sf for f in v))


def _base_starts(base_setup, current, cand_fits, values_reset):
    """Starts for the current model from candidates' optima with the effect removed
    (parameters it shares with the current model, and its release instants, start angles
    and offsets; a piece the candidate replaced, e.g. the cubic spring under
    ``soft_windup``, at the current fit's values, not the set-up model's), and from the
    catalog friction shape."""
    from .._fitting import _refit

    starts = []
    now = current.values()
    for sf in cand_fits:
        if not sf.finite:
            continue
        v = sf.values()
        try:
            starts.append((f"reverse:{sf.label}", _refit.warm(
                base_setup, {**now, **{k: v[k] for k in base_setup.problem.free if k in v}},
                _refit.tail_of(sf.setup.problem, sf.u))))
        except ValueError:
            continue
    if values_reset:
        starts.append(("shape_reset", _refit.warm(
            base_setup, {**current.values(), **values_reset},
            _refit.tail_of(current.setup.problem, current.u))))
    return starts


def _cross_starts(own, current, others):
    """Starts for a candidate (``own``: its best refit, whose set-up the starts use) from
    the other candidates' optima (``others``): the current model's parameters at that
    optimum (friction, spring, …; the current fit's where that candidate replaced them),
    its release instants, start angles and offsets, and this candidate's own effect at
    its set-up's data-derived start. A candidate whose refits found a better basin of
    the shared parameters must not win by that start alone (a log with a hidden soft
    wind-up: hysteresis's refit reached friction the soft wind-up's never did, χ² 112
    against 198, and the soft wind-up was left out of the verdict; from hysteresis's
    optimum it reaches 96.5)."""
    from .._fitting import _refit

    starts = []
    now = current.values()
    base_free = set(current.setup.problem.free)
    for sf in others:
        if not sf.finite or sf is own:
            continue
        v = sf.values()
        shared = {k: v.get(k, now.get(k)) for k in own.setup.problem.free if k in base_free}
        try:
            starts.append((f"cross:{sf.label}", _refit.warm(
                own.setup, shared, _refit.tail_of(sf.setup.problem, sf.u))))
        except ValueError:
            continue
    return starts


def _candidate_fits(log, cand, current, hints, opts, grid_points, say, scans,
                    scan_refitted=None, prepared=None):
    """Refit ``cand`` on ``log`` from ``current``: a list of StructureFits (one per
    discrete setting refitted) — warm starts from the current optimum with the effect at
    each variant's data-derived values (and from the catalog friction shape), plus the
    best points of the base model's data-driven grid (``grid_points``: ``(values, tail)``
    pairs) with the effect at its first variant's values. (The base grid's points, not
    the candidate's own grid: the same data-driven rule, and one compiled grid program
    instead of one per candidate.) Scanned settings (orders) are first
    screened by one Gauss–Newton step; the best ``SCAN_REFITS`` are refitted.
    (``prepared``: :func:`_candidate_setups`'s result for the same arguments.)"""
    from .._fitting import _refit

    tail = _refit.tail_of(current.setup.problem, current.u)
    scan_refitted = {} if scan_refitted is None else scan_refitted
    groups, setups = (prepared if prepared is not None
                      else _candidate_setups(log, cand, current, hints, opts))
    fits = []
    if cand.scanned:
        return _scan_fits(cand, groups, setups, current, tail, grid_points, say, scans,
                          scan_refitted)
    for label, models in groups.items():
        s = setups[label]
        starts = [("warm", _refit.warm(s, m.float_values(), tail)) for m in models]
        first = models[0].float_values()
        starts += [("grid", _refit.warm(s, {**first, **v}, t)) for v, t in grid_points]
        say(f"  + {label}  ({len(starts)} starts)")
        fits.append(_refit.run(label, s, starts))
    return fits


def _cand_bic(sf, cand) -> float:
    """BIC of a candidate's refit, its scan's cost included (:meth:`Candidate.penalty`)."""
    return bic_value(sf.cost, sf.n_effective, sf.n_unknowns) + cand.penalty(sf.n_effective)


def _record(cand, sf, current_fit, base_bic_k):
    """A :class:`CandidateResult` from a candidate's refit (ΔBIC against ``current_fit``)."""
    dbic = (_cand_bic(sf, cand)
            - bic_value(current_fit.cost, current_fit.n_effective, base_bic_k))
    vals = sf.values()
    shown = {k: v for k, v in vals.items()
             if k not in current_fit.setup.problem.free or k in ("k1", "tau_c", "tau_s")}
    shown = {k: v for k, v in shown.items() if k in sf.setup.problem.free or k == "order"}
    return CandidateResult(
        cand.key, sf.label, math.nan, sf.rms_rad(), dbic, sf.n_unknowns - current_fit.n_unknowns,
        None, "", shown, None, None, fit=sf,
    )
