"""One round of :func:`hdid.diagnose`'s search, step by step: look at the current fit's
residual, refit every candidate from it, give the current model every start a candidate
got (and start the candidates again where that finds it a better basin, each also from
the others' optima), and tabulate the candidates against it. The rules that judge the
table are in :mod:`._verdict`; the order of the steps and why is the module docstring of
:mod:`._diagnose`."""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._candidates import _candidate_setups, _merge, _ripple_orders, _shape_is_unusual, _shape_reset
from ._ladder import bic_value
from ._refits import (_base_starts, _cand_bic, _candidate_fits, _cross_starts, _own_optimum,
                      _record, sf_key)
from ._result import CandidateResult

#: A current fit with RMS above this many quantization floors is a poor warm start ...
FAR_FROM_FLOOR = 3.0
#: ... so its candidates get as many grid starts as the base fit always gets.
FULL_GRID_STARTS = 6
#: Strong candidates whose residual is analysed (covariance, whiteness) per round: the
#: verdict needs only the best one's (each analysis compiles programs of its own).
MAX_ANALYSED = 1
#: Passes of "current model from the candidates' optima, then the candidates from the
#: current model's new optimum" when the first finds the current model a better basin.
BASIN_PASSES = 2
#: A restart of the current model counts as a better optimum (a note, a warning, the
#: candidates started again) when it lowers the current model's BIC by more than this:
#: where "positive" evidence starts on Kass & Raftery's (1995) scale. (The old 1-χ² rule
#: also fired below the quantization floor, e.g. χ² 15.0 → 13.4 on a clean 250 Hz log
#: with n = 35, k = 17, where the BIC does not move; above it, 21.7 → 20.2 is ΔBIC 2.5:
#: a better basin found late, real, not noise.) The better optimum is kept either way.
BASE_IMPROVED_DBIC = 2.0


@dataclass
class Search:
    """What the rounds of one diagnosis share: the log, the fit options and the candidate
    catalog; the base fit's set-up and data-driven grid (every round's grid starts come
    from it); and what the rounds record for the report."""

    log: Any
    fit_options: dict[str, Any]
    all_cands: dict[str, Any]
    say: Callable[[str], None]
    base_setup: Any
    base_grid: list
    #: the report's notes, in the order the steps wrote them
    notes: list[str] = field(default_factory=list)
    #: ``(χ² before, χ² after, candidate)`` each time a candidate's optimum gave the
    #: current model a better basin (a warning: the log's fits have several basins)
    local_base: list[tuple[float, float, str]] = field(default_factory=list)
    #: one-step gains of every scanned setting, per candidate, and the settings refitted
    scans: dict[str, dict[str, float]] = field(default_factory=dict)
    refitted: dict[str, list[str]] = field(default_factory=dict)


@dataclass
class Residual:
    """The current fit's analysed result and what its residual shows: the whiteness test
    (RMS against the floor, Ljung–Box) and the features the reasons quote."""

    result: Any
    white: Any
    frame: Any
    features: dict[str, float]


def look_at(current) -> Residual:
    """Analyse the current fit (covariance, residual frame) and test its residual."""
    from .._results._residuals import residual_features, residual_frame, whiteness

    result = current.result()
    white = whiteness(result)
    frame = residual_frame(result)
    return Residual(result, white, frame, residual_features(frame))


def hints_from(frame) -> dict[str, Any]:
    """What the residual tells the candidates' starts: the ripple orders the periodogram
    finds, and the swing of the wave-generator angle while moving [rad] (which orders
    complete a period within it); and the frame itself (the reading-age scan reads it)."""
    moving = frame.loc[frame["phase"] == "moving", "theta_wg"]
    swing = float(np.ptp(moving)) if len(moving) else math.inf
    return {"ripple_orders": _ripple_orders(frame), "swing_rad": swing, "frame": frame}


def grid_points(s: Search, current, floor: float, n_starts: int) -> list:
    """The base grid's best points as ``(values, tail)`` starts for every candidate:
    ``n_starts`` of them, or ``FULL_GRID_STARTS`` when the current fit is far from the
    floor (``FAR_FROM_FLOOR``; e.g. a model without static friction that never sticks is
    no trustworthy warm start)."""
    from .._fitting import _refit

    far = current.rms_rad() > FAR_FROM_FLOOR * floor
    n_grid = max(n_starts, FULL_GRID_STARTS) if far else n_starts
    p0 = s.base_setup.problem
    return [({k: float(v) for k, v in p0.unpack_np(u)[0].items()}, _refit.tail_of(p0, u))
            for u in s.base_grid[:n_grid]]


