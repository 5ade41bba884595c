"""The calibration script's check logs (benchmarks/posterior_sbc.py): ``--noise analog`` gives
the readings the sampler's likelihood describes exactly (docs/decisions/sbc-tau-c-skew.md)."""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import posterior_sbc as S  # noqa: E402

from hdid.reference import logs as gen  # noqa: E402


def test_analog_logs_are_unrounded_with_the_rounding_variance_as_gaussian_noise():
    truth, df, info, notes = S.draw_log(gen, "paper", 36002, "analog")
    step = gen.encoder_step()
    # the noise is the Widrow variance q²/12 itself, so the likelihood's σ is the generator's
    assert notes["noise_sigma_rad"] == pytest.approx(step / math.sqrt(12), rel=1e-12)
    # unrounded: a continuous reading lies on the encoder grid with probability zero
    off_grid = np.abs(df.theta / step - np.round(df.theta / step)) > 1e-6
    assert off_grid.mean() > 0.99
    # the holds (the first 40 ms: 10 samples a run at 250 Hz, before any release) scatter by
    # σ: 4 runs × 10 readings about each run's mean, 36 degrees of freedom, so the sample sd
    # is within 3 × 1/√72 ≈ 35 % of σ
    held = df[df.time < 0.9 * gen.PAPER_DESIGN["hold"]]
    resid = held.theta - held.groupby("run").theta.transform("mean")
    sd = math.sqrt(float(np.sum(resid**2)) / (len(held) - held.run.nunique()))
    assert sd == pytest.approx(step / math.sqrt(12), rel=0.35)


def test_shards_put_paper_logs_first_and_start_no_log_past_their_end(tmp_path, monkeypatch):
    """The sharded calibration (devrun's 16-core plan): ``--paper-first`` orders every paper
    log before any rich one, and ``--end-by`` starts no log expected to end past it (recorded
    as skipped, none run): a shard cut by its hard timeout keeps whole logs only."""
    monkeypatch.setattr(S._common, "RESULTS", tmp_path)
    S.main(["--paper-logs", "2", "--rich-logs", "2", "--seed0", "100", "--paper-first", "--end-by", "1",
            "--expect-s", "paper:5,rich:5", "--shard", "0/1", "--name", "t"])
    res = json.loads((tmp_path / "t.json").read_text())
    assert res["logs"] == []
    assert [(s["design"], s["seed"]) for s in res["skipped"]] == [
        ("paper", 100), ("paper", 101), ("rich", 1100), ("rich", 1101)]


def test_aliased_logs_are_told_from_their_truth_swing():
    """The calibration reports aliased logs apart: readings a period of the truth's swing,
    ``fs / f``, with ``f = √(k1/(J·N²))/2π`` (the spring at the output, the inertia at the
    motor) hardened by the Duffing backbone ``√(1 + ¾·k2·A²/k1)`` at the largest release's
    twist ``A = 0.157 rad / N``."""
    J, N, fs = 7e-7, 100.0, gen.PAPER_DESIGN["fs"]
    k1 = J * N**2 * (2 * math.pi * 100.0) ** 2  # a 100 Hz linear swing: 2.5 readings a period at 250 Hz
    linear = {"design": "paper", "truth_params": {"k1": k1, "k2": 0.0, "inertia": J, "ratio": N}}
    assert S.samples_per_period(linear) == pytest.approx(fs / 100.0, rel=1e-12)
    # k2 with ¾·k2·A²/k1 = 3 doubles the swing's frequency: half the readings a period
    A = max(abs(a) for a in gen.PAPER_DESIGN["amplitudes"]) / N
    hard = {"design": "paper", "truth_params": dict(linear["truth_params"], k2=4 * k1 / A**2)}
    assert S.samples_per_period(hard) == pytest.approx(fs / 200.0, rel=1e-12)
    # the rich design reads the same plant at 1 kHz: 10 readings a period
    assert S.samples_per_period(dict(linear, design="rich")) == pytest.approx(10.0, rel=1e-12)
