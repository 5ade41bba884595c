"""Which physical effect is missing? Refit with each candidate and rank by BIC.

``diagnose`` fits the current model, then adds each library effect the model lacks (or
swaps in a richer law for a base piece), refits, and ranks the candidates by the change
of the Bayesian information criterion.

The driver reads as the method, one function a step: the base fit (:func:`_base_fit`);
the ladder of candidates (:func:`_ladder_of_candidates`), each round refitting them,
giving the current model their optima and tabulating them (:mod:`hdid._diagnosis._search`),
with the rival test for forms the BIC holds at the floor (:mod:`hdid._diagnosis._rival`);
the verdict (:func:`_verdict`); the separating experiments
(:mod:`hdid._diagnosis._separating`); the assembly of the :class:`Diagnosis`
(:func:`_assemble`).

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
    optimum, and each also from every other candidate's optimum credited with anything
    against it (that effect removed, its own added: a candidate must not win by a basin
    of the shared parameters its own refits missed), and the current model again from
    their new optima (``BASIN_PASSES``). A candidate is credited only with what the
    current model cannot reach from there.
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
        residual to the floor). A richer form that reaches the floor only at the corner
        of its parameters that *is* a simpler contender (soft wind-up with no centre
        stiffness: a free play) is no rival of it: the simpler form, with fewer
        parameters, is named and the summary and ``Diagnosis.nested`` say so
        (:mod:`hdid._diagnosis._nesting`).
    ``unexplained``
        the residual is above the floor and either no candidate has strong evidence or
        the best leaves it above the floor (and ``steps`` > 1 did not reach it).
Separating experiments (``design=True``, ``Diagnosis.separating_experiments``)
    for an ``ambiguous`` verdict (the best against each rival) and a same-mark pair, the
    experiment that separates the two forms, *computed* by :mod:`hdid._design` from the
    two refits with its expected ``2·ln LR``, linearised and with the rival refitted, and
    whether the linearisation is credible (:mod:`hdid._diagnosis._separating`).
    For an ``adequate`` verdict every candidate is "not detectable in this design": the
    best ``MAX_DETECTED`` by ΔBIC get the experiment that would detect each at the size
    its refit gives it, the expected ``2·ln LR`` with the effect as the truth and the
    base refitted (:mod:`hdid._diagnosis._detecting`; ``purpose`` ``"detect"``).
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

from collections.abc import Callable, Iterable
from typing import Any

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
    nested_named,
)
from ._ladder import _chi2, _ladder_step, bic, bic_value, model_ladder  # noqa: F401
from ._excess import floor_check
from ._rival import rank_within_families
from ._wrong_step import readings_step
from ._refits import (  # noqa: F401 (re-exported)
    _base_starts, _cand_bic, _candidate_fits, _own_optimum, _record, sf_key)
from ._separating import MAX_SEPARATED_PAIRS, for_verdict as _separating_experiments  # noqa: F401
from . import _detecting, _nesting
from ._search import (  # noqa: F401 (re-exported: tests, calibration)
    BASE_IMPROVED_DBIC,
    BASIN_PASSES,
    FAR_FROM_FLOOR,
    FULL_GRID_STARTS,
    MAX_ANALYSED,
    Search,
    analyse,
    analyse_strong,
    candidate_table,
    corner_restarts,
    current_from_candidates,
    driver_refits,
    grid_points,
    hints_from,
    look_at,
    refit_candidates,
)


# -- the driver: the method's steps in order ------------------------------------------


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
        :mod:`hdid._design`: ``Diagnosis.separating_experiments``); for an ``adequate``
        one, the experiment that would detect each of the best ``MAX_DETECTED``
        candidates (:mod:`hdid._diagnosis._detecting`). ``False`` skips it (its programs
        cost a compile per model structure on a cold store).
    **fit_options:
        Passed to :func:`hdid.fit` (``inertia``, ``fix``, ``counts_per_rev``, …).

    Returns
    -------
    Diagnosis
        ``verdict`` and its rules: see the module docstring.
    """
    from .._problems import _programs

    say, clock = _programs.phase_reporter(progress)
    log, model, fit_options, all_cands, wanted = _inputs(log, model, candidates, fit_options)
    # 0. runs that move from their first samples: hdid.fit's story of their first readings
    from .._fitting._fit import first_reading_story

    log = first_reading_story(log, model, fit_options)
    # 1. the base fit (refitted with the readings' spacing where its step is wrong)
    search, current, step_warning = _base_fit(log, model, fit_options, all_cands, say)
    # 2-3. the ladder of candidates, each round judged by the rival test; the rounding
    #      floor measured on the first round's settled base
    rounds, ladder, fcheck = _ladder_of_candidates(search, current, wanted, steps, n_starts)
    # 4. the verdict
    verdict, summary, vnotes = _verdict(rounds, all_cands)
    search.notes += vnotes
    # 5. the experiment that would separate (or detect) what this log cannot
    separating = _experiments(verdict, rounds, all_cands, say, search.notes) if design else []
    summary += _separating_summary(verdict, separating)
    # 6. the assembly: notes, warnings, the measured false-alarm rate
    return _assemble(search, rounds, ladder, fcheck, verdict, summary, separating,
                     step_warning, clock)