def refit_candidates(s: Search, current, wanted: list[str], hints, points) -> dict[str, Any]:
    """Every wanted candidate that applies to the current model, refitted from it: its
    key → its refits (a list of StructureFits) or the exception that stopped it (one
    candidate failing must not stop the others). All set-ups are made first, so their
    programs are read from the store in the background while the first are refitted."""
    from .._fitting import _refit

    by_key: dict[str, Any] = {}
    prepared: dict[str, Any] = {}
    for key in wanted:
        cand = s.all_cands[key]
        if not cand.applies(current.model):
            continue
        try:
            prepared[key] = _candidate_setups(s.log, cand, current, hints, s.fit_options)
        except Exception as exc:  # one candidate failing must not stop the others
            by_key[key] = exc
            continue
        for setup in prepared[key][1].values():
            _refit.prefetch(setup)
    for key, prep in prepared.items():
        try:
            by_key[key] = _candidate_fits(s.log, s.all_cands[key], current, hints,
                                          s.fit_options, points, s.say, s.scans, s.refitted,
                                          prepared=prep)
        except Exception as exc:  # one candidate failing must not stop the others
            by_key[key] = exc
    return by_key


def current_from_candidates(s: Search, current, look: Residual, by_key, hints):
    """The current model gets every start a candidate got, so that a candidate is credited
    only with what the current model cannot reach: from each candidate's own optimum (its
    best refit) with the effect removed, wherever the candidate would be credited with
    anything (ΔBIC < 0: a strong claim and its possible rivals alike; one start each), and
    from the catalog friction shape where the current one is unusual. When that lowers
    the current model's BIC by more than ``BASE_IMPROVED_DBIC``, the first optimum was a
    local one: a note says so, the candidates are started again from the new optimum and
    the current model again from their new optima (``BASIN_PASSES``). ``by_key`` gains
    the new refits. Returns the current fit and its residual."""
    from .._fitting import _refit

    tried: set[int] = set()
    for basin in range(BASIN_PASSES):
        bic_now = bic_value(current.cost, current.n_effective, current.n_unknowns)
        cand_fits = sorted(
            (sf for sf in (_own_optimum(v) for v in by_key.values()) if sf is not None
             and id(sf) not in tried
             and _cand_bic(sf, s.all_cands[sf_key(by_key, sf)]) - bic_now < 0),
            key=lambda sf: sf.cost)
        tried.update(id(sf) for sf in cand_fits)
        values = current.values()
        reset = _shape_reset(values) if basin == 0 and _shape_is_unusual(values) else {}
        back = _base_starts(current.setup, current, cand_fits, reset)
        if not back:
            break
        s.say(f"  current model from {len(back)} candidate optima (effect removed)")
        again = _refit.run(current.label, current.setup, back)
        if not (again.finite and bic_value(again.cost, again.n_effective, again.n_unknowns)
                < bic_now - BASE_IMPROVED_DBIC):
            current = _merge(current, again)
            current._result = look.result  # the same optimum: its analysis stands
            break
        best_origin = again.origins[again.best].split(":")[-1]
        s.local_base.append((current.cost, again.cost, best_origin))
        s.notes.append(
            f"the current model improved from a start at {best_origin}'s optimum (χ² "
            f"{current.cost:.1f} → {again.cost:.1f}): its first optimum was a local one, "
            "and no candidate is credited with the difference"
        )
        current = _merge(current, again)
        look = look_at(current)
        if basin + 1 < BASIN_PASSES:
            # The candidates started from the first, local optimum: start them again from
            # the new one (warm starts only; the grid's are the same), so each is at its
            # own optimum next to the current model's, and the current model gets a start
            # from every new candidate optimum in the next pass.
            s.say("  candidates again from the current model's new optimum")
            for key in list(by_key):
                if isinstance(by_key[key], Exception):
                    continue
                try:
                    by_key[key] = by_key[key] + _candidate_fits(
                        s.log, s.all_cands[key], current, hints, s.fit_options, [], s.say,
                        s.scans, s.refitted)
                except Exception:  # the first pass's refits stand
                    pass
            cross_refits(s, current, by_key)
    return current, look


