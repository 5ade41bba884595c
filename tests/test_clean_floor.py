"""Every fit of a clean log ends in bounded time (issue 33, "A clean log reaches the floor").

A clean rich log of the independent simulator (``benchmarks/clean_floor.py``, log 173)
once ended its poorer basin at ``tau_s`` 2e-7 below ``tau_c`` 1e-3 with ``v_s`` 1e-4 rad/s:
friction that creeps, rising by ``tau_c`` within 1e-4 rad/s. Its stick-band bracket
(``hdid._problems._derived.band_bracket``: the event-driven reference simulator at the
fitted parameters, explicit DOP853) then needed ~1e7 steps a run — the fit never ended.
The bracket's simulations now have an evaluation budget; past it the bracket is left out
and a warning says why.
"""

from __future__ import annotations

from types import SimpleNamespace

import pytest

from hdid import Model
from hdid._problems._derived import BRACKET_MAX_EVALUATIONS, BracketTooCostly, band_bracket

#: the fitted values of that poorer basin (rich log 173), rounded
CREEP = dict(k1=652.4, k2=5.92e7, tau_c=1.013e-3, tau_s=2.08e-7, v_s=1.1e-4, delta=3.96,
             c_v=5.5e-6, inertia=7e-7)
#: its true plant (a regular Stribeck law: tau_s > tau_c, v_s 2 rad/s)
TRUE = dict(k1=648.2, k2=6.37e7, tau_c=8.97e-4, tau_s=1.107e-3, v_s=2.07, delta=1.97,
            c_v=1.13e-5, inertia=7e-7)


def _bracket(values):
    model = Model.default().with_ratio(100.0).replace(**values)
    # one run released from 0.157 rad (wave-generator angle, as logged), at rest at 0.01
    run = SimpleNamespace(theta0=0.157, rest_logged=0.01)
    return band_bracket(model, [run], 0.34)


def test_a_creeping_friction_law_stops_the_bracket_within_its_budget():
    # without the budget this call does not end for minutes (explicit steps of ~1e-8 s
    # over 0.34 s); with it, it raises after BRACKET_MAX_EVALUATIONS evaluations
    with pytest.raises(BracketTooCostly, match=str(BRACKET_MAX_EVALUATIONS)):
        _bracket(CREEP)


def test_a_regular_friction_law_brackets_within_the_budget():
    # the same log's true plant: a few thousand evaluations, far inside the budget (the
    # budget must not cost regular fits their bracket)
    lo, hi = _bracket(TRUE)
    assert lo == 0.01 and lo < hi < 0.157


def _clean_floor_log(design: str, seed: int):
    # the benchmark's own logs (benchmarks/clean_floor.py: the independent scipy
    # simulator, tests/independent.py, with a broad plant drawn per seed)
    import sys

    from synthetic import ROOT

    sys.path.insert(0, str(ROOT / "benchmarks"))
    import clean_floor

    return clean_floor.make(design, seed)


def test_a_clean_paper_log_in_a_poorer_basin_restarts_to_the_floor():
    # clean paper log 129 ended at 1.56x the floor (tau_s 2.4x tau_c, the limits' restarts
    # did not leave it); the Stribeck restarts from the fit's sliding level reach the
    # true basin. An exact model on rounded readings leaves 0.4-1.0x the floor step/√12;
    # 1.5x is the benchmark's (and the issue's) line for "reached the floor"
    import hdid

    df, truth = _clean_floor_log("paper", 129)
    r = hdid.fit(df, resolution=truth["resolution"], ratio=100.0)
    assert r.rms_residual_rad <= 1.5 * r.quantization_floor_rad, (r.values, r.limits)