def _inputs(log, model, candidates, fit_options):
    """The log read (its encoder options taken from ``fit_options``), the fit options
    checked (a ``TypeError`` naming any unknown one; only the set-up's are kept), the
    model (default :meth:`Model.default`) and the candidates to try (a ``KeyError``
    naming unknown keys). Returns ``(log, model, fit_options, all_cands, wanted)``."""
    from .._fitting import _refit
    from .._log import Log, read_log
    from .._models._model import Model

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
    return log, model, fit_options, all_cands, wanted


def _base_fit(log, model, fit_options, all_cands, say):
    """The current model fitted from ``FULL_GRID_STARTS`` data-driven grid starts (more
    than any candidate gets: the base must not lose by having fewer starts). A fit whose
    every start diverged is a ``FitError`` naming the usual causes. A base far above its
    step's floor but at the readings' own spacing was given a wrong step and is refitted
    with the spacing (:func:`hdid._diagnosis._wrong_step.readings_step`, a warning).
    Returns the :class:`Search` the rounds share, the base fit and the warning."""
    from .._fitting import _refit

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
    search = Search(log, fit_options, all_cands, say, base_setup, base_grid)
    return search, current, step_warning


def _ladder_of_candidates(s: Search, current, wanted, steps, n_starts):
    """The rounds of the search (:mod:`hdid._diagnosis._search`): each refits the
    candidates from the current fit, gives the current model their optima, tabulates
    them, ranks forms of one family that the BIC holds at the floor by their χ² under
    the rounding (the rival test, :func:`~hdid._diagnosis._rival.rank_within_families`)
    and analyses the strong best. With ``steps`` > 1 the best is added and the next round
    starts from it, until it reaches the floor, has rivals, or the steps run out (the
    model ladder). The rounding floor a correct model leaves on the log
    (:func:`~hdid._diagnosis._excess.floor_check`) is measured on the first round's
    settled base: reported, never used by the rules. Returns ``(rounds, ladder, fcheck)``."""
    ladder: list[dict[str, Any]] = []
    rounds: list[dict[str, Any]] = []
    fcheck = None
    for step in range(max(1, steps)):
        look = look_at(current)
        hints = hints_from(look.frame)
        floor = look.result.quantization_floor_rad
        points = grid_points(s, current, floor, n_starts)
        by_key = refit_candidates(s, current, wanted, hints, points)
        current, look = current_from_candidates(s, current, look, by_key, hints)
        if step == 0:
            ladder.append(_ladder_step(" + ".join(current.model.effect_names), current, None))
            prep = s.base_setup.prep
            fcheck = floor_check(current, 1.0 / float(prep.sample_period), len(prep.lengths))
        results = candidate_table(s, by_key, current, fcheck)
        results = driver_refits(s, by_key, results, current, fcheck, floor, STRONG_DBIC)
        results = corner_restarts(s, by_key, results, current, fcheck, STRONG_DBIC)
        s.notes += rank_within_families(results, s.all_cands, STRONG_DBIC, AMBIGUOUS_DBIC)
        strong = analyse_strong(results, STRONG_DBIC)
        # a richer form at the corner that is a simpler strong one (the nesting rule):
        # the richer one's std, and the simpler one analysed as the best would be
        nested = _nesting.corners(strong, analyse)
        for rec in nested:
            analyse(next(c for c in strong if c.key == rec["named"]))
        for c in results:
            c.reason = _reason(c, s.all_cands[c.key], look.features, floor)
        rounds.append({"current": current, "results": results, "white": look.white,
                       "floor": floor, "result": look.result, "nested": nested})
        best = strong[0] if strong else None
        if best is None:
            break
        ladder.append(_ladder_step(f"+ {best.label}", best.fit, s.all_cands[best.key]))
        if (best.adequate_after or step + 1 >= steps
                or _rivals(best, results, s.all_cands, floor)):
            break
        current = best.fit
        wanted = [k for k in wanted if k != best.key]
    return rounds, ladder, fcheck