def cross_refits(s: Search, current, by_key) -> None:
    """After the current model found a better basin: every candidate also starts from
    every other candidate's optimum that would be credited with anything against the new
    optimum (ΔBIC < 0), that optimum's effect removed and its own added
    (:func:`~hdid._diagnosis._refits._cross_starts`; one refit of its best set-up). Where
    the fits have several basins a candidate's refits may miss the basin of the shared
    parameters another's reached, and the verdict would credit the other's start, not
    its effect. ``by_key`` gains the new refits."""
    from .._fitting import _refit

    bic_now = bic_value(current.cost, current.n_effective, current.n_unknowns)
    own = {k: _own_optimum(v) for k, v in by_key.items()}
    others = [sf for k, sf in own.items() if sf is not None
              and _cand_bic(sf, s.all_cands[k]) - bic_now < 0]
    if not others:
        return
    s.say(f"  candidates again from {len(others)} other candidates' optima")
    for key, sf in own.items():
        starts = _cross_starts(sf, current, others) if sf is not None else []
        if starts:
            try:
                by_key[key] = [*by_key[key], _refit.run(sf.label, sf.setup, starts)]
            except Exception:  # the earlier refits stand
                continue


def candidate_table(s: Search, by_key, current, fcheck) -> list[CandidateResult]:
    """One :class:`CandidateResult` per candidate from its best finite refit (ΔBIC against
    the current model, RMS before and after, χ² over the base's rounding floor ``F``), or
    its error; sorted by ΔBIC, failures last."""
    results: list[CandidateResult] = []
    k_base = current.n_unknowns
    for key, fits in by_key.items():
        cand = s.all_cands[key]
        if isinstance(fits, Exception) or not fits or not any(f.finite for f in fits):
            err = fits if isinstance(fits, Exception) else RuntimeError("no finite refit")
            results.append(CandidateResult(key, key, math.nan, math.nan, math.inf, 0, None,
                                           "", {}, None, f"{type(err).__name__}: {err}"))
            continue
        best_sf = min((f for f in fits if f.finite), key=lambda f: f.cost)
        results.append(_record(cand, best_sf, current, k_base))
    rms_before = current.rms_rad()
    for c in results:
        c.rms_before_rad = rms_before
        if fcheck is not None and c.fit is not None:  # against the base's F
            c.chi2_over_floor = float(c.fit.cost) / fcheck.floor
    results.sort(key=lambda c: (c.error is not None, c.delta_bic))
    return results


#: Strong candidates above the floor that get :func:`hdid.fit`'s whole driver before the
#: verdict (:func:`driver_refits`), the best ΔBIC first; each costs one fit.
MAX_DRIVER_REFITS = 4


def driver_refits(s: Search, by_key, results: list[CandidateResult], current, fcheck,
                  floor: float, strong_dbic: float) -> list[CandidateResult]:
    """Before a verdict: the strong candidates whose refits stay above the floor (at most
    ``MAX_DRIVER_REFITS``, by ΔBIC) are fitted again by :func:`hdid.fit` itself — its
    data-driven grid of the candidate's model, its restarts and limit checks above the
    floor — from where their refits began, as the separating experiment's rival is
    (:mod:`hdid._design._best_rival`). The refits above start every candidate near the
    current optimum; a candidate whose optimum lies elsewhere (a free play with a stiffer
    spring and another friction shape: a hidden backlash on a 1 kHz log of four
    amplitudes, refitted to 2.2× the floor where hdid.fit reaches 0.95×) lost to a
    look-alike at the floor (named alone on 7 of 10 such logs), or left the log
    ``unexplained`` (``benchmarks/design_check.py --diagnose-logs``). An optimum found
    joins the candidate's refits and the table is made again."""
    from .._errors import HdidError
    from .._fitting import _refit
    from .._fitting._fit import fit as fit_log
    from .._results._whiteness import AT_FLOOR_RATIO

    behind = [c for c in results if c.error is None and c.delta_bic < strong_dbic
              and c.fit is not None and c.rms_after_rad > AT_FLOOR_RATIO * floor]
    changed = False
    for c in behind[:MAX_DRIVER_REFITS]:
        sf = c.fit
        # from the candidate's set-up model (the current optimum with the effect at its
        # data-derived start), where the refits began: the driver's own grid and restarts
        # then search from there (from the refit's optimum it stayed in its basin: 1.4×)
        model = sf.setup.model
        s.say(f"  {c.label}: hdid.fit's own driver (its refits stay above the floor)")
        try:
            r = fit_log(s.log, model=model, start_from_model=True, **s.fit_options)
            u = _refit.warm(sf.setup, r.model.float_values(), _refit.tail_of(r.problem, r.u))
        except (HdidError, ValueError, FloatingPointError):
            continue
        again = _refit.run(sf.label, sf.setup, [("driver", u)])
        if again.finite and again.cost < sf.cost:
            by_key[c.key] = [*by_key[c.key], again]
            changed = True
    return candidate_table(s, by_key, current, fcheck) if changed else results


