"""``hdid.design``: which experiment would determine what this log cannot."""

from __future__ import annotations

import math
import os
import time

from .._config import float64
from .._errors import HdidError
from . import _candidates, _fisher, _linearity, _rank
from ._candidates import Experiment
from ._result import DesignResult

#: ``separate``'s global rival fits (best first, until the largest separation is a value;
#: :func:`hdid._design._separate.separations`' ``certify``).
RIVAL_FITS = 3


@float64
def design(
    fit,
    candidates=None,
    *,
    targets=None,
    criterion: str | None = None,
    check: int = 0,
    check_candidate: str | None = None,
    seed: int = 0,
    separate=None,
    rival_fits: int = RIVAL_FITS,
    **fit_options,
) -> DesignResult:
    """Rank candidate experiments by the standard errors they would give at the current fit.

    Parameters
    ----------
    fit:
        A :class:`~hdid.FitResult` (also one read with :meth:`hdid.FitResult.load`), the
        path of a fit JSON (``hdid fit --json``), or a log (path, DataFrame or
        :class:`~hdid.Log`), which is fitted first (``fit_options`` go to
        :func:`hdid.fit`).
    candidates:
        Experiments to compare with the log's own design: :class:`Experiment` objects or
        mappings of what differs from the log (``{"name": "fast", "rate": 1000}``), or the
        path of a TOML/JSON file of them. Default: the log's design varied one knob at a
        time (:func:`hdid._design._candidates.default_candidates`).
    targets:
        Quantities whose std decides the ranking: parameter names or derived quantities
        (``band`` = stick-band half-width, ``frequency`` = natural frequency); a list or
        ``"tau_c,band"``.
    criterion:
        ``"targets"`` (default when targets are given) or ``"d"`` (D-optimality on the
        free parameters; the default otherwise).
    check:
        Simulate this many logs of the top candidate (or ``check_candidate``, a name) at
        the current fit, fit them and set their spread beside the prediction.
    seed:
        Seed of the check's simulated logs.
    separate:
        Two fits of the same log by rival models (FitResults or fit JSON paths, e.g. two
        diagnose candidates): each candidate also gets the expected ``2·ln LR`` that
        tells them apart, both directions, computed as :func:`hdid.diagnose` computes its
        separating experiments (:mod:`hdid._design._separate`): linearised, then with the
        rival refitted locally on the exact simulator (an upper bound), and the largest
        then with the rival fitted globally by :func:`hdid.fit` (a value); and
        ``criterion="separate"`` (the default then) ranks by the smaller of the two.
    rival_fits:
        With ``separate``: at most this many experiments' rivals fitted globally, the
        largest separation first, until the largest is a value (each costs two
        :func:`hdid.fit` calls on a log of that design); 0 keeps the local upper bounds.
        The values rank above every upper bound (a bound is only an "at most"); where
        the fits run out with a bound above the top value, ``warnings`` says so.

    The prediction is the linearised Fisher information of the exact simulator with the
    nuisances (release instants, start angles, set-up offsets) estimated alongside and the
    encoder's rounding as the noise (:mod:`hdid._design._fisher`); where that
    linearisation is not honest for a candidate, its ``honesty`` lines say why
    (:mod:`hdid._design._linearity`).
    """
    t0 = time.perf_counter()
    result = _as_fit(fit, fit_options)
    base = _candidates.baseline(result)
    if candidates is None:
        cands = _candidates.default_candidates(base, result.model)
    else:
        cands = [base, *_candidates.load_candidates(candidates, base)]
    free, every = _fisher.parameter_names(result)
    derived_names = list(result.derived)
    targets = _rank.resolve_targets(targets, every, derived_names)
    pair = None
    if separate is not None:
        if len(separate) != 2:
            raise HdidError("separate: give two fits of the same log by the rival models")
        pair = [_as_fit(f, {}) for f in separate]
    criterion = criterion or ("separate" if pair else "targets" if targets else "d")
    if criterion == "separate" and pair is None:
        raise HdidError("criterion 'separate' needs separate=(fit_a, fit_b) (--separate A.json,B.json)")
    if criterion == "targets" and not targets:
        raise HdidError("criterion 'targets' needs targets (e.g. targets='tau_c,band')")
    preds, derived = _fisher.predict(result, cands)
    _linearity.check(result, preds, every)
    if pair is not None:
        from ._separate import separations

        for p, sep in zip(preds, separations(pair[0], pair[1], cands, certify=rival_fits)):
            lam = sep.best if sep.fitted else sep.refitted
            p.separation, p.separation_kind = (
                (lam, "rival fitted globally" if sep.fitted else "upper bound")
                if all(math.isfinite(x) for x in lam) else (sep.linear, "linearised"))
    ranking = _rank.rank(preds, criterion, targets)
    values = {n: result.model.float_values()[n] for n in every}
    out = DesignResult(
        source=str(result.source), criterion=criterion, targets=targets, values=values,
        derived=derived, predictions=preds, ranking=ranking,
        noise_rad=_fisher.extra_noise(result), warnings=_warnings(result, preds))
    if criterion == "separate":
        out.warnings += _rank.separation_warnings(preds, rival_fits)
    if check:
        out.check = _check_one(result, out, check, check_candidate, seed)
    out.wall_time_s = time.perf_counter() - t0
    return out


