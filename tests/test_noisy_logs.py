"""Logs with Gaussian noise printed at fixed decimals instead of an encoder's grid (an analog
sensor, an interpolated encoder): the fit must reach the noise, as an encoder log reaches
its quantization floor.

The plant is one a random sweep drew (127 Hz at 1 kHz, eight samples a period, a ring-down
of ~20 periods and ~400 stuck samples a run), logged by the independent reference
simulator (:mod:`hdid.reference.logs`, numpy/scipy only) with the logger started at the
servo-off (no hold: the release falls in the first interval) and releases of four sizes.
Before the search weighted a stuck tail as one observation
(:func:`hdid._simulation._prepare.search_weight`) every start, and the truth itself, ended
at 35× the noise; the same log on an encoder grid reached its floor.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

import hdid
from hdid._simulation._prepare import prepare, search_weight
from hdid.reference.logs import TRUTH_CSF8, make_log

TRUTH = dict(TRUTH_CSF8, k1=3281.0, k2=1.294e8, tau_c=2.111e-3, tau_s=3.447e-3, v_s=5.95,
             c_v=2.57e-5, inertia=5.178e-7)
#: the noise of a 17-bit encoder's rounding, as Gaussian noise instead of a grid [rad]
SIGMA = 2 * math.pi / 131072 / math.sqrt(12.0)
AMPLITUDES = [0.157, -0.12, 0.08, -0.05]


def _noisy_log(tmp_path) -> str:
    df = make_log(TRUTH, amplitudes=AMPLITUDES, fs=1000.0, duration=0.5, hold=0.0,
                  offsets_by_setup={"A": 0.035}, seed=11, quantize=False, noise_std=SIGMA)
    out = pd.DataFrame({"run": df["run"], "setup": df["setup"],
                        "time": [f"{v:.6f}" for v in df["time"]],
                        "theta": [f"{v:.8f}" for v in df["theta"]]})
    path = tmp_path / "noisy_127hz_1khz.csv"
    out.to_csv(path, index=False)
    return str(path)


@pytest.fixture(scope="module")
def noisy_fit(tmp_path_factory):
    path = _noisy_log(tmp_path_factory.mktemp("noisy"))
    return path, hdid.fit(path, inertia=TRUTH["inertia"])


def test_noisy_ring_down_without_hold_reaches_the_noise(noisy_fit):
    _, res = noisy_fit
    assert res.resolution_source == "noise"
    # At the optimum the residuals are the noise plus the simulator's own error, which is
    # up to ~1e-4 of the swing (docs/decisions/simulator-scheme.md; the noise estimate's
    # floor): ~1.6e-5 rad here, about SIGMA, so RMS ≤ √2·SIGMA ≈ 1.41·SIGMA, and χ²'s own
    # scatter over ~2000 samples is 1/√(2ν) ≈ 2 %: 1.5. A poorer basin was 35×.
    assert res.rms_residual_rad <= 1.5 * SIGMA, res.report()
    # the parameters within 4 reported sd of the truth (a two-sided 6e-5 tail each)
    for name in ("k1", "tau_c", "c_v"):
        p = res.parameters[name]
        assert abs(p.value - TRUTH[name]) <= 4.0 * p.std, (name, p.value, p.std, TRUTH[name])


def test_search_weights_a_noisy_stuck_tail_as_one_observation(noisy_fit):
    path, _ = noisy_fit
    prep = prepare(hdid.read_log(path))
    w = search_weight(prep)
    for i in range(prep.n_runs):
        n = int(prep.lengths[i])
        tail = slice(int(prep.tail_start[i]) + 3, n)  # (FULL_WEIGHT_TAIL samples keep theirs)
        # the likelihood: independent noise, every reading full weight
        assert np.all(prep.weight[i, :n] == 1.0)
        # the search: the stuck tail's readings share one observation's weight
        assert n - tail.start > 100  # (the run rests for most of its 0.5 s)
        assert math.isclose(float(np.sum(w[i, tail] ** 2)), 1.0)
        assert np.all(w[i, : tail.start] == 1.0)


def test_search_weight_of_an_encoder_log_is_its_likelihood(tmp_path):
    df = make_log(TRUTH, amplitudes=AMPLITUDES, fs=1000.0, duration=0.5, hold=0.0,
                  offsets_by_setup={"A": 0.035}, seed=11, counts_per_rev=131072)
    prep = prepare(hdid.read_log(df))
    assert prep.quantized and search_weight(prep) is prep.weight


# ------------------------------------------------------- an encoder printed too coarsely

#: a 161 Hz plant of the same sweep (1 kHz: six samples a period), 17-bit encoder printed
#: to 1e-4 rad — twice its step, so the log tells no encoder grid and its noise is
#: estimated; a stuck run reads one printed level again and again
COARSE = dict(TRUTH_CSF8, k1=4215.6, k2=5.705e6, tau_c=1.0294e-3, tau_s=2.3276e-3,
              v_s=11.10, c_v=3.151e-6, inertia=4.108e-7)
PRINT_UNIT = 1e-4


@pytest.fixture(scope="module")
def coarse_fit(tmp_path_factory):
    df = make_log(COARSE, amplitudes=AMPLITUDES, fs=1000.0, duration=0.5, hold=0.04,
                  offsets_by_setup={"A": 0.041}, seed=29, counts_per_rev=131072)
    out = pd.DataFrame({"run": df["run"], "setup": df["setup"],
                        "time [ms]": [f"{v:.3f}" for v in df["time"] * 1e3],
                        "theta": [f"{v:.4f}" for v in df["theta"]]})
    path = tmp_path_factory.mktemp("coarse") / "printed_1e-4.csv"
    out.to_csv(path, index=False)
    return str(path), hdid.fit(path, inertia=COARSE["inertia"])


def test_coarse_printing_repeats_one_level_and_fits_at_its_rounding(coarse_fit):
    path, res = coarse_fit
    prep = prepare(hdid.read_log(path))
    assert prep.resolution_source == "noise"
    # the printing's own rounding is a floor on the noise: print unit/√12
    assert prep.resolution >= PRINT_UNIT
    # a stuck tail that repeats its printed level is one observation, in the likelihood
    for i in range(prep.n_runs):
        n = int(prep.lengths[i])
        tail = slice(int(prep.tail_start[i]) + 3, n)
        assert n - tail.start > 100
        assert math.isclose(float(np.sum(prep.weight[i, tail] ** 2)), 1.0)
    # the residual is the printing's rounding (p/√12) plus the encoder's (q/√12, q = 0.48 p)
    # and the simulator's (~1e-4 of the swing, ~p/√12 here): ≤ 1.5 p/√12 as above. A poorer
    # basin was 51× (the stuck tails counted once per sample in the search).
    assert res.rms_residual_rad <= 1.5 * PRINT_UNIT / math.sqrt(12.0), res.report()
    # the friction within 4 reported sd of its truth (with the stuck readings counted once
    # per sample the errors were too small: on the sweep's own log of this plant tau_c and
    # c_v ended 4.3 and 4.1 sd off, 0.3 and 0.2 with them counted once)
    for name in ("tau_c", "c_v"):
        p = res.parameters[name]
        assert abs(p.value - COARSE[name]) <= 4.0 * p.std, (name, p.value, p.std, COARSE[name])


# ------------------------------------------------------------ the noise and the frequency


def test_noise_of_still_stretches_is_pooled_not_their_smallest():
    # 8 runs of pure white noise: each run's head and tail (11 differences each) are still.
    # The pooled MAD of 176 differences scatters by ~1.17/√176 ≈ 9 % (MAD efficiency 37 %),
    # so 4 sd is ±35 %; the smallest of the 16 stretches' own estimates was ~0.5 σ.
    from types import SimpleNamespace

    from hdid._simulation._prepare import noise_sigma

    rng = np.random.default_rng(5)
    runs = [SimpleNamespace(theta=rng.normal(0.0, 1e-3, 120)) for _ in range(8)]
    assert noise_sigma(runs, None, still_only=True) == pytest.approx(1e-3, rel=0.35)


#: a plant that stops within two or three swings (a 71 Hz gear at 250 Hz), 12-bit
#: encoder noise printed to 1e-6 rad, logger started at the servo-off
QUICK = dict(TRUTH_CSF8, k1=4144.0, k2=5.45e7, tau_c=7.8e-3, tau_s=1.71e-2, v_s=3.06,
             c_v=2.18e-5, inertia=2.093e-6)


def test_held_story_reads_the_frequency_from_turns_not_from_noisy_stops():
    import dataclasses

    sigma = 2 * math.pi / 4000 / math.sqrt(12.0)
    f_n = math.sqrt(QUICK["k1"] / (QUICK["inertia"] * 100.0**2)) / (2 * math.pi)
    found = []
    for seed in range(7, 13):  # (cheap: no fit)
        df = make_log(QUICK, amplitudes=AMPLITUDES, fs=250.0, duration=0.5, hold=0.0,
                      offsets_by_setup={"A": -0.039}, seed=seed, quantize=False,
                      noise_std=sigma)
        log = hdid.read_log(df.assign(theta=[float(f"{v:.6f}") for v in df["theta"]]))
        log = dataclasses.replace(log, first_reading_held=tuple(r.name for r in log.runs))
        found.append(prepare(log).frequency_hz / f_n)
    # the start grid is centred on this frequency and spans 0.25–6.7× it: the truth must
    # lie well inside (from a few turns at 3.5 samples a period: within 2×). Runs that
    # stop without a turn, timed where the noise last left the rest reading, made it
    # 0.05–0.17 f_n on 3 of these 6 logs (the sweep's own: 3.7 Hz, 7.5× the noise).
    assert all(0.5 < f < 2.0 for f in found), found



def test_batch_fits_a_noisy_log_as_hdid_fit_does(tmp_path):
    # fit_many's batch path has no polish of its own: a log on no grid (search weights ≠
    # the likelihood's) goes through hdid.fit itself. The log of the module's plant held
    # 40 ms before each release (so no run moves from its first sample, which took the
    # other route already). Same computation in one process: equal up to the order of
    # sums (1e-9 relative); the batch's unpolished search ended at 440× the noise.
    df = make_log(TRUTH, amplitudes=AMPLITUDES, fs=1000.0, duration=0.5, hold=0.04,
                  offsets_by_setup={"A": 0.035}, seed=11, quantize=False, noise_std=SIGMA)
    path = tmp_path / "noisy_held.csv"
    pd.DataFrame({"run": df["run"], "setup": df["setup"],
                  "time": [f"{v:.6f}" for v in df["time"]],
                  "theta": [f"{v:.8f}" for v in df["theta"]]}).to_csv(path, index=False)
    res = hdid.fit(path, inertia=TRUTH["inertia"])
    assert res.resolution_source == "noise" and not res.first_reading_held
    row = hdid.fit_many([path], inertia=TRUTH["inertia"]).iloc[0]
    assert row["error"] is None, row["error"]
    assert math.isclose(row["rms_residual_rad"], res.rms_residual_rad, rel_tol=1e-9), (
        row["rms_residual_rad"], res.rms_residual_rad)
    for name in ("k1", "tau_c", "c_v"):
        assert math.isclose(row[name], res.parameters[name].value, rel_tol=1e-9), name


# ------------------------------------------- noise ahead of an encoder's rounding

#: the paper design's encoder step (make_log's 4000 counts/rev) [rad]
PAPER_STEP = 2 * math.pi / 4000


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_noise_of_a_step_and_more_before_the_rounding_is_noise_not_the_grid(seed):
    # The readings lie on the encoder's grid, but noise of 1.4 steps ahead of the
    # rounding makes still stretches jump by 2 steps and more; half their differences are
    # still 0 or ±1 step, so their median-absolute noise (1.05 steps) cannot tell it from
    # an encoder's flicker, and the grid (σ = step/√12, 4.8× too small) was kept.
    from hdid.reference.logs import PAPER_DESIGN

    s = 1.4 * PAPER_STEP
    df = make_log(TRUTH_CSF8, **dict(PAPER_DESIGN, seed=seed), noise_std=s)
    prep = prepare(hdid.read_log(df))
    assert prep.resolution_source == "noise"
    # the readings' error, Sheppard: √(s² + step²/12), from the fraction p ≈ 0.45 of the
    # still stretches' ~90 differences that jump ≥ 2 steps (binomial sd ~0.05 in p, ~10 %
    # in σ; 4 sd and the model's approximations): within 1.5× — the grid was 4.8× small
    want = math.sqrt(s**2 + PAPER_STEP**2 / 12)
    got = prep.resolution / math.sqrt(12.0)
    assert want / 1.5 <= got <= 1.5 * want, (got / want)


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_noise_well_below_a_step_keeps_the_encoder_grid(seed):
    # noise of 0.2 steps: a still gear reads one level or flickers between two; the
    # readings' error √(s² + step²/12) is within 1.2× of the grid's step/√12: keep it
    from hdid.reference.logs import PAPER_DESIGN

    df = make_log(TRUTH_CSF8, **dict(PAPER_DESIGN, seed=seed), noise_std=0.2 * PAPER_STEP)
    prep = prepare(hdid.read_log(df))
    assert prep.resolution_source == "estimated" and prep.quantized
    assert math.isclose(prep.resolution, PAPER_STEP, rel_tol=1e-9)


def test_a_noisy_log_far_above_its_noise_says_so(noisy_fit):
    # A noise-model log has no quantization floor; its floor is the readings' noise σ, taken
    # from the still readings (not from the fit). A fit at 3.9× that noise (a poorer basin
    # of a 1.4-step-noise paper log) used to carry no warning at all. Factor 3 is the
    # encoder logs' rule (RESIDUAL_FLOOR_FACTOR); 1.0× is the fit at the noise.
    from hdid._fitting._identifiability import plausibility_warnings

    path, res = noisy_fit
    prep = prepare(hdid.read_log(path))
    sigma = prep.resolution / math.sqrt(12.0)
    values = {n: p.value for n, p in res.parameters.items()}
    far = plausibility_warnings(prep, res.model, values, 3.9 * sigma)
    assert any("3.9× the readings' noise" in w for w in far), far
    assert not any("× the" in w for w in plausibility_warnings(prep, res.model, values, sigma))
