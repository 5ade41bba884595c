"""The experiment that would detect what this log cannot: for an ``adequate`` verdict, each
candidate effect is "not detectable in this design", and the experiment that would detect
it is computed by :mod:`hdid._design` from the candidate's refit and the base fit.

The candidate's refit (the base model plus the effect, at the size this log gives it) and
the base fit are the two hypotheses; the base is nested in the candidate. For each of
:func:`hdid.design`'s default candidate experiments (both fits' models:
:func:`hdid._diagnosis._separating.experiments_for`) the expected ``2·ln LR`` for the
effect is the noncentrality with the *candidate* as the truth and the base refitted to its
noise-free readings (:func:`hdid._design._separate.separations`, direction ``A`` true). The
other direction is no test of a nested pair: the larger model always fits the smaller
one's readings (its ``2·ln LR`` is ``≈ 0`` whatever the design), so the separation of
:mod:`._separating` (the smaller of the two directions) would rank nothing. The
experiment named is the one with the largest value whose linearisation the refit
confirms (within ``CREDIBLE_FACTOR``) and whose refit stopped, then the largest
confirmed one, then the largest refitted one — the order :mod:`._separating` uses — with
the log's own value beside it. An effect fitted at almost no size gives almost no
separation anywhere, and the line says that no default experiment reaches
``MIN_SEPARATION``: the log does not bound the effect's size from below, and no test
is named as if it could.

Each candidate costs its refit's analysis and the base's refit on every experiment
(seconds warm), so at most ``MAX_DETECTED`` are computed, best ΔBIC first.
"""

from __future__ import annotations

import math

#: Candidates of an ``adequate`` verdict a detecting experiment is computed for (best
#: ΔBIC first): each costs two simulations per refit step over the default experiments.
MAX_DETECTED = 3
#: The label of the nested hypothesis (the base fit) in a record's ``forms``.
BASE = "base model"


def undetected(verdict: str, rounds) -> list:
    """The candidates "not detectable in this design": for an ``adequate`` verdict, those
    refitted without error (best ΔBIC first); none otherwise."""
    if verdict != "adequate":
        return []
    return [c for c in rounds[0]["results"] if c.error is None and c.fit is not None]


def note(cands) -> str:
    """The notes' line naming the undetected candidates (and those whose detecting
    experiment is computed: the best ``MAX_DETECTED``)."""
    first = cands[:MAX_DETECTED]
    return ("not detectable in this design: " + ", ".join(
        f"{c.label} (ΔBIC {c.delta_bic:.1f})" for c in cands)
        + " — the experiment that would detect "
        + ("it" if len(cands) == 1 else "each" if len(first) == len(cands)
           else f"each of the first {len(first)}")
        + " at the size this log's refit gives it: separating_experiments")


def for_verdict(verdict: str, rounds, say) -> list[dict]:
    """:func:`detecting` for the best ``MAX_DETECTED`` of :func:`undetected`'s candidates
    against the base."""
    out = []
    base = rounds[0]["result"]
    for c in undetected(verdict, rounds)[:MAX_DETECTED]:
        say(f"  experiment that would detect {c.key} (hdid.design)")
        out.append(detecting(c, base))
    return out


def _a_true(s) -> float:
    """The candidate-true value: globally fitted where fitted, else refitted locally, else
    linearised."""
    best = getattr(s, "best", (math.nan,))[0]
    if math.isfinite(best):
        return float(best)
    ref = s.refitted[0]
    return float(ref) if math.isfinite(ref) else float(s.linear[0])


def _credible(s) -> bool:
    """The candidate-true linearisation within ``CREDIBLE_FACTOR`` of its refit (give or
    take one quantization variance), as :attr:`Separation.credible` asks of each
    direction."""
    from .._design._separate import CREDIBLE_FACTOR

    lin, ref = s.linear[0], s.refitted[0]
    return (math.isfinite(lin) and math.isfinite(ref)
            and ref <= CREDIBLE_FACTOR * lin + 1.0 and lin <= CREDIBLE_FACTOR * ref + 1.0)


