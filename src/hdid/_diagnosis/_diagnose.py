"""Which physical effect is missing? Refit with each candidate and rank by BIC.

``diagnose`` fits the current model, then adds each library effect the model lacks (or
swaps in a richer law for a base piece), refits, and ranks the candidates by the change
of the Bayesian information criterion.

Refits (:mod:`hdid._fitting._refit`)
    Every candidate starts from the current optimum — every shared parameter at the
    current fit's value (:func:`_at_optimum`), release instants, start angles and offsets
    included — with its new parameters at data-derived values (several where the
    effect's basin is narrow), from the catalog friction shape when the current fit's is
    unusual, and from the best points of :func:`hdid.fit`'s data-driven grid; all starts
    of one model structure run through one program. The current model gets every start
    a candidate gets: its own grid (``FULL_GRID_STARTS``, more than any candidate), the
    catalog shape, and each candidate's own optimum (its best refit, wherever it would be
    credited with anything: ΔBIC < 0) with the added effect removed (a piece the
    candidate replaced at the current fit's values). When one of those restarts finds
    the current model a better basin, the candidates are started again from the new
    optimum and the current model again from their new optima (``BASIN_PASSES``). A
    candidate is credited only with what the current model cannot reach from there.
Orders
    Position-periodic candidates (``ripple``, ``kinematic_error``) scan every integer
    order 1–48 (the ripple also the residual periodogram's two peaks): each screened by
    one Gauss–Newton step (the score statistic; the order is traced, one program for
    all), the best ``SCAN_REFITS`` and every order within ``SCAN_TIE_DCHI2`` of the best
    screen refitted (at most ``SCAN_MAX_REFITS``: the order is decided by the fit), from
    the starts other candidates get (:func:`~hdid._diagnosis._candidates._scan_fits`).
    The scan costs one parameter plus ``2·ln M`` for choosing among ``M`` orders (the
    periodogram searches 120: 9.6). The scanned set, the one-step gains and the refitted
    orders are in the notes and in ``Diagnosis.scanned`` / ``.refitted``.
Evidence
    ``BIC = n·ln(max(χ², n − k)/n) + k·ln n`` (:func:`bic_value`), ``χ²`` in units of the
    quantization variance ``step²/12``, ``n`` the effective observations, ``k`` the fitted
    unknowns. The noise variance is profiled out but never below the quantization floor:
    a fit below the floor is fitting the rounding, and that is no evidence. A candidate
    has strong evidence when ``ΔBIC < STRONG_DBIC`` (−10; Kass & Raftery 1995: a Bayes
    factor above e⁵ ≈ 150 under the BIC's unit-information prior). That footing is
    asymptotic; at the few dozen effective observations of a 250 Hz log it is not exact,
    so the rules' false-alarm rate is *measured*: clean logs simulated from a fitted base
    model, quantized like the data, diagnosed with every candidate; a false alarm is any
    verdict but ``adequate`` (``calibration/diagnose_rates.py``; the numbers, per
    design, in :mod:`hdid._diagnosis._rates`). ``Diagnosis.false_alarm`` reports the rate
    of the design nearest the log (or ``None``, with a warning, when none was measured
    near it).
Verdicts (the only four; :func:`_verdict`)
    ``adequate``
        no candidate has strong evidence and the moving residual is at the floor
        (RMS ≤ 1.3× ``step/√12``); a residual that is not white there is noted.
    ``missing_effect``
        the best candidate has strong evidence, no candidate of another family is within
        ``AMBIGUOUS_DBIC`` (10) of it — strong or not: the evidence for the best over it
        would not be very strong — and with it the moving residual is at the floor. At
        the floor a whiteness test with little power (a few lags at 250 Hz) does not
        overrule it: a non-white residual is noted and warned about, not turned into
        ``unexplained``. Candidates of one family (``ripple``/``kinematic_error``: a
        torque periodic in the WG angle) tying is noted with the separating experiment
        computed for the pair; where the BIC holds both fits at the floor, the χ²
        difference judged under the rounding alone decides which is named first
        (:mod:`hdid._diagnosis._rival`).
    ``ambiguous``
        the best candidate has strong evidence and candidates of other families are
        within ``AMBIGUOUS_DBIC`` of it (below the floor, the BIC gap plus the rounding's
        ``2·ln LR``: :mod:`hdid._diagnosis._rival`), or — where the best and a strong
        candidate of another family both bring the RMS residual to the floor — the
        likelihood alone (the BIC gap without its penalties) does not favour the best by
        ``AMBIGUOUS_DBIC`` (:func:`hdid._diagnosis._verdict._likelihood_gap`: penalties
        never choose between forms that both reach the floor): "ambiguous between A, B" —
        never a single confident name (a warning says when none of them brings the
        residual to the floor).
Separating experiments (``design=True``, ``Diagnosis.separating_experiments``)
    for an ``ambiguous`` verdict (the best against each rival) and a same-mark pair, the
    experiment that separates the two forms, *computed* by :mod:`hdid._design` from the
    two refits with its expected ``2·ln LR``, linearised and with the rival refitted, and
    whether the linearisation is credible (:mod:`hdid._diagnosis._separating`).
    ``unexplained``
        the residual is above the floor and either no candidate has strong evidence or
        the best leaves it above the floor (and ``steps`` > 1 did not reach it).
Warnings (:func:`_warnings`, ``Diagnosis.warnings``)
    what is known against trusting the verdict: no false-alarm rate measured near this
    design, or one whose one-sided 95 % upper bound is above the 5 % target; the current model's
    first optimum was a local one (its fits have several basins); a whiteness test with
    fewer than ``LOW_POWER_LAGS`` lags; the named effect leaves a residual that is not
    white or not at the floor; candidate refits that failed; a verdict naming no effect
    while the base leaves more than clean logs' fits do over the floor a correct model
    leaves on this log (:mod:`hdid._diagnosis._excess`: χ², that floor ``F`` and ``χ²/F``
    are reported, ``Diagnosis.rounding_floor``; the BIC's floor stays ``n − k``).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from typing import Any

import numpy as np

from ._candidates import (  # noqa: F401  (re-exported: tests, CLI)
    KINEMATIC_ORDERS,
    SCAN_GRID,
    SCAN_MAX_REFITS,
    SCAN_REFITS,
    SCAN_TIE_DCHI2,
    _at_optimum,
    _candidate_setups,
    _effect_of,
    _merge,
    _reorder,
    _scan_fits,
    _scan_note,
    _scan_refits,
    PERIODOGRAM_ORDERS,
    RIPPLE_ORDERS,
    SHAPE_RESET,
    Candidate,
    _kinematic_variants,
    _ripple_orders,
    _ripple_variants,
    _shape_is_unusual,
    _shape_reset,
    default_candidates,
)
from ._result import CandidateResult, Diagnosis  # noqa: F401
from ._verdict import (  # noqa: F401
    AMBIGUOUS_DBIC,
    LOW_POWER_LAGS,
    STRONG_DBIC,
    _features_text,
    _reason,
    _rivals,
    _verdict,
    _warnings,
)
from ._ladder import _chi2, _ladder_step, bic, bic_value, model_ladder  # noqa: F401
from ._excess import floor_check
from ._rival import rank_within_families
from ._wrong_step import readings_step
from ._refits import (  # noqa: F401 (re-exported)
    _base_starts, _cand_bic, _candidate_fits, _own_optimum, _record, sf_key)
from ._separating import MAX_SEPARATED_PAIRS, for_verdict as _separating_experiments  # noqa: F401

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


# -- the driver -----------------------------------------------------------------------


def diagnose(
    log,
    model=None,
    *,
    candidates: Iterable[str] | None = None,
    steps: int = 1,
    n_starts: int = 2,
    progress: Callable[[str], None] | None = None,
    design: bool = True,
    **fit_options,
) -> Diagnosis:
    """Fit ``model``, then rank the effects that could be missing from it.

    Parameters
    ----------
    log:
        A log (path, DataFrame or :class:`~hdid.Log`).
    model:
        The current model (default :meth:`Model.default`).
    candidates:
        Keys to try (default: every library candidate that applies to the model; see
        :func:`default_candidates`).
    steps:
        Forward-selection steps: after adding the best candidate, diagnose again from the
        improved model, at most this many times (the model ladder).
    n_starts:
        Data-driven grid starts per candidate refit, besides the warm starts from the
        current fit (the base model gets ``FULL_GRID_STARTS`` of them, more than any
        candidate, and a start from every candidate's optimum).
    progress:
        Called with a short message at each phase (e.g. ``print``).
    design:
        For an ``ambiguous`` verdict and a same-mark pair, compute the experiment that
        separates the two forms (:mod:`hdid._diagnosis._separating`, by
        :mod:`hdid._design`: ``Diagnosis.separating_experiments``). ``False`` skips it
        (its programs cost a compile per model structure on a cold store).
    **fit_options:
        Passed to :func:`hdid.fit` (``inertia``, ``fix``, ``counts_per_rev``, …).

    Returns
    -------
    Diagnosis
        ``verdict`` and its rules: see the module docstring.
    """
    from .._problems import _programs
    from .._fitting import _refit
    from .._log import Log, read_log
    from .._models._model import Model
    from .._results._residuals import residual_features, residual_frame, whiteness

    say, clock = _programs.phase_reporter(progress)
    if not isinstance(log, Log):
        log = read_log(log, counts_per_rev=fit_options.pop("counts_per_rev", None),
                       resolution=fit_options.pop("resolution", None))
    unknown_opts = set(fit_options) - set(_refit.SETUP_OPTIONS) - {"n_starts", "max_steps"}
    if unknown_opts:
        raise TypeError(f"diagnose: unknown option(s) {sorted(unknown_opts)}")
    fit_options = {k: v for k, v in fit_options.items() if k in _refit.SETUP_OPTIONS}
    model = Model.default() if model is None else model
    all_cands = {c.key: c for c in default_candidates()}
    if candidates is not None:
        wanted = list(candidates)
        unknown = [k for k in wanted if k not in all_cands]
        if unknown:
            raise KeyError(
                f"candidates: unknown {unknown}; choose from {sorted(all_cands)}"
            )
    else:
        wanted = list(all_cands)

    say(f"fitting the base model ({' + '.join(model.effect_names)})")
    base_setup = _refit.setup(log, model, fit_options)
    _refit.prefetch(base_setup)  # read while the grid's costs are computed
    base_grid = _refit.grid(base_setup, FULL_GRID_STARTS)
    current = _refit.run("base", base_setup, [("grid", u) for u in base_grid])
    if not current.finite:
        from .._errors import FitError

        raise FitError(
            f"{base_setup.prep.source}: every start diverged (non-finite residuals); check "
            "units (rad vs counts) and --inertia, or fix some parameters"
        )
    base_setup, base_grid, current, step_warning = readings_step(
        log, model, fit_options, base_setup, base_grid, current, say, FULL_GRID_STARTS)
    notes: list[str] = []
    local_base: list[tuple[float, float, str]] = []
    ladder: list[dict[str, Any]] = []
    rounds: list[dict[str, Any]] = []
    scans: dict[str, dict[str, float]] = {}
    refitted: dict[str, list[str]] = {}
    for step in range(max(1, steps)):
        base_result = current.result()
        white = whiteness(base_result)
        frame = residual_frame(base_result)
        feat = residual_features(frame)
        moving = frame.loc[frame["phase"] == "moving", "theta_wg"]
        swing = float(np.ptp(moving)) if len(moving) else math.inf
        hints = {"ripple_orders": _ripple_orders(frame), "swing_rad": swing}
        floor = base_result.quantization_floor_rad
        # Far from the floor, the current fit is no trustworthy warm start (e.g. a model
        # without static friction that never sticks): candidates get the full grid too.
        far = current.rms_rad() > FAR_FROM_FLOOR * floor
        n_grid = max(n_starts, FULL_GRID_STARTS) if far else n_starts
        p0 = base_setup.problem
        grid_points = [({k: float(v) for k, v in p0.unpack_np(u)[0].items()},
                        _refit.tail_of(p0, u)) for u in base_grid[:n_grid]]
        by_key: dict[str, list] = {}
        # every candidate's set-ups first, and their programs read from the store in the
        # background while the first candidates are refitted (_programs.prefetch)
        prepared: dict[str, Any] = {}
        for key in wanted:
            cand = all_cands[key]
            if not cand.applies(current.model):
                continue
            try:
                prepared[key] = _candidate_setups(log, cand, current, hints, fit_options)
            except Exception as exc:  # one candidate failing must not stop the others
                by_key[key] = exc
                continue
            for setup in prepared[key][1].values():
                _refit.prefetch(setup)
        for key, prep in prepared.items():
            try:
                by_key[key] = _candidate_fits(log, all_cands[key], current, hints, fit_options,
                                              grid_points, say, scans, refitted, prepared=prep)
            except Exception as exc:  # one candidate failing must not stop the others
                by_key[key] = exc
        # The current model gets every start a candidate got: from each candidate's
        # optimum with the effect removed, and from the catalog friction shape. A
        # candidate is credited only with what the current model cannot reach.
        # (each candidate's own optimum — its best refit — wherever it would be credited
        # with anything, ΔBIC < 0: a strong claim and its possible rivals alike; one start
        # each, ~0.1–0.5 s with one-lane programs)
        tried: set[int] = set()
        for basin in range(BASIN_PASSES):
            bic_now = bic_value(current.cost, current.n_effective, current.n_unknowns)
            cand_fits = sorted(
                (sf for sf in (_own_optimum(v) for v in by_key.values()) if sf is not None
                 and id(sf) not in tried
                 and _cand_bic(sf, all_cands[sf_key(by_key, sf)]) - bic_now < 0),
                key=lambda sf: sf.cost)
            tried.update(id(sf) for sf in cand_fits)
            values = current.values()
            reset = (_shape_reset(values) if basin == 0 and _shape_is_unusual(values)
                     else {})
            back = _base_starts(current.setup, current, cand_fits, reset)
            if not back:
                break
            say(f"  current model from {len(back)} candidate optima (effect removed)")
            again = _refit.run(current.label, current.setup, back)
            if not (again.finite and bic_value(again.cost, again.n_effective, again.n_unknowns)
                    < bic_now - BASE_IMPROVED_DBIC):
                current = _merge(current, again)
                current._result = base_result
                break
            best_origin = again.origins[again.best].split(":")[-1]
            local_base.append((current.cost, again.cost, best_origin))
            notes.append(
                f"the current model improved from a start at {best_origin}'s optimum (χ² "
                f"{current.cost:.1f} → {again.cost:.1f}): its first optimum was a local one, "
                "and no candidate is credited with the difference"
            )
            current = _merge(current, again)
            base_result = current.result()
            white = whiteness(base_result)
            frame = residual_frame(base_result)
            feat = residual_features(frame)
            if basin + 1 < BASIN_PASSES:
                # The candidates started from the first, local optimum: start them again
                # from the new one (warm starts only; the grid's are the same), so each is
                # at its own optimum next to the current model's, and the current model
                # gets a start from every new candidate optimum in the next pass.
                say("  candidates again from the current model's new optimum")
                for key in list(by_key):
                    if isinstance(by_key[key], Exception):
                        continue
                    try:
                        by_key[key] = by_key[key] + _candidate_fits(
                            log, all_cands[key], current, hints, fit_options, [], say, scans,
                            refitted)
                    except Exception:  # the first pass's refits stand
                        pass
        if step == 0:
            ladder.append(_ladder_step(" + ".join(current.model.effect_names), current, None))
            prep = base_setup.prep  # the floor a correct model leaves: reported (_excess)
            fcheck = floor_check(current, 1.0 / float(prep.sample_period), len(prep.lengths))
        results: list[CandidateResult] = []
        k_base = current.n_unknowns
        for key, fits in by_key.items():
            cand = all_cands[key]
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
        # same-family ties the BIC holds at the floor: the χ² difference decides (_rival)
        notes += rank_within_families(results, all_cands, STRONG_DBIC, AMBIGUOUS_DBIC)
        strong = [c for c in results if c.error is None and c.delta_bic < STRONG_DBIC]
        for c in strong[:MAX_ANALYSED]:
            c.result = c.fit.result()
            w = whiteness(c.result)
            c.white_after = bool(w.white)
            c.moving_ratio_after = float(w.rms_ratio)
            c.adequate_after = bool(w.at_floor)
        for c in results:
            c.reason = _reason(c, all_cands[c.key], feat, floor)
        rounds.append({"current": current, "results": results, "white": white,
                       "floor": floor, "result": base_result})
        best = strong[0] if strong else None
        if best is None:
            break
        ladder.append(_ladder_step(f"+ {best.label}", best.fit, all_cands[best.key]))
        if (best.adequate_after or step + 1 >= steps
                or _rivals(best, results, all_cands, floor)):
            break
        current = best.fit
        wanted = [k for k in wanted if k != best.key]

    first = rounds[0]
    verdict, summary, vnotes = _verdict(rounds, all_cands)
    notes += vnotes
    separating = _separating_experiments(verdict, rounds, all_cands, say) if design else []
    if separating and verdict == "ambiguous":
        summary += ". Separating experiment (computed): " + "; ".join(
            f"{x['forms'][0]} vs {x['forms'][1]}: {x['experiment']}, expected 2·ln LR "
            f"{x['expected_2lnlr']:.3g}" if "experiment" in x else x["text"]
            for x in separating)
    results = first["results"]
    if any(c.error for c in results):
        notes.append("some candidate fits failed: " + ", ".join(c.key for c in results if c.error))
    for key, table in scans.items():
        notes.append(_scan_note(key, table, refitted.get(key, [])))
    from ._rates import false_alarm

    fa = false_alarm(1.0 / float(prep.sample_period), len(prep.lengths))
    warns = ([step_warning] if step_warning else []) + _warnings(
        verdict, rounds, all_cands, local_base, fa)
    if fcheck is not None:
        warns += fcheck.warnings(verdict)
        notes += fcheck.notes()
    t = clock()
    say("done")
    return Diagnosis(
        source=first["result"].source,
        verdict=verdict,
        summary=summary,
        base=first["result"],
        candidates=results,
        whiteness_before=first["white"],
        notes=notes,
        ladder=ladder,
        floor_rad=first["floor"],
        timing=t,
        scanned={k: list(v) for k, v in scans.items()},
        refitted={k: list(v) for k, v in refitted.items()},
        warnings=warns,
        false_alarm=fa.to_dict() if fa is not None else None,
        rounding_floor=fcheck.to_dict() if fcheck is not None else None,
        separating_experiments=separating,
    )