def _experiments(verdict, rounds, all_cands, say, notes) -> list[dict]:
    """The experiments this log calls for, computed by :mod:`hdid._design` from the
    refits: for an ``ambiguous`` verdict the one separating the best from each rival, for
    a same-mark pair the one separating the two forms (:mod:`hdid._diagnosis._separating`);
    for an ``adequate`` verdict the one that would detect each candidate — not detectable
    in this design — at the size this log's refit gives it, against the base
    (:mod:`hdid._diagnosis._detecting`; a note names them)."""
    out = _separating_experiments(verdict, rounds, all_cands, say)
    undetected = _detecting.undetected(verdict, rounds)
    if undetected:
        notes.append(_detecting.note(undetected))
        out += _detecting.for_verdict(verdict, rounds, say)
    return out


def _separating_summary(verdict, separating) -> str:
    """An ``ambiguous`` verdict's summary names the computed separating experiments (the
    same-mark pair of a named effect is in the notes and the report's section)."""
    if not (separating and verdict == "ambiguous"):
        return ""
    return ". Separating experiment (computed): " + "; ".join(
        f"{x['forms'][0]} vs {' and '.join(x['forms'][1:])}: {x['experiment']}, expected 2·ln LR "
        f"{x['expected_2lnlr']:.3g}" + (" (the smallest over the rivals)" if x.get("against") else "")
        if "experiment" in x else x["text"]
        for x in separating)


def _assemble(s: Search, rounds, ladder, fcheck, verdict, summary, separating,
              step_warning, clock) -> Diagnosis:
    """The :class:`Diagnosis` of the first round: its candidates, the notes (failed
    refits, the scans, the rounding floor), the warnings (a wrong step, the rules'
    measured false-alarm rate for the nearest design, what else is known against the
    verdict) and the timing."""
    from ._rates import false_alarm

    first = rounds[0]
    results = first["results"]
    notes = s.notes
    if any(c.error for c in results):
        notes.append("some candidate fits failed: " + ", ".join(c.key for c in results if c.error))
    for key, table in s.scans.items():
        notes.append(_scan_note(key, table, s.refitted.get(key, [])))
    prep = s.base_setup.prep
    fa = false_alarm(1.0 / float(prep.sample_period), len(prep.lengths))
    warns = ([step_warning] if step_warning else []) + _warnings(
        verdict, rounds, s.all_cands, s.local_base, fa)
    if fcheck is not None:
        warns += fcheck.warnings(verdict)
        notes += fcheck.notes()
    t = clock()
    s.say("done")
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
        scanned={k: list(v) for k, v in s.scans.items()},
        refitted={k: list(v) for k, v in s.refitted.items()},
        warnings=warns,
        false_alarm=fa.to_dict() if fa is not None else None,
        rounding_floor=fcheck.to_dict() if fcheck is not None else None,
        separating_experiments=separating,
        nested=nested_named(rounds, s.all_cands),
    )