def detecting(c, base) -> dict:
    """The experiment that detects candidate ``c`` (a
    :class:`~hdid._diagnosis._result.CandidateResult` with its refit) against the base fit
    ``base`` (a FitResult): a JSON-ready record like :func:`._separating.separating`'s,
    ``purpose`` ``"detect"``, ``text`` its report line."""
    from .._design._separate import separations
    from ._separating import ALTERNATIVES, MIN_SEPARATION, computed, experiments_for, unusable

    rec = {"forms": [c.key, BASE], "variants": [c.label, " + ".join(base.model.effect_names)],
           "purpose": "detect", "computed_by": "hdid.design"}
    def compute():
        fa = c.result if c.result is not None else c.fit.result()
        return separations(fa, base, experiments_for(fa, base))

    seps = computed(rec, c.key, "the experiment that would detect it", compute)
    if seps is None:
        return rec
    this, others = seps[0], [s for s in seps[1:] if math.isfinite(_a_true(s))]
    ranked = sorted(others, key=lambda s: (not (_credible(s) and s.converged[0]),
                                           not _credible(s), -_a_true(s)))
    rec["this_log_2lnlr"] = _a_true(this)
    if not ranked:
        return unusable(rec, c.key)
    top = ranked[0]
    rec.update(top.to_dict())
    value = _a_true(top)
    rec["expected_2lnlr"] = value
    rec["linearisation_credible"] = _credible(top)
    rec["reaches_min_separation"] = bool(value >= MIN_SEPARATION)
    rec["alternatives"] = [{"experiment": s.experiment.name, "expected_2lnlr": _a_true(s),
                            "linearisation_credible": _credible(s)}
                           for s in ranked[1:1 + ALTERNATIVES]]
    bound = log_bound(c, base)
    rec["this_log_bound"] = bound
    rec["consistent_with_log"] = consistent(rec["this_log_2lnlr"], bound)
    rec["text"] = _text(c, top, value, rec["this_log_2lnlr"], MIN_SEPARATION)
    if not rec["consistent_with_log"]:
        rec["text"] += (f"; NOT CREDIBLE: on this log's own design the computation gives "
                        f"{rec['this_log_2lnlr']:.3g}, where the two fits to the log bound "
                        f"it by {bound:.3g} — the design's simulation does not reproduce "
                        f"this log's fits with {c.key}, so no number here can be trusted")
    return rec


def log_bound(c, base) -> float:
    """What the two fits to the log allow on the log's own design: ``(√χ²_A + √χ²_B)²``.

    With ``y`` the log's readings and ``μ_A``, ``μ_B`` the candidate's and the base's
    fitted trajectories (``χ²`` in units of the quantization variance, the fits'
    weights), the triangle inequality gives ``|μ_A − μ_B| ≤ |μ_A − y| + |y − μ_B|``; the
    base started at its fit to the log and refitted to ``μ_A`` (or linearised there) can
    only lower its χ², so every value the computation gives for the log's own design is
    at most this."""
    from ._ladder import _chi2

    if c.fit is None or getattr(base, "starts", None) is None:
        return math.nan  # no refit or no analysed base fit: nothing to bound with
    chi2_a = float(c.fit.cost)
    return (math.sqrt(max(chi2_a, 0.0)) + math.sqrt(max(_chi2(base), 0.0))) ** 2


def consistent(this: float, bound: float) -> bool:
    """The log's own value within ``CREDIBLE_FACTOR`` of :func:`log_bound` (plus one
    quantization variance): the design's baseline only approximates the log (its runs'
    amplitudes and lengths read from the fit), so the bound is held loosely; beyond it
    the design's simulation of the candidate is not the fit's."""
    from .._design._separate import CREDIBLE_FACTOR

    if not (math.isfinite(this) and math.isfinite(bound)):
        return True  # nothing to compare (no value, or a loaded fit)
    return this <= CREDIBLE_FACTOR * bound + 1.0


def _text(c, s, value, this, min_separation) -> str:
    head = (f"to detect {c.key} (not detectable in this design): {s.experiment.name} "
            f"({s.experiment.describe()}), expected 2·ln LR {value:.3g} for it over the "
            f"base model if it is there at the size this log's refit gives it (this log: "
            f"{this:.2g}), computed by hdid.design from the two fits")
    if not s.converged[0]:
        head += " (the base's refit had not stopped: an upper bound)"
    if not _credible(s):
        head += ("; the linearised value is not credible here — treat the number as the "
                 "size, not the value, and confirm by simulation")
    if value < min_separation:
        head += (f"; no default candidate reaches 2·ln LR {min_separation:g}: at this size "
                 "the effect needs a longer campaign (several of them together), or is "
                 "too small to matter")
    return head
