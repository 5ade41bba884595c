"""Noisy logs with holds: a hold is a stretch whose readings stay within a few σ of one
level, and the release is where they leave it for good — not the first noise excursion.

The plant is one a random sweep drew (74.6 Hz logged at 250 Hz, a 40 ms hold, Gaussian
noise of a 14-bit encoder's rounding printed to 1e-8 rad), logged by the independent
reference simulator (:mod:`hdid.reference.logs`). The difference of two noisy readings has
sd √2σ: a first reading 3.5σ below its hold and a second 1.5σ above differ by 5σ, where
the old pairwise test called the run already moving (the sweep's log ended at 11.6× the
noise with that run fitted as a ring-down).
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

import hdid
from hdid._simulation._noise import grid_noise
from hdid._simulation._prepare import prepare
from hdid.reference.logs import TRUTH_CSF8, make_log

TRUTH = dict(TRUTH_CSF8, k1=1679.7, k2=7.723e7, tau_c=1.670e-3, tau_s=1.865e-3, v_s=1.013,
             c_v=3.665e-6, inertia=7.651e-7)
#: a 14-bit encoder's rounding as Gaussian noise [rad]
SIGMA = 2 * math.pi / 16384 / math.sqrt(12.0)
AMPLITUDES = [0.157, -0.12, 0.08, -0.05]
OFFSET = 0.035
HOLD = 0.04
FS = 250.0


def _frame(spikes: dict) -> pd.DataFrame:
    """The log, with ``spikes[(run, sample)] = Δθ [rad]`` added to single readings."""
    df = make_log(TRUTH, amplitudes=AMPLITUDES, fs=FS, duration=0.5, hold=HOLD,
                  offsets_by_setup={"A": OFFSET}, seed=5, quantize=False, noise_std=SIGMA)
    th = df["theta"].to_numpy(copy=True)
    for (run, k), d in spikes.items():
        rows = np.flatnonzero(df["run"].astype(str).to_numpy() == str(run))
        th[rows[k]] += d
    df["theta"] = th
    return df


def _write(df: pd.DataFrame, path) -> str:
    out = pd.DataFrame({"run": df["run"], "setup": df["setup"],
                        "time": [f"{v:.6f}" for v in df["time"]],
                        "theta": [f"{v:.8f}" for v in df["theta"]]})
    out.to_csv(path, index=False)
    return str(path)


def _runs(df):
    return [g["theta"].to_numpy() for _, g in df.groupby("run", sort=True)]


# Run 4 is held at −0.05 + OFFSET and moves up. Its first reading set 6σ below the second
# (the pairwise test's 5σ exceeded whatever the second's own noise) on the side away from
# the motion; or its second reading a lone 8σ spike.
SPIKES = {"first reading below": {(4, 0): None}, "second reading": {(4, 1): 8.0 * SIGMA}}


def _spiked(case: str) -> pd.DataFrame:
    base = _frame({})
    th4 = _runs(base)[3]
    spikes = dict(SPIKES[case])
    if (4, 0) in spikes:
        spikes[(4, 0)] = (th4[1] - 6.0 * SIGMA) - th4[0]
    return _frame(spikes)


@pytest.mark.parametrize("case", sorted(SPIKES))
def test_a_noise_spike_at_the_start_of_a_hold_keeps_the_run_held(case, tmp_path):
    df = _spiked(case)
    prep = prepare(hdid.read_log(_write(df, tmp_path / "spiked.csv")))
    assert not prep.moving_start[3]
    # the release bracket holds the simulator's release instant, HOLD + u/FS with u in
    # [0, 1): the hold's last sample is at or before HOLD + 1/FS, the first moved after HOLD
    assert prep.release_lo[3] <= HOLD + 1.0 / FS and prep.release_hi[3] > HOLD
    # the hold's level is the run's, not the spike's: within 2σ/√n of the hold's mean
    # (n = 10 held readings) plus the simulator's start, i.e. within 1σ of θ0 + offset
    assert abs(prep.hold[3] - (AMPLITUDES[3] + OFFSET)) <= SIGMA


def test_a_first_reading_off_toward_the_motion_is_not_taken_for_a_spike(tmp_path):
    # a ring-down cut just before a turning point comes from the side it then returns to:
    # a first reading off its neighbours' level on the motion's side keeps the run moving
    base = _frame({})
    th4 = _runs(base)[3]
    df = _frame({(4, 0): (th4[1] + 8.0 * SIGMA) - th4[0]})
    prep = prepare(hdid.read_log(_write(df, tmp_path / "toward.csv")))
    assert prep.moving_start[3]


@pytest.fixture(scope="module")
def spiked_fit(tmp_path_factory):
    path = _write(_spiked("first reading below"), tmp_path_factory.mktemp("spike") / "s.csv")
    return hdid.fit(path, inertia=TRUTH["inertia"])


def test_a_noisy_log_with_a_spike_before_a_release_reaches_the_noise(spiked_fit):
    res = spiked_fit
    assert res.resolution_source == "noise"
    # residuals: the noise (one spike of 6σ adds 36σ²/~2000 readings ≈ 2 % of χ²) plus the
    # simulator's own error (~1e-4 of the swing, ~σ here), so RMS ≤ √2·σ ≈ 1.41σ, and χ²'s
    # scatter over ~2000 readings is ~2 %: 1.5σ. With the run read as moving: 11.6σ.
    assert res.rms_residual_rad <= 1.5 * SIGMA, res.report()

    # 3.35 samples a period: resolved, no aliasing warning (the guard of the next test)
    assert not any(w.startswith("aliased") for w in res.warnings), res.warnings


#: a 127 Hz plant (test_noisy_logs' sweep plant) logged at 250 Hz: 1.97 samples a period
ALIASED = dict(TRUTH_CSF8, k1=3281.0, k2=1.294e8, tau_c=2.111e-3, tau_s=3.447e-3, v_s=5.95,
               c_v=2.57e-5, inertia=5.178e-7)


@pytest.mark.parametrize("noisy", [False, True], ids=["encoder", "noise"])
def test_a_swing_above_the_logs_nyquist_frequency_says_so(noisy, tmp_path):
    step = 2 * math.pi / 131072
    df = make_log(ALIASED, amplitudes=AMPLITUDES, fs=FS, duration=0.5, hold=HOLD,
                  offsets_by_setup={"A": OFFSET}, seed=3, quantize=not noisy,
                  noise_std=step / math.sqrt(12.0) if noisy else 0.0)
    res = hdid.fit(_write(df, tmp_path / "aliased.csv"), inertia=ALIASED["inertia"])
    f_true = math.sqrt(ALIASED["k1"] / (ALIASED["inertia"] * 1e4)) / (2 * math.pi)
    assert f_true > FS / 2  # (the plant is above Nyquist)
    # the fit lands on the swing or on its alias fs − f (123 Hz): both under 2.5 samples a
    # period; the warning names the remedy, and the JSON carries it
    hits = [w for w in res.warnings if w.startswith("aliased")]
    assert len(hits) == 1 and "sample faster" in hits[0], res.warnings
    assert any(w.startswith("aliased") for w in res.to_dict()["warnings"])


QUIET_HOLD = 0.1  # [s]: 100 readings, longer than the 50 a still stretch is read from


def _quiet_hold_frame(noise: float, grid: float | None) -> pd.DataFrame:
    """The 74.6 Hz plant at 1 kHz held 0.1 s, with noise ``noise`` [rad] only after the
    release (a sensor or drive quiet until the servo-off: every hold repeats one reading),
    rounded to ``grid`` [rad] when given."""
    df = make_log(TRUTH, amplitudes=AMPLITUDES, fs=1000.0, duration=0.6, hold=QUIET_HOLD,
                  offsets_by_setup={"A": OFFSET}, seed=7, quantize=False, noise_std=0.0)
    rng = np.random.default_rng(7)
    t = df["time"].to_numpy()
    th = df["theta"].to_numpy() + np.where(t > QUIET_HOLD, rng.normal(0.0, noise, t.size), 0.0)
    df["theta"] = np.round(th / grid) * grid if grid else th
    return df


def test_noise_after_quiet_holds_is_read_from_the_stuck_tails(tmp_path):
    step = 2 * math.pi / 16384
    s = 1.4 * step  # noise ahead of the rounding (well past the grid/noise switch at ½ step)
    df = _quiet_hold_frame(s, step)
    prep = prepare(hdid.read_log(_write(df, tmp_path / "quiet.csv")))
    assert prep.resolution_source == "noise"
    # the readings' error: the noise and its rounding (Sheppard: s² + step²/12), from the
    # four stuck tails' ~200 differences (the jump fraction's relative sd ~10 %): within
    # 0.7–1.4× of it. The holds, read as the still stretches, said 0: the grid was kept
    truth = math.sqrt(s**2 + step**2 / 12.0)
    sigma = prep.resolution / math.sqrt(12.0)
    assert 0.7 * truth <= sigma <= 1.4 * truth, (sigma / truth)


def test_a_hardening_spring_swings_above_nyquist_although_its_small_swing_does_not():
    # posterior_sbc's paper seed 40000: k1 284, k2 5.26e9 N·m/rad³, a 0.157 rad release
    # through a 100:1 gear (1.57e-3 rad twist), inertia 7e-7 at the input, logged at 250 Hz.
    # Small swings: f₀ = √(k1/(I·N²))/2π = 32 Hz, 7.8 samples a period. The Duffing backbone
    # (f₀·√(1 + ¾k2A²/k1), k2A²/k1 = 45) puts the largest swings at ~190 Hz, above 125 Hz:
    # its readings flip sign sample to sample, and the fit ended in an aliased basin (3.7×)
    from hdid._simulation._aliasing import aliasing_warning, swing_hz

    k1, k2, twist = 283.6, 5.26e9, 0.157 / 100.0
    f0 = math.sqrt(k1 / (7e-7 * 100.0**2)) / (2 * math.pi)
    f = swing_hz(f0, {"k1": k1, "k2": k2}, twist)
    assert 180.0 < f < 200.0  # (√(1 + 0.75·45.0) = 5.89 × 32.0 Hz = 189 Hz)
    assert aliasing_warning(1 / 250.0, f0, math.nan) is None
    w = aliasing_warning(1 / 250.0, f, math.nan)
    assert w is not None and "above the log's Nyquist" in w and "sample faster" in w


@pytest.mark.parametrize("seed", [1, 2])
def test_an_encoder_log_without_holds_keeps_its_grid(seed, tmp_path):
    # Each run cut at its first moving sample (a logger started by the motion): its head is
    # the swing (74.6 Hz at 250 Hz: differences of tens of counts, anticorrelated at lag 1
    # like noise's), its tail one stuck count. Motion is no still stretch: the tail's clean
    # level says the readings are the 4000-count encoder's, exactly (grid_noise 0). Read as
    # noise, the log was fitted with a noise model of ~1.5 steps (and the fit at 1.2x that)
    df = make_log(TRUTH, amplitudes=AMPLITUDES, fs=FS, duration=0.5, hold=HOLD,
                  offsets_by_setup={"A": OFFSET}, seed=seed, quantize=True)
    cut = []
    for _, g in df.groupby("run", sort=True):
        th = g["theta"].to_numpy()
        cut.append(g.iloc[int(np.flatnonzero(th != th[0])[0]):])
    log = hdid.read_log(_write(pd.concat(cut), tmp_path / "no_hold.csv"))
    step = 2 * math.pi / 4000
    assert grid_noise(log.runs, log.resolution) == 0.0
    prep = prepare(log)
    assert prep.resolution_source != "noise"
    # the step found in readings printed to 1e-8 rad: within 1e-6 of 2π/4000
    assert abs(prep.resolution - step) <= 1e-6 * step
