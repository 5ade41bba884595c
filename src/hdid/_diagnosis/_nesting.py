"""Forms that contain another at a corner of their parameters: the nesting rule.

The soft wind-up (:class:`~hdid.effects.ThreeSegmentStiffness`, five parameters) with its
centre segment gone — ``K1 → 0`` with ``T1/K1 = b/2N`` — is a dead zone of total play
``b`` at the WG followed by a spring stiffening at a corner (``K2`` then ``K3``): the
free play (:class:`~hdid.effects.FreePlayStiffness`, ``backlash``: a dead zone then a
cubic spring, three parameters) up to the law of the stiffening. On a backlash log the
soft wind-up therefore reaches the floor too, at that corner, and the two were named
``ambiguous backlash | soft_windup`` on 10 of 10 simulated backlash logs (the
backlash–hysteresis experiment, ``benchmarks/results/design_check.md``); no experiment
separates them when backlash is true (the realised ``2·ln LR`` −1.7 ± 2.9 on 5 logs).

Rule (:func:`resolve`, used by the verdict): where both forms are among the contenders
(the best and the candidates it cannot be told from) and the richer one's optimum sits at
the corner that *is* the simpler form — the parameter that vanishes there is zero within
``CORNER_SD`` of its standard deviations — the richer form says nothing the simpler one
does not: it is dropped from the contenders and the simpler form (fewer parameters) is
named, with the corner in the summary and ``Diagnosis.nested``. A richer form away from
its corner (a real soft centre, ``K1`` many std from zero) stays a contender.

Where the richer form sits at its corner but the simpler one's refits ended higher (its
refits start near the base optimum), the simpler one is refitted from the corner mapped
back first (:func:`simple_values`; :func:`hdid._diagnosis._search.corner_restarts`), so
that the rule compares the two at their optima. The separation's rival fit starts the richer form at that corner from the simpler one's
fit (:func:`hdid._design._best_rival.corner_model`), and diagnose's soft wind-up refit
from the corner at free play's own starts (``effects/soft_windup.py``): the soft-centre
starts never reach it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

#: The vanishing parameter is "at zero" when within this many of its standard deviations
#: (a two-sided 95 % interval that includes the corner).
CORNER_SD = 2.0


@dataclass(frozen=True)
class Nesting:
    """``rich`` contains ``simple`` where its parameter ``zero`` vanishes."""

    rich: str
    simple: str
    zero: str
    what: str


#: The library's nested pairs (registry keys).
NESTINGS = (Nesting("soft_windup", "backlash", "K1",
                    "a dead zone then a stiffening spring: a free play"),)


def nesting_of(rich: str, simple: str) -> Nesting | None:
    return next((n for n in NESTINGS if n.rich == rich and n.simple == simple), None)


def simple_values(n: Nesting, rich: dict[str, float], ratio: float) -> dict[str, float]:
    """The simpler form's parameters at the richer one's corner (free play from the soft
    wind-up: the zone's total play ``2·N·T1/K1`` at the WG, ``k1`` the first slope past it,
    ``K2``; the cubic ``k2`` left at its own start)."""
    if (n.rich, n.simple) == ("soft_windup", "backlash") and rich.get("K1", 0.0) > 0:
        return {"backlash": 2.0 * ratio * rich["T1"] / rich["K1"], "k1": rich["K2"]}
    return {}


def at_corner(rich_result, simple_values: dict[str, float], n: Nesting) -> dict | None:
    """The record of a richer fit at its corner (``None`` where it is not): the vanishing
    parameter's value and std, and (free play) the zone's total play ``2·N·T1/K1`` beside
    the simpler fit's ``backlash``. An infinite std (undetermined) includes zero; a NaN one
    decides nothing."""
    p = getattr(rich_result, "parameters", {}).get(n.zero)
    if p is None:
        return None
    value, sd = float(p.value), float(p.std)
    if math.isnan(sd) or not abs(value) <= CORNER_SD * sd:
        return None
    rec = {"named": n.simple, "richer": n.rich, "parameter": n.zero, "value": value,
           "std": sd, "within_sd": CORNER_SD, "what": n.what}
    params = rich_result.parameters
    ratio = float(getattr(rich_result.model, "ratio", math.nan))
    if "T1" in params and value > 0:
        rec["play_rad"] = 2.0 * ratio * float(params["T1"].value) / value
        if "backlash" in simple_values:
            rec["simple_play_rad"] = float(simple_values["backlash"])
    return rec


def text(rec: dict) -> str:
    """One clause for the verdict's summary."""
    play = ""
    if "play_rad" in rec:
        play = f"; its dead zone {rec['play_rad']:.3g} rad at the WG"
        if "simple_play_rad" in rec:
            play += f" against {rec['named']}'s {rec['simple_play_rad']:.3g}"
    sd = f"{rec['std']:.3g}" if math.isfinite(rec["std"]) else "undetermined"
    return (f"{rec['richer']} reaches the floor only at its corner that is {rec['named']} "
            f"({rec['parameter']} {rec['value']:.3g} ± {sd}, zero within {rec['within_sd']:g} "
            f"std: {rec['what']}{play}), so the form with fewer parameters is named")


def corners(strong, analyse) -> list[dict]:
    """The nested pairs among the ``strong`` candidates whose richer form sits at its
    corner (:func:`at_corner`); ``analyse(c)`` gives a candidate's analysed fit (its
    covariance: the std), called only for a richer form whose simpler one is strong too."""
    by_key = {c.key: c for c in strong if c.error is None}
    out = []
    for n in NESTINGS:
        rich, simple = by_key.get(n.rich), by_key.get(n.simple)
        if rich is None or simple is None:
            continue
        rec = at_corner(analyse(rich), simple.values, n)
        if rec is not None:
            out.append(rec)
    return out


def resolve(best, rivals: list, nested: list[dict]):
    """``(best, rivals, applied)``: the contenders with every richer form at its corner
    dropped where its simpler form is a contender too (module docstring); the simpler
    form takes the richer one's place as the best. ``applied``: the records used."""
    contenders = [best, *rivals]
    keys = {c.key for c in contenders}
    applied = [r for r in nested if r["richer"] in keys and r["named"] in keys]
    drop = {r["richer"] for r in applied}
    kept = [c for c in contenders if c.key not in drop]
    if not applied or not kept:
        return best, rivals, []
    return kept[0], kept[1:], applied
