"""The free-motion fit against its nested special case (Stribeck ⊃ Coulomb, ``hdid._nested``).

The logic is checked with stand-in fits (so each branch is reached on purpose), and the
guarantee it gives on a real fit: a free Stribeck law never ends worse than Coulomb.
"""

from __future__ import annotations

import dataclasses
from types import SimpleNamespace

import hdid
from hdid._nested import NESTED_MARGIN, RESTART_RATIO, against_nested


def _result(model, rms):
    return SimpleNamespace(model=model, values=model.float_values(), rms_residual_rad=rms,
                           warnings=[])


def _refits(rms_by_kind):
    """A stand-in ``refit``: the RMS it returns depends on what it is asked to fit."""
    calls = []

    def refit(model, n_starts=6):
        kind = "coulomb" if type(model.effect("stribeck")).__name__ == "CoulombFriction" else "stribeck"
        calls.append((kind, model))
        return _result(model, rms_by_kind[kind])

    return refit, calls


def test_general_at_least_as_good_is_kept_and_the_nested_case_only_checked():
    general = _result(hdid.Model.default(), 1.0e-4)
    refit, calls = _refits({"coulomb": 1.0e-4 * (1 + NESTED_MARGIN / 4), "stribeck": 0.5e-4})
    out = against_nested(general, frozenset(), refit)
    assert out is general and not out.warnings
    assert [k for k, _ in calls] == ["coulomb"]


def test_general_worse_restarts_from_the_nested_optimum_and_keeps_the_better():
    general = _result(hdid.Model.default(), 2.0e-4)
    refit, calls = _refits({"coulomb": 1.0e-4, "stribeck": 0.9e-4})
    out = against_nested(general, frozenset(), refit)
    assert [k for k, _ in calls] == ["coulomb", "stribeck"]
    assert out.rms_residual_rad == 0.9e-4 and not out.warnings
    # the restart starts at the nested optimum, tau_s just above its tau_c
    nested_tc = calls[0][1].float_values()["tau_c"]
    start = calls[1][1].float_values()
    assert start["tau_c"] == nested_tc and start["tau_s"] == RESTART_RATIO * nested_tc


def test_general_still_worse_after_the_restart_is_a_warning():
    general = _result(hdid.Model.default(), 2.0e-4)
    refit, _ = _refits({"coulomb": 1.0e-4, "stribeck": 1.5e-4})
    out = against_nested(general, frozenset(), refit)
    assert out.rms_residual_rad == 1.5e-4
    assert any("nested" in w and "--add coulomb" in w for w in out.warnings)


def test_no_check_without_a_free_stribeck_law():
    refit, calls = _refits({"coulomb": 1.0, "stribeck": 1.0})
    general = _result(hdid.Model.default(), 2.0e-4)
    assert against_nested(general, frozenset({"tau_s"}), refit) is general
    coulomb = hdid.Model.default().with_effect(hdid.effects.library({})["coulomb"])
    assert against_nested(_result(coulomb, 2.0e-4), frozenset(), refit).rms_residual_rad == 2.0e-4
    assert not calls
