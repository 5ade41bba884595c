"""A general friction law against its nested special case: Stribeck ⊃ Coulomb.

Stribeck friction with ``tau_s = tau_c`` is Coulomb friction (any ``v_s``, ``delta``), so
the least-squares optimum of a model with a free Stribeck law can never be worse than the
same model with Coulomb friction. A multi-start fit can still end there (the Stribeck
shape adds a curved ridge and a ``v_s → 0`` corner to the cost); this module checks the
claim on the log in hand: it fits the nested case, restarts the general law from the
nested optimum when the general fit ended worse, and warns when even that restart stays
worse (the driven fit does the same, Coulomb first, in :mod:`hdid._driven_fit`).
"""

from __future__ import annotations

from collections.abc import Callable

from .effects import CoulombFriction, StribeckFriction

#: Relative χ² margin by which a general model may end above its nested special case
#: before it is called worse: the LM's relative stopping tolerance on the cost is 1e-6
#: per step, and starts that converge to one optimum agree to ~1e-4 in χ².
NESTED_MARGIN = 1e-3

#: Grid starts for the nested fit, beside the warm start from the general optimum.
NESTED_STARTS = 2

#: The general law restarts from the nested optimum with ``tau_s`` this much above
#: ``tau_c`` (at ``tau_s = tau_c`` exactly the Stribeck shape has no gradient).
RESTART_RATIO = 1.02


def stribeck_pair(model, fixed) -> tuple[str, str] | None:
    """``(tau_c, tau_s)`` names of the model's one Stribeck law when both are free."""
    laws = [e for e in model.effects if type(e) is StribeckFriction]
    if len(laws) != 1:
        return None
    tc, ts = (p.name for p in laws[0].parameters[:2])
    return None if tc in fixed or ts in fixed else (tc, ts)


def against_nested(result, fixed, refit: Callable) -> object:
    """Check ``result`` (a :class:`~hdid.FitResult` of a model with a free Stribeck law)
    against its nested Coulomb case.

    ``refit(model, n_starts=…)`` fits ``model`` to the same log, warm-started from its
    values, with the caller's options. Returns ``result``, or the general law refitted from the nested
    optimum when that is better; a warning says when the general law still ends worse.
    """
    model = result.model
    pair = stribeck_pair(model, fixed)
    if pair is None:
        return result
    tc, ts = pair
    values = result.values
    nested_model = model.with_effect(CoulombFriction(tau_c=values[tc]))
    # warm-started at the general optimum's tau_c; the Coulomb law has no shape ridge
    nested = refit(nested_model, n_starts=NESTED_STARTS)
    rss_g, rss_n = result.rms_residual_rad**2, nested.rms_residual_rad**2
    if not rss_g > rss_n * (1 + NESTED_MARGIN):
        return result
    at = {n: v for n, v in nested.values.items() if n in values}
    again = refit(model.replace(**{**at, ts: RESTART_RATIO * at[tc]}))
    if again.rms_residual_rad < result.rms_residual_rad:
        result = again
    rss_g = result.rms_residual_rad**2
    if rss_g > rss_n * (1 + NESTED_MARGIN):
        result.warnings.append(
            f"the Stribeck fit ends worse (RMS {result.rms_residual_rad:.4g}) than its nested "
            f"Coulomb case {ts} = {tc} (RMS {nested.rms_residual_rad:.4g}), even restarted "
            f"from it: {ts}, v_s and delta are not determined by this log; fit with "
            "--add coulomb (Coulomb friction) instead"
        )
    return result
