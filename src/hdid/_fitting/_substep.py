"""The RK4 substep of a fit: picked from the log, checked against the fitted swing.

:func:`hdid.fit` simulates every run with RK4 at a fixed longest substep ``h``. It picks
``h`` before fitting, from the log's own oscillation frequency, its turning points
(:func:`substep_for`: ``h·ω ≲ 0.26``). A log sampled below twice its swing shows the
swing's slow alias there, so ``h`` is picked for the alias: a stiff gear on the paper
design (a 222 Hz swing read at 250 Hz, its turning points at 29.5 Hz) ran at 1 ms,
``h·ω`` = 1.4, where RK4's phase error over the ring-down puts the simulation at the truth
4.8 encoder steps off the reference simulator. No optimum of that discretised model
describes the log (SBC paper seed 36016: 3.3× the floor; the truth, its nuisances refitted,
34×), and nothing downstream of the fit could tell the integrator's error from a poorer
basin.

So the fitted swing is asked again once the fit is done (:func:`substep_wanted`: its
natural frequency hardened at the log's largest release), and a fit whose substep clearly
under-resolves it is refitted at the substep that swing asks for (:func:`refined`, at most
:data:`MAX_REFITS` times); the lower χ² is kept and the warnings say so. The posterior's
basin check (:mod:`hdid._posterior.basin`) asks the same rule.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from .._simulation._aliasing import swing_hz
from .._simulation._phase_error import BIAS_SHARE, frequency_bias, substep_for_error
from .._simulation._simulate import DEFAULT_MAX_SUBSTEP, substeps_for

#: Natural frequency [Hz] at which the default substep (``DEFAULT_MAX_SUBSTEP``) was
#: validated against the event-driven reference (error 0.04 of the 250 Hz quantization
#: floor); other logs scale the substep by powers of two to keep ``h·ω_n`` about the same.
SUBSTEP_REFERENCE_HZ = 60.0

#: ``h·ω`` (substep × the fitted swing's angular frequency) beyond which a fit's substep
#: clearly under-resolves its swing: twice the centre of :func:`substep_for`'s rule
#: (2π·60 Hz·0.5 ms = 0.19, its octaves spanning 0.13–0.27), half an octave past the rule's
#: edge, where RK4's error per unit time (∝ (h·ω)⁴) is 4× the rule's worst; a log near an
#: octave's edge (its fitted swing a little off its turning points, e.g. hardened at the
#: largest release) is not refitted for nothing.
AT_FLOOR_HW = 0.377

#: Refits :func:`refined` runs at most: on an aliased log a refit may settle on a faster
#: alias, whose swing asks for a finer substep again (SBC seed 36008: 0.5 → 0.25 ms ended
#: at k1 11.9× the truth, asking for 0.0625 ms).
MAX_REFITS = 2
#: Δχ² [floor units] above which a refit for the RK4 phase error alone is taken for
#: another basin and not kept (a 3 sd shift of one parameter): HV log21's refit at 0.209 ms
#: ended 4.7 above the 1 ms fit, which carries k1 +24 ppm at 25 sd of bias.
PRECISION_CHI2 = 9.0


def substep_for(frequency_hz: float) -> float:
    """Longest RK4 substep [s] for a log whose oscillation frequency is ``frequency_hz``:
    ``DEFAULT_MAX_SUBSTEP`` at ``SUBSTEP_REFERENCE_HZ``, halved per octave above (so
    ``h·ω_n`` stays ≲ 0.26), doubled per octave below; powers of two, so logs of similar
    gears share compiled programs."""
    if not (math.isfinite(frequency_hz) and frequency_hz > 0):
        return DEFAULT_MAX_SUBSTEP
    octaves = math.floor(math.log2(frequency_hz / SUBSTEP_REFERENCE_HZ) + 0.5)
    return DEFAULT_MAX_SUBSTEP * 2.0 ** (-octaves)


def fitted_swing_hz(fit) -> float:
    """The fit's swing [Hz]: its natural frequency hardened at the log's largest release
    (:func:`~hdid._simulation._aliasing.swing_hz`; each run's hold reading against its
    last weighted one, its rest, as the fit's aliasing warning measures it); NaN when the
    fit has no problem or no finite natural frequency."""
    prob = getattr(fit, "problem", None)
    f0 = (getattr(fit, "derived", None) or {}).get("natural_frequency_hz", (math.nan,))[0]
    if prob is None or not (math.isfinite(f0) and f0 > 0):
        return math.nan
    theta, weight = np.asarray(prob.theta, dtype=float), np.asarray(prob.weight, dtype=float)
    hold = np.asarray(prob.hold, dtype=float)
    amp = [abs(float(h0 - th[np.flatnonzero(w > 0)[-1]]))
           for h0, th, w in zip(hold, theta, weight) if np.any(w > 0)]
    values = {n: float(p.value) for n, p in fit.parameters.items()}
    ratio = float(getattr(fit.model, "ratio", 1.0) or 1.0)
    return float(swing_hz(float(f0), values, max(amp, default=0.0) / ratio))


def substep_wanted(fit, at_floor: bool = False) -> float | None:
    """The longest RK4 substep [s] that :func:`substep_for` gives for the fit's fitted
    swing (:func:`fitted_swing_hz`) when that is finer than the substep the fit ran at
    (``at_floor``: and that substep's ``h·ω`` above :data:`AT_FLOOR_HW`); ``None``
    otherwise (or when the frequency is not known)."""
    f = fitted_swing_hz(fit)
    if not math.isfinite(f):
        return None
    h, h_fit = substep_for(f), float(fit.problem.max_substep)
    if at_floor and h_fit * 2.0 * math.pi * f <= AT_FLOOR_HW:
        return for_precision(fit, f)
    return h if h < h_fit * (1.0 - 1e-9) else None


def for_precision(fit, f: float) -> float | None:
    """A finer substep where the fit's own leaves an RK4 phase error of more than
    :data:`~hdid._simulation._phase_error.BIAS_SHARE` of its fitted frequency's standard
    error (a fine encoder measures the frequency to ppm: world logs 04/05/11/14, k1 +9 …
    +48 ppm at 4–10 sd, the (h·ω)⁴/60 of each fit's substep): the longest power-of-two
    division that brings it to :data:`~hdid._simulation._phase_error.TARGET_SHARE`
    (:mod:`hdid._simulation._phase_error`); ``None`` where the bias is within it. ``f``:
    the fitted swing [Hz]."""
    f0, sd = (getattr(fit, "derived", None) or {}).get("natural_frequency_hz", (math.nan,) * 2)
    dt = float(getattr(fit, "sample_period", math.nan))
    if not (math.isfinite(sd) and sd > 0 and f0 > 0 and dt > 0):
        return None
    run = dt / substeps_for(dt, float(fit.problem.max_substep))  # the substep run
    if frequency_bias(run, f) <= BIAS_SHARE * sd / f0:
        return None
    return substep_for_error(run, f, sd / f0)


def _chi2(result) -> float:
    """The data's weighted sum of squares [rad²] (RMS² × the effective readings): the same
    readings and weights at any substep, so fits at two substeps compare by it."""
    rms = float(result.rms_residual_rad)
    return rms**2 * float(result.n_effective) if math.isfinite(rms) else math.inf


def _why(fit, h: float, f: float) -> str:
    """What made the substep ``h`` [s] needed for the fit's swing ``f`` [Hz]."""
    old = float(fit.problem.max_substep)
    nyquist = 0.5 / float(fit.sample_period)
    if old * 2.0 * math.pi * f <= AT_FLOOR_HW:  # resolved: its phase error against the std
        return (f"the RK4 phase error at {1e3 * old:.4g} ms (h·ω {old * 2 * math.pi * f:.2g} "
                f"at the fitted {f:.4g} Hz swing) biased its frequency by more than "
                f"{BIAS_SHARE:g} of its standard error; at {1e3 * h:.4g} ms it is within it")
    where = (f"above the log's Nyquist frequency ({nyquist:.4g} Hz), so its turning points "
             "show a slower alias, for which the substep was picked" if f > nyquist else
             "faster than the log's turning points, from which the substep was picked")
    return (f"the fitted {f:.4g} Hz swing is {where} ({1e3 * old:.4g} ms, h·ω "
            f"{old * 2 * math.pi * f:.2g}; the rule wants {1e3 * h:.4g} ms, h·ω ≲ 0.26)")


def refined(result, log, given: dict, fit):
    """``result`` of ``fit(log, **given)`` (:func:`hdid.fit`), refitted at the substep its
    fitted swing wants (:func:`substep_wanted` with ``at_floor``: only where its substep
    clearly under-resolves that swing, ``h·ω`` above :data:`AT_FLOOR_HW`; a non-aliased
    log's fit at the substep of its turning points stays as it is) when the fit picked its
    substep itself (``given["max_substep"]`` None: a substep the caller gave stands). The
    refit is ``fit`` with the fitted model as a warm start (``start_from_model``: its
    optimum's parameters; its own grid, limit checks and restarts, the fold-back restart
    of an aliased optimum among them) at that substep; the lower χ² is kept and its
    warnings say which substep ran and why. At most :data:`MAX_REFITS` times. A result
    still above the floor whose fold-back restart replaced a fast optimum (:func:`_unfolded`)
    has that optimum refitted the same way, warm from its model."""
    if given.get("max_substep") is not None:
        return result
    notes: list[str] = []
    for _ in range(MAX_REFITS):
        src, h = result, substep_wanted(result, at_floor=True)
        if h is None and (u := _unfolded(result)) is not None:
            src, h = u, substep_wanted(u, at_floor=True)
        if h is None:
            break
        f, old = fitted_swing_hz(src), float(src.problem.max_substep)
        held = tuple(getattr(result, "first_reading_held", ()) or ())
        on = dataclasses.replace(log, first_reading_held=held) if held else log
        new = fit(on, **{**given, "model": src.model, "max_substep": h,
                         "start_from_model": True})
        a, b = _chi2(result), _chi2(new)
        floor2 = float(new.quantization_floor_rad) ** 2 or 1.0
        why = _why(src, h, f) + (" (the optimum its fold-back restart replaced)"
                                 if src is not result else "")
        # a refit for the phase error alone (:func:`for_precision`) is the same model
        # simulated more closely: kept unless it ends PRECISION_CHI2 higher (another basin)
        precise = old * 2.0 * math.pi * f <= AT_FLOOR_HW
        if b < a or (precise and (b - a) / floor2 < PRECISION_CHI2):
            notes.append(f"refitted at the {1e3 * h:.4g} ms RK4 substep: {why}; "
                         f"χ² {a / floor2:.4g} → {b / floor2:.4g} (quantization-floor units)")
            result = new
            continue
        notes.append(f"a refit at the {1e3 * h:.4g} ms RK4 substep ended higher (χ² "
                     f"{b / floor2:.4g} against {a / floor2:.4g} in quantization-floor units) "
                     f"and the fit at {1e3 * old:.4g} ms is kept, though {why}: "
                     "its simulation may be off the dynamics it models (log faster than "
                     "twice the swing)")
        break
    result.__dict__.pop("unfolded", None)
    result.warnings += [n for n in notes if n not in result.warnings]
    return result


def _unfolded(result):
    """The optimum a fold-back restart replaced in ``result``
    (:func:`hdid._fitting._cubic_restart.restarted`: a swing above the log's Nyquist
    frequency folded to the alias nearest the log's own), where ``result`` has not reached
    the quantization floor: that optimum was judged at the substep of the slow swing,
    which may have cost it the integrator's error alone (a 222 Hz gear read at 250 Hz,
    fitted at 1 ms: its folded 31 Hz restart won at 91× the floor, the 222 Hz swing refitted
    at 0.125 ms reaches it). At the floor the folded swing describes the log and stays."""
    from ._limits import reached_floor

    u = getattr(result, "unfolded", None)
    return None if u is None or reached_floor(result) else u
