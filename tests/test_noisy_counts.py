"""Noise ahead of an encoder's rounding in a log of counts whose step is *given*
(``counts_per_rev``): the step is the grid, not the readings' error. A still gear reads
one count or flickers between two; noise of a step and more makes still stretches jump by
2 counts and more, as on a grid found in the readings (tests/test_noisy_logs.py). A sweep
log (62 Hz at 1 kHz, 14-bit counts, 0.86 steps of noise) was fitted on its given grid at
8× the noise."""

from __future__ import annotations

import math

import pytest

import hdid
from hdid._simulation._prepare import prepare
from hdid.reference.logs import PAPER_DESIGN, TRUTH_CSF8, make_log

CPR = 4000  # (make_log's paper design encoder)
STEP = 2 * math.pi / CPR


def _counts_prep(noise_steps: float, seed: int):
    df = make_log(TRUTH_CSF8, **dict(PAPER_DESIGN, seed=seed), noise_std=noise_steps * STEP,
                  as_counts=True)
    return prepare(hdid.read_log(df, counts_per_rev=CPR))


@pytest.mark.parametrize("seed", [1, 2])
def test_noise_of_a_step_before_the_rounding_of_given_counts_is_noise(seed):
    prep = _counts_prep(1.4, seed)
    assert prep.resolution_source == "noise"
    # the readings' error, Sheppard: √(s² + step²/12), from the jump fraction of the still
    # stretches' ~90 differences (~10 % in σ; 4 sd and the model's approximations): within
    # 1.5× (the given grid said step/√12, 4.8× small)
    want = math.sqrt((1.4 * STEP) ** 2 + STEP**2 / 12)
    got = prep.resolution / math.sqrt(12.0)
    assert want / 1.5 <= got <= 1.5 * want, (got / want)


def test_noise_well_below_a_step_keeps_the_given_counts():
    # 0.2 steps: one level or a flicker between two; the readings' error is within 1.2× of
    # the grid's step/√12: the given step stays
    prep = _counts_prep(0.2, 1)
    assert prep.resolution_source == "given" and prep.quantized
    assert math.isclose(prep.resolution, STEP, rel_tol=1e-9)
