"""Every fit of a clean log ends in bounded time (issue 33, "A clean log reaches the floor").

A clean rich log of the independent simulator with a broad plant (``clean_log`` below,
log 173; the measured table: ``docs/decisions/limits-at-the-floor.md``) once ended its
poorer basin at ``tau_s`` 2e-7 below ``tau_c`` 1e-3 with ``v_s`` 1e-4 rad/s: friction
that creeps, rising by ``tau_c`` within 1e-4 rad/s. Its stick-band bracket
(``hdid._problems._derived.band_bracket``: the event-driven reference simulator at the
fitted parameters, explicit DOP853) then needed ~1e7 steps a run — the fit never ended.
The bracket's simulations now have an evaluation budget; past it the bracket is left out
and a warning says why.
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

import independent as ind

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


#: The clean-log designs of the limit checks' measurement (docs/decisions/limits-at-the-floor.md):
#: releases of the wave generator [rad], sampling rate [Hz], seconds a run, setups.
DESIGNS = {"paper": dict(amps=[0.157, -0.157, 0.157, -0.157], rate=250.0, duration=0.5, setups=list("AABB")),
           "rich": dict(amps=[0.157, -0.157, 0.12, -0.12, 0.08, -0.08, 0.05, -0.05], rate=1000.0, duration=0.3,
                        setups=list("AAAABBBB"))}
SEED_BASE = {"paper": 330000, "rich": 331000}


def clean_log(design: str, seed: int):
    """``(DataFrame, truth)``: clean log ``seed`` of ``design`` from the independent scipy
    simulator (``tests/independent.py``), a broad plant drawn per seed: k1 ±40 %, k2 0–2×
    the catalog's 6.5e7 N m/rad³, tau_s the wave generator's stiffness times 0.012–0.040 rad
    [N m], tau_s/tau_c 1.1–2, v_s 2–20 rad/s (log-uniform), delta 0.8–3, c_v over a decade."""
    d, rng, N = DESIGNS[design], np.random.default_rng(SEED_BASE[design] + seed), 100.0
    k1, k2 = 940.0 * rng.uniform(0.6, 1.4), 6.5e7 * rng.uniform(0.0, 2.0)
    tau_s = k1 / N**2 * rng.uniform(0.012, 0.040)
    tau_c = tau_s / rng.uniform(1.1, 2.0)
    v_s = math.exp(rng.uniform(math.log(2.0), math.log(20.0)))
    delta = rng.uniform(0.8, 3.0)
    c_v = 1.8e-5 * math.exp(rng.uniform(-0.5, 0.5) * math.log(10.0))
    plant = ind.Plant(inertia=7e-7, ratio=N, k1=k1, k2=k2, tau_c=tau_c, tau_s=tau_s, v_s=v_s, delta=delta, c_v=c_v)
    offsets = {s: float(rng.uniform(-0.03, 0.03)) for s in sorted(set(d["setups"]))}
    phases = rng.uniform(0.0, 1.0, len(d["amps"]))
    return ind.make_log(plant, d["amps"], rate=d["rate"], duration=d["duration"], hold=0.04,
                        setups=d["setups"], offsets=offsets, counts_per_rev=4000, release_phase=list(phases), seed=seed)


def test_a_clean_paper_log_in_a_poorer_basin_restarts_to_the_floor():
    # clean paper log 129 ended at 1.56x the floor (tau_s 2.4x tau_c, the limits' restarts
    # did not leave it); the Stribeck restarts from the fit's sliding level reach the
    # true basin. An exact model on rounded readings leaves 0.4-1.0x the floor step/√12;
    # 1.5x is the measurement's (and the issue's) line for "reached the floor"
    import hdid

    df, truth = clean_log("paper", 129)
    r = hdid.fit(df, resolution=truth["resolution"], ratio=100.0)
    assert r.rms_residual_rad <= 1.5 * r.quantization_floor_rad, (r.values, r.limits)