def corner_restarts(s: Search, by_key, results: list[CandidateResult], current, fcheck,
                    strong_dbic: float) -> list[CandidateResult]:
    """A strong richer form whose optimum sits at its corner that is a simpler one
    (:mod:`hdid._diagnosis._nesting`: soft wind-up with ``K1`` at zero, a free play) while
    the simpler one's refits ended higher: the simpler one refitted from that corner
    mapped back (:func:`hdid._diagnosis._nesting.simple_values`, the shared parameters and
    the runs' nuisances at the richer fit's). Its refits start near the current optimum and
    may miss the basin the richer one found through its extra freedom (a backlash log
    with four amplitudes at 1 kHz: soft wind-up at K1 66 ± 162, χ² 169; backlash 262, so
    the richer form was named alone). An optimum found joins the simpler one's refits and
    the table is made again."""
    from .._fitting import _refit
    from ._nesting import NESTINGS, at_corner, simple_values

    fitted = {c.key: c for c in results if c.error is None and c.fit is not None and c.fit.finite}
    changed = False
    for n in NESTINGS:  # the simpler one strong or not: its refits may have missed the basin
        rich, simple = fitted.get(n.rich), fitted.get(n.simple)
        if (rich is None or simple is None or not rich.delta_bic < strong_dbic
                or simple.fit.cost <= rich.fit.cost):
            continue
        if at_corner(rich.fit.result(), simple.values, n) is None:
            continue
        rf, sf = rich.fit, simple.fit
        values = {**rf.values(), **simple_values(n, rf.values(), float(rf.model.ratio))}
        s.say(f"  {simple.label}: refitted from {rich.label}'s corner that is it")
        u = _refit.warm(sf.setup, values, _refit.tail_of(rf.setup.problem, rf.u))
        again = _refit.run(sf.label, sf.setup, [("corner", u)])
        if again.finite and again.cost < sf.cost:
            by_key[simple.key] = [*by_key[simple.key], again]
            changed = True
    return candidate_table(s, by_key, current, fcheck) if changed else results


def analyse_strong(results: list[CandidateResult], strong_dbic: float) -> list[CandidateResult]:
    """The strong candidates (ΔBIC below ``strong_dbic``), best first; the first
    ``MAX_ANALYSED`` analysed: whether their refit leaves a white residual at the floor
    (the verdict needs only the best one's; each analysis compiles programs of its own)."""
    strong = [c for c in results if c.error is None and c.delta_bic < strong_dbic]
    for c in strong[:MAX_ANALYSED]:
        analyse(c)
    return strong


def analyse(c: CandidateResult):
    """``c``'s refit analysed (its covariance: ``c.result``) and its residual's whiteness
    and floor test (``white_after``, ``moving_ratio_after``, ``adequate_after``), once.
    Returns ``c.result``."""
    from .._results._residuals import whiteness

    if c.result is None:
        c.result = c.fit.result()
    if c.adequate_after is None:
        w = whiteness(c.result)
        c.white_after = bool(w.white)
        c.moving_ratio_after = float(w.rms_ratio)
        c.adequate_after = bool(w.at_floor)
    return c.result
