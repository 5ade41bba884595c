"""A fit with the readings' age (:class:`~hdid.effects.ReadingAge`): the device's clock is
scanned on a fit without it, then held while the physics is refitted (``hdid fit --add
reading_age``)."""

from __future__ import annotations

from ..effects import ReadingAge
from ..effects._age_scan import scan


#: Clocks refitted: the scan's best and the best outside ±``ALIAS_GAP`` of it (an alias of
#: the best against the host's rate makes the same sawtooth up to its height, which a
#: first-order scan may misjudge); the fit with the lower cost is kept.
CLOCKS = 2
ALIAS_GAP = 0.05


def fit_with_age(log, model, *, fit=None, base=None, rounds: int = 1, periods=None,
                 clocks: int = CLOCKS, **fit_options):
    """Fit ``model`` plus :class:`ReadingAge` to ``log``: a fit without it (or ``base``,
    such a fit already made), the scan for ``P`` and the phases on its residuals, a fit with
    the clock held; ``rounds`` > 1 scans again on that fit's residuals and refits (on
    STS3215 drop m0.535_l0.10 a second round moved P by 0.02 ms and the RMS from 23.24 to
    23.35× the floor: not worth a fit by default).
    ``periods`` [s]: the periods to try (one: a known ``P``; default the scan's grid);
    ``clocks``: how many distinct clocks of the scan to refit (the lowest cost is kept).
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
        tried = [found]
        if clocks > 1 and (periods is None or len(periods) > 1):
            gap = (found.period * (1 - ALIAS_GAP), found.period * (1 + ALIAS_GAP))
            other = scan(result.residuals(), floor=result.quantization_floor_rad,
                         current=result.model.reading, periods=periods, exclude=gap)
            tried += [other] if other is not None else []
        # the age moves the physics little: the last fit's optimum is one more start (on a
        # synthetic decay read through a 7 ms clock the Scales starts alone ended at 105× the
        # floor, k1 +2.5 %, in some processes; from the base optimum: 0.95×, k1 within 1e-5)
        own = plain.float_values()
        warm = plain.replace(**{n: e.value for n, e in result.parameters.items() if n in own})
        fits = [fit(log, warm.with_effect(ReadingAge.of_scan(f)),
                    **{**fit_options, "start_from_model": True}) for f in tried]
        best = min(range(len(fits)), key=lambda i: fits[i].rms_residual_rad)
        for i, f in enumerate(tried):
            f.refit_rms_rad = float(fits[i].rms_residual_rad)
        scans.append(tried[best])
        scans[-1].rivals = [f for i, f in enumerate(tried) if i != best]
        result = fits[best]
    result.reading_age_scans = scans
    rival = "".join(f"; the runner-up clock, P = {1e3 * r.period:.4g} ms, left "
                    f"{r.refit_rms_rad / result.quantization_floor_rad:.3g}× the floor against "
                    f"{result.rms_residual_rad / result.quantization_floor_rad:.3g}×"
                    for r in scans[-1].rivals)
    result.warnings.append(
        f"reading_age: the device's clock (P = {1e3 * scans[-1].period:.4g} ms, one phase per "
        "run) was found by a scan and held; the standard errors do not include its uncertainty"
        + rival)
    return result