def _as_fit(fit, fit_options):
    from .._results._result import FitResult

    if isinstance(fit, FitResult):
        if fit_options:
            raise HdidError(f"design: {', '.join(fit_options)} apply only when a log is fitted "
                            "first; the fit is given")
        return fit
    if isinstance(fit, (str, os.PathLike)) and str(fit).lower().endswith(".json"):
        if not os.path.isfile(fit):
            raise HdidError(f"{fit}: no such fit JSON (write one with hdid fit LOG --json FIT.json)")
        try:
            return FitResult.load(fit)
        except (KeyError, TypeError, ValueError) as exc:
            raise HdidError(f"{fit}: not a fit JSON of hdid ({exc}); give hdid fit's --json "
                            "output or the log itself") from None
    if type(fit).__name__.endswith("FitResult"):  # a driven fit
        raise HdidError("design: this is a driven fit; hdid design plans free-motion release "
                        "tests (give the fit of a free-motion log)")
    from .._fitting._fit import fit as fit_log

    return fit_log(fit, **fit_options)


def _warnings(fit, preds) -> list[str]:
    out = []
    if math.isfinite(fit.rms_residual_rad) and fit.resolution_known:
        floor = fit.resolution_rad / math.sqrt(12.0)
        if fit.rms_residual_rad > 3.0 * floor:
            out.append(f"the fit's residual is {fit.rms_residual_rad / floor:.2g}x the "
                       "quantization floor: the model does not describe the log, and designs "
                       "planned at this fit inherit that (diagnose it first: hdid diagnose)")
    if not fit.resolution_known:
        out.append("the log's readings lie on no encoder grid: 'encoder' candidates change the "
                   "noise level (step/sqrt 12) rather than a rounding")
    problem = getattr(fit, "problem", None)
    if problem is not None and getattr(problem, "n_moving", 0):
        out.append("runs of this log start in motion (no hold): every design here releases "
                   "its runs from rest at their start angle")
    bad = [p.experiment.name for p in preds if p.error]
    if bad:
        out.append("not evaluated: " + ", ".join(bad))
    return out


def _check_one(fit, out: DesignResult, n: int, name: str | None, seed: int):
    from . import _check

    if name is None:
        p = out.best
    else:
        found = [p for p in out.predictions if p.experiment.name == name]
        if not found:
            raise HdidError(f"check: no candidate named {name!r}; choose from "
                            + ", ".join(repr(p.experiment.name) for p in out.predictions))
        p = found[0]
    names = [*p.names, "stick_band_halfwidth_rad"]
    predicted = {k: _rank.std_of(p, k) for k in names}
    return _check.run(fit, p.experiment, predicted, int(n), seed=seed, names=tuple(names))


__all__ = ["design", "DesignResult", "Experiment"]
