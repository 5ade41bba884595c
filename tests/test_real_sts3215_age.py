"""The readings' age on a real bus servo: Feetech STS3215 pendulum drops
(``../shared/data/real/sts3215_drop``; K-Scale's BAM-protocol bench, 100 Hz host polls).

The servo samples its encoder on its own clock and the host's poll returns the last sample,
so each reading is up to one of the servo's periods old. A base fit leaves that age in the
residual's sample-to-sample part; :class:`hdid.effects.ReadingAge` (period and per-run phase
scanned on the base fit's residuals, then held) must find one clock for all runs and take a
large share of that part away (benchmarks/results/real_logs.md, ``--sts reading_age``).
"""

from __future__ import annotations

import json

import numpy as np
import pytest

import hdid
from hdid.effects import library

from synthetic import ROOT, real_reference

STS = ROOT.parent / "shared" / "data" / "real" / "sts3215_drop"
SETUP = "m0.741_l0.10"   # the quickest of the eight to fit


def _fast_part(result) -> float:
    """RMS of the residual minus its 5-sample running mean, ×√(5/4), over the floor: the
    part no smooth trajectory follows."""
    fr = result.residuals()
    fast, w = [], []
    for _, d in fr.groupby("run", sort=False):
        r = d.residual_rad.to_numpy()
        fast.append(r - np.convolve(r, np.ones(5) / 5, "same"))
        w.append(d.weight.to_numpy())
    fast, w = np.concatenate(fast), np.concatenate(w)
    return float(np.sqrt(1.25 * np.sum(w * fast**2) / np.sum(w)) / result.quantization_floor_rad)


@pytest.fixture(scope="module")
def fits():
    real_reference(STS.name)  # skips, naming the folder, where the real logs are absent
    ref_path = STS / "reference.json"
    from hdid._fitting._reading_age import fit_with_age

    ref = json.loads(ref_path.read_text())["setups"][SETUP]
    model = (hdid.Model.default(inertia=ref["bam_m6_total_inertia_kgm2"], ratio=1.0)
             .without("stiffness").with_effect(library({})["gravity"]))
    base = hdid.fit(STS / ref["csv"], model)
    # one clock refitted (the scan's best; the runner-up's refit is skipped to save a fit)
    aged = fit_with_age(STS / ref["csv"], model, base=base, clocks=1)
    return base, aged


def test_one_clock_for_every_run(fits):
    _, aged = fits
    scan = aged.reading_age_scans[-1]
    assert scan.significant
    # one servo, one clock: most runs' own best period agrees with the joint one within
    # 1 % (its aliases against the 100 Hz polls, e.g. 8 ms ↔ 4.44 ms, lie 44 % apart)
    near = np.abs(np.asarray(scan.run_periods) / scan.period - 1) < 0.01
    assert near.sum() >= len(near) / 2, (scan.period, scan.run_periods)
    assert aged.model.reading is not None and any("reading_age" in w for w in aged.warnings)


def test_the_age_takes_the_sample_to_sample_part_away(fits):
    base, aged = fits
    # without the age the refit is the base fit (ratio 1); a clock unrelated to the data
    # adds its sawtooth to the residual instead (the scan measured 1.1–2× the base's
    # sample-to-sample sum of squares for the 13.3 ms alias): a fall by a quarter is the age
    assert _fast_part(aged) < 0.75 * _fast_part(base), (_fast_part(aged), _fast_part(base))
    # the physics left (the friction law's misfit) is not made worse by holding the clock
    assert aged.rms_residual_rad <= base.rms_residual_rad * 1.001
