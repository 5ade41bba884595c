"""A fit with the readings' age (:class:`~hdid.effects.ReadingAge`): the device's clock is
scanned on a fit without it, then held while the physics is refitted (``hdid fit --add
reading_age``)."""

from __future__ import annotations

from ..effects import ReadingAge
from ..effects._age_scan import scan


def fit_with_age(log, model, *, fit=None, base=None, rounds: int = 1, periods=None,
                 **fit_options):
    """Fit ``model`` plus :class:`ReadingAge` to ``log``: a fit without it (or ``base``,
    such a fit already made), the scan for ``P`` and the phases on its residuals, a fit with
    the clock held; ``rounds`` > 1 scans again on that fit's residuals and refits (on
    STS3215 drop m0.535_l0.10 a second round moved P by 0.02 ms and the RMS from 23.24 to
    23.35× the floor: not worth a fit by default).
    ``periods`` [s]: the periods to try (one: a known ``P``; default the scan's grid).
    ``fit`` is :func:`hdid.fit` by default; ``fit_options`` go to it. Returns the last fit;
    its ``reading_age_scans`` attribute lists each scan (period, per-run periods, phases)."""
    if fit is None:
        from ._fit import fit
    plain = model.without("reading") if "reading" in model.effect_names else model
    result = base if base is not None else fit(log, plain, **fit_options)
    scans = []
    for _ in range(max(1, rounds)):
        found = scan(result.residuals(), floor=result.quantization_floor_rad,
                     current=result.model.reading, periods=periods)
        if found is None:
            raise ValueError("reading_age: no moving samples with a model velocity to find "
                             "the sampling clock from")
        scans.append(found)
        # the age moves the physics little: the last fit's optimum is one more start (on a
        # synthetic decay read through a 7 ms clock the Scales starts alone ended at 105× the
        # floor, k1 +2.5 %, in some processes; from the base optimum: 0.95×, k1 within 1e-5)
        own = plain.float_values()
        warm = plain.replace(**{n: e.value for n, e in result.parameters.items() if n in own})
        result = fit(log, warm.with_effect(ReadingAge.of_scan(found)),
                     **{**fit_options, "start_from_model": True})
    result.reading_age_scans = scans
    result.warnings.append(
        f"reading_age: the device's clock (P = {1e3 * scans[-1].period:.4g} ms, one phase per "
        "run) was found by a scan and held; the standard errors do not include its uncertainty")
    return result
