"""A general friction law against its nested special case: Stribeck ⊃ Coulomb.

Stribeck friction with ``tau_s = tau_c`` is Coulomb friction (any ``v_s``, ``delta``), so
the least-squares optimum of a model with a free Stribeck law can never be worse than the
same model with Coulomb friction. A multi-start fit can still end there (the Stribeck
shape adds a curved ridge and a ``v_s → 0`` corner to the cost); this module checks the
claim on the log in hand: it fits the nested case, restarts the general law from the
nested optimum when the general fit ended worse, and warns when even that restart stays
worse (the driven fit does the same, Coulomb first, in :mod:`hdid._fitting._driven_fit`).

The check costs a second model structure (on a cold start ~4 s of tracing: the first fit
of the shipped paper log in a new process took 15.1 s with it, 11.1 s without; warm
~0.1 s), so by default (``"auto"``) it runs only when the
general fit shows a symptom of a poorer basin or an undetermined law
(:func:`needs_check`); ``nested=True`` always runs it.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from ..effects import CoulombFriction, StribeckFriction

#: Relative χ² margin by which a general model may end above its nested special case
#: before it is called worse: the LM's relative stopping tolerance on the cost is 1e-6
#: per step, and starts that converge to one optimum agree to ~1e-4 in χ².
NESTED_MARGIN = 1e-3

#: Grid starts for the nested fit, beside the warm start from the general optimum.
NESTED_STARTS = 2

#: The general law restarts from the nested optimum with ``tau_s`` this much above
#: ``tau_c`` (at ``tau_s = tau_c`` exactly the Stribeck shape has no gradient).
RESTART_RATIO = 1.02

#: ``"auto"`` checks a fit whose RMS residual exceeds this multiple of the noise floor
#: (``step/√12``, or the noise σ estimated from the log's still stretches). A model that
#: describes the log leaves at most the floor (0.4–1.0× measured on exact models: less
#: where the gear sticks); a fit above 2× has not reached it, so a better optimum of the
#: nested case is possible (a wrong basin of a paper-design log measured 14.7×).
CHECK_ABOVE_FLOOR = 2.0


def stribeck_pair(model, fixed) -> tuple[str, str] | None:
    """``(tau_c, tau_s)`` names of the model's one Stribeck law when both are free."""
    laws = [e for e in model.effects if type(e) is StribeckFriction]
    if len(laws) != 1:
        return None
    tc, ts = (p.name for p in laws[0].parameters[:2])
    return None if tc in fixed or ts in fixed else (tc, ts)


def needs_check(result, fixed) -> bool:
    """Whether ``"auto"`` checks ``result`` against its nested case: a residual above
    ``CHECK_ABOVE_FLOOR`` × the floor, or a Stribeck law the fit left degenerate (a
    non-finite standard error, ``tau_s`` at or below ``tau_c``). A wide but finite error
    (``v_s``, ``delta`` on the paper design) is no sign of a poorer optimum: the report
    says how much the data determine each parameter."""
    pair = stribeck_pair(result.model, fixed)
    if pair is None:
        return False
    floor = result.quantization_floor_rad
    if not (math.isfinite(result.rms_residual_rad) and floor > 0):
        return True
    if result.rms_residual_rad > CHECK_ABOVE_FLOOR * floor:
        return True
    law = next(e for e in result.model.effects if type(e) is StribeckFriction)
    for p in law.parameters:
        est = result.parameters.get(p.name)
        if est is None or est.fixed:
            continue
        if not math.isfinite(est.std):
            return True
    tc, ts = pair
    return not result.values[ts] > RESTART_RATIO * result.values[tc]


def against_nested(result, fixed, optimum: Callable, refit: Callable) -> object:
    """Check ``result`` (a :class:`~hdid.FitResult` of a model with a free Stribeck law)
    against its nested Coulomb case.

    ``optimum(model)`` fits ``model`` to the same log (warm-started from its values, plus
    ``NESTED_STARTS`` grid starts) and returns ``(rms_residual_rad, values)`` of its best
    optimum without analysing it; ``refit(model)`` fits and analyses ``model`` with the
    caller's options, warm-started from its values. Returns ``result``, or the general law
    refitted from the nested optimum when that is better; a warning says when the general
    law still ends worse.
    """
    model = result.model
    pair = stribeck_pair(model, fixed)
    if pair is None:
        return result
    tc, ts = pair
    values = result.values
    nested_model = model.with_effect(CoulombFriction(tau_c=values[tc]))
    # warm-started at the general optimum's tau_c; the Coulomb law has no shape ridge
    rms_n, nested_values = optimum(nested_model)
    rss_g, rss_n = result.rms_residual_rad**2, rms_n**2
    if not rss_g > rss_n * (1 + NESTED_MARGIN):
        return result
    at = {n: v for n, v in nested_values.items() if n in values}
    again = refit(model.replace(**{**at, ts: RESTART_RATIO * at[tc]}))
    if again.rms_residual_rad < result.rms_residual_rad:
        result = again
    rss_g = result.rms_residual_rad**2
    if rss_g > rss_n * (1 + NESTED_MARGIN):
        result.warnings.append(
            f"the Stribeck fit ends worse (RMS {result.rms_residual_rad:.4g}) than its nested "
            f"Coulomb case {ts} = {tc} (RMS {rms_n:.4g}), even restarted "
            f"from it: {ts}, v_s and delta are not determined by this log; fit with "
            "--add coulomb (Coulomb friction) instead"
        )
    return result
