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
