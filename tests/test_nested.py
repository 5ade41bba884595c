"""The free-motion fit against its nested special case (Stribeck ⊃ Coulomb, ``hdid._fitting._nested``).

The logic is checked with stand-in fits (so each branch is reached on purpose), and the
guarantee it gives on a real fit: a free Stribeck law never ends worse than Coulomb.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from types import SimpleNamespace

import hdid

from hdid._fitting._nested import (
    CHECK_ABOVE_FLOOR,
    NESTED_MARGIN,
    RESTART_RATIO,
    against_nested,
    needs_check,
)


EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"


def _result(model, rms):
    return SimpleNamespace(model=model, values=model.float_values(), rms_residual_rad=rms,
                           warnings=[])


def _refits(rms_by_kind):
    """Stand-ins for ``optimum`` and ``refit``: the RMS they return depends on what they
    are asked to fit."""
    calls = []

    def kind_of(model):
        return ("coulomb" if type(model.effect("stribeck")).__name__ == "CoulombFriction"
                else "stribeck")

    def optimum(model):
        calls.append((kind_of(model), model))
        return rms_by_kind[kind_of(model)], model.float_values()

    def refit(model):
        calls.append((kind_of(model), model))
        return _result(model, rms_by_kind[kind_of(model)])

    return optimum, refit, calls


def test_general_at_least_as_good_is_kept_and_the_nested_case_only_checked():
    general = _result(hdid.Model.default(), 1.0e-4)
    optimum, refit, calls = _refits({"coulomb": 1.0e-4 * (1 + NESTED_MARGIN / 4),
                                     "stribeck": 0.5e-4})
    out = against_nested(general, frozenset(), optimum, refit)
    assert out is general and not out.warnings
    assert [k for k, _ in calls] == ["coulomb"]


def test_general_worse_restarts_from_the_nested_optimum_and_keeps_the_better():
    general = _result(hdid.Model.default(), 2.0e-4)
    optimum, refit, calls = _refits({"coulomb": 1.0e-4, "stribeck": 0.9e-4})
    out = against_nested(general, frozenset(), optimum, refit)
    assert [k for k, _ in calls] == ["coulomb", "stribeck"]
    assert out.rms_residual_rad == 0.9e-4 and not out.warnings
    # the restart starts at the nested optimum, tau_s just above its tau_c
    nested_tc = calls[0][1].float_values()["tau_c"]
    start = calls[1][1].float_values()
    assert start["tau_c"] == nested_tc and start["tau_s"] == RESTART_RATIO * nested_tc


def test_general_still_worse_after_the_restart_is_a_warning():
    general = _result(hdid.Model.default(), 2.0e-4)
    optimum, refit, _ = _refits({"coulomb": 1.0e-4, "stribeck": 1.5e-4})
    out = against_nested(general, frozenset(), optimum, refit)
    assert out.rms_residual_rad == 1.5e-4
    assert any("nested" in w and "--add coulomb" in w for w in out.warnings)


def test_no_check_without_a_free_stribeck_law():
    optimum, refit, calls = _refits({"coulomb": 1.0, "stribeck": 1.0})
    general = _result(hdid.Model.default(), 2.0e-4)
    assert against_nested(general, frozenset({"tau_s"}), optimum, refit) is general
    coulomb = hdid.Model.default().with_effect(hdid.effects.library({})["coulomb"])
    out = against_nested(_result(coulomb, 2.0e-4), frozenset(), optimum, refit)
    assert out.rms_residual_rad == 2.0e-4
    assert not calls
    assert not needs_check(_result(coulomb, 1.0), frozenset())


def _estimates(model, std=None):
    std = std or {}
    return {n: SimpleNamespace(value=v, std=std.get(n, 0.1 * abs(v)), fixed=False)
            for n, v in model.float_values().items()}


def test_auto_checks_only_a_fit_with_a_symptom():
    m = hdid.Model.default()  # catalog tau_s 1.5 tau_c
    floor = 1e-4

    def r(rms, std=None, **values):
        mm = m.replace(**values) if values else m
        return SimpleNamespace(model=mm, values=mm.float_values(), rms_residual_rad=rms,
                               quantization_floor_rad=floor, parameters=_estimates(mm, std))

    assert not needs_check(r(0.5 * floor), frozenset())  # at the floor, determined
    assert not needs_check(r((CHECK_ABOVE_FLOOR - 0.1) * floor), frozenset())
    assert needs_check(r((CHECK_ABOVE_FLOOR + 0.1) * floor), frozenset())
    assert needs_check(r(0.5 * floor, {"v_s": float("nan")}), frozenset())
    assert not needs_check(r(0.5 * floor, {"v_s": 100.0}), frozenset())  # wide is no symptom
    tc = m.float_values()["tau_c"]
    assert needs_check(r(0.5 * floor, tau_s=tc), frozenset())  # tau_s at tau_c
    assert not needs_check(r(3 * floor), frozenset({"tau_s"}))  # no free law: no check


TRUTH_7001 = {"k1": 987.9908367878866, "k2": 83346829.31987147, "tau_c": 0.003714300737917284,
              "tau_s": 0.007180487035723282, "v_s": 5.5747670319671085,
              "delta": 0.7769390144567819, "c_v": 2.587737081563798e-05, "inertia": 7e-07,
              "ratio": 100.0}
#: The optimum the default multistart ended in on that log before its starts included the
#: log's own frequency (measured with fit(nested=False) at 61069be): 14.7× the floor.
WRONG_BASIN_7001 = {"k1": 24586.74, "k2": 9.3257e8, "tau_c": 0.020456, "tau_s": 0.127458,
                    "v_s": 5.582987, "delta": 0.943668, "c_v": 3e-06}


def _log_7001():
    # A paper-design log (4 releases ±0.157 rad, 250 Hz, 4000 counts) of a CSF-8 whose
    # truth was drawn around the catalog (benchmarks/posterior_sbc.py, seed 7001); the
    # true frequency is 1.30× the log's own estimate (4 samples per period).
    from hdid.reference import logs

    return logs.make_log(TRUTH_7001, **{**logs.PAPER_DESIGN, "seed": 7001})


def _at_truth(r):
    # an optimum at the floor (an exact model on rounded readings leaves ≤ step/√12; 1.3×
    # is diagnose's margin) and k1 within 3 std of the truth
    assert r.rms_residual_rad <= 1.3 * r.quantization_floor_rad, r.warnings
    k1 = r.parameters["k1"]
    assert abs(k1.value - TRUTH_7001["k1"]) <= 3 * k1.std


def test_the_multistart_starts_near_the_logs_own_frequency():
    # Measured before GRID_NEAR_FACTOR: every cost-ranked start stuck at 1.5–6.7× the log's
    # frequency and the fit ended at k1 ≈ 24 600, 14.7× the floor, without a warning.
    _at_truth(hdid.fit(_log_7001(), inertia=TRUTH_7001["inertia"], nested=False))


def test_a_fit_left_in_a_wrong_basin_is_rescued_by_its_nested_case():
    # One start, in the wrong basin: alone it stays there; the nested Coulomb check
    # ("auto": the residual is far above the floor) finds the right one and restarts.
    log, wrong = _log_7001(), hdid.Model.default().replace(**WRONG_BASIN_7001)
    kw = dict(inertia=TRUTH_7001["inertia"], n_starts=1, start_from_model=True)
    stuck = hdid.fit(log, wrong, nested=False, **kw)
    assert stuck.rms_residual_rad > CHECK_ABOVE_FLOOR * stuck.quantization_floor_rad
    _at_truth(hdid.fit(log, wrong, **kw))


def test_a_residual_above_three_times_the_floor_is_a_warning():
    # plausibility_warnings on the shipped paper log's own prepared data: an exact model
    # leaves ≤ 1× step/√12 (0.6–0.9× measured at paper-design truths); the generator's
    # poorer basins measured 4.2–11.9×. Just below the factor: no warning; above: one.
    from hdid._fitting._fit import _setup
    from hdid._fitting._identifiability import RESIDUAL_FLOOR_FACTOR, plausibility_warnings

    s = _setup(hdid.read_log(EXAMPLE))
    floor = s.prep.resolution / 12**0.5
    values = s.model.float_values()
    quiet = plausibility_warnings(s.prep, s.model, values, 0.95 * RESIDUAL_FLOOR_FACTOR * floor)
    loud = plausibility_warnings(s.prep, s.model, values, 1.05 * RESIDUAL_FLOOR_FACTOR * floor)
    assert not any("does not describe" in w for w in quiet)  # (below: "not reached the floor")
    assert [w for w in loud if "quantization floor" in w and "basin" in w]
    assert RESIDUAL_FLOOR_FACTOR * 0.9 < 4.2  # the generator's poorer basins are flagged
