"""One-sample read dropouts (a bus servo's −π reading) are dropped with a note, before the
encoder step is sought; legitimate motion — a fast release turning around, an oscillation
near two samples per period, an encoder's flicker — is never called a dropout.

The real logs are read from ``../shared/data/real`` (skipped when absent): the Feetech
STS3215 bench (K-Scale) writes −π for a failed read in 7 of its 64 raw logs.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hdid import LogError, read_log
from hdid._log._dropouts import _run_dropouts

ROOT = Path(__file__).resolve().parents[1]
SYN = ROOT / "data" / "synthetic"
REAL = ROOT.parent / "shared" / "data" / "real"
STS = REAL / "sts3215_drop"


def _need(path: Path) -> None:
    if not path.exists():
        pytest.skip(f"{path.name} not in {path.parent} (real logs stay outside the "
                    "repository: ../shared/data/real/README.md says where they come from)")


def _dropout_notes(log) -> list[str]:
    return [n for n in log.notes if "read dropout" in n]


def _with_dropouts(tmp_path: Path, rows: list[int], value: float = -math.pi) -> Path:
    """The shipped paper log with the readings at data rows ``rows`` replaced by what a
    failed bus read returns."""
    d = pd.read_csv(SYN / "csf8_paper.csv")
    for r in rows:
        d.loc[r, "theta"] = value
    path = tmp_path / "dropout.csv"
    d.to_csv(path, index=False, float_format="%.10g")
    return path


def test_one_dropout_is_dropped_with_a_note(tmp_path):
    clean = read_log(SYN / "csf8_paper.csv")
    d = pd.read_csv(SYN / "csf8_paper.csv")
    run0 = d["run"].iloc[0]
    k = int(np.flatnonzero(d["run"] == run0)[40])  # in the free swing of the first run
    log = read_log(_with_dropouts(tmp_path, [k]))
    notes = _dropout_notes(log)
    assert len(notes) == 1, log.notes
    # the note names the CSV line (header is line 1), the time and the reading
    assert f"row {k + 2} " in notes[0] and "-3.141593" in notes[0], notes[0]
    run = log.runs[0]
    assert run.n_samples == clean.runs[0].n_samples - 1
    assert d["time"].iloc[k] not in set(run.time)
    assert np.all(run.theta > -3.0)  # the swing is within ±0.2 rad of its offset
    # the step is the clean log's: the dropout leaves before the grid is sought
    assert log.resolution == pytest.approx(clean.resolution, rel=1e-9)
    assert [r.n_samples for r in log.runs[1:]] == [r.n_samples for r in clean.runs[1:]]


def test_many_dropouts_refuse_the_log_with_the_fix(tmp_path):
    d = pd.read_csv(SYN / "csf8_paper.csv")
    first = np.flatnonzero(d["run"] == d["run"].iloc[0])
    rows = [int(i) for i in first[10:-10:40]]  # 2.5 % of the run's rows, each alone
    assert len(rows) > 0.01 * len(first)
    with pytest.raises(LogError) as err:
        read_log(_with_dropouts(tmp_path, rows))
    msg = str(err.value)
    assert "\n" not in msg and "read dropouts" in msg and "theta" in msg, msg


@pytest.mark.parametrize("name, kw", [
    ("csf8_paper.csv", {}), ("csf8_rich_1khz.csv", {}),
    ("hidden_hysteresis_1khz.csv", {}), ("driven_csf8.csv", {}),
    ("csf8_paper_counts.csv", {"counts_per_rev": 4000}),
])
def test_shipped_logs_have_no_dropouts(name, kw):
    log = read_log(SYN / name, **kw)
    assert not _dropout_notes(log), log.notes


def test_real_logs_have_no_dropouts_but_the_documented_two():
    _need(REAL)
    ref = json.loads((STS / "reference.json").read_text()) if STS.exists() else {"setups": {}}
    documented = {}
    for setup in ref["setups"].values():
        for run, info in setup["runs"].items():
            for t in info["dropout_samples_in_csv_s"]:
                documented.setdefault(setup["csv"], []).append((run, t))
    files = sorted(p for p in REAL.glob("*/*.csv") if p.name != "sts3215_drop_all.csv")
    assert files
    for path in files:
        try:
            log = read_log(path)
        except LogError:  # a driven log needs its torque constant
            log = read_log(path, torque_constant=1.0)
        notes = _dropout_notes(log)
        expect = documented.get(path.name, [])
        assert len(notes) == len(expect), (path.name, notes, expect)
        for run, t in expect:
            assert any(f"run '{run}'" in n and f"t = {t:.6g} s" in n for n in notes), notes


def test_raw_sts3215_logs_every_minus_pi_and_nothing_else():
    """The 64 raw STS3215 logs (hold, lift, release, swing, rest at 100 Hz): the rule finds
    exactly the samples that read −π (the arm never goes past −1.6 rad; a reading within
    0.01 rad of −π is the bus's failed read)."""
    raw = STS / "raw" / "logs"
    _need(raw)
    files = sorted(raw.glob("*.json"))
    assert files
    hits = 0
    for f in files:
        e = json.loads(f.read_text())["entries"]
        t = np.array([x["timestamp"] for x in e], float)
        x = np.array([x["position"] for x in e], float)
        steps = np.abs(np.diff(x))
        found = set(_run_dropouts(t, x, float(steps[steps > 0].min())).tolist())
        minus_pi = set(np.flatnonzero(np.abs(x + math.pi) < 0.01).tolist())
        assert found == minus_pi, (f.name, found, minus_pi)
        hits += len(found)
    assert hits > 0


@pytest.mark.parametrize("samples_per_period", [2.2, 2.5, 3.0, 4.0, 6.0, 12.0])
def test_fast_motion_that_turns_around_is_no_dropout(samples_per_period):
    """A harmonic drive released from its twist at 250 Hz, ringing at 2.2–12 samples per
    period with ~20–300 encoder steps per sample, quantized: every sample between two
    neighbours that agree (a turnaround) is as far from them as the largest one-sample
    change, never ten times it."""
    q = 2 * math.pi / 4000
    t = np.arange(1500) / 250.0
    f = 250.0 / samples_per_period
    for phase in np.linspace(0.0, 2 * math.pi, 9):
        x = 0.3 + 0.5 * np.exp(-t / 0.5) * np.cos(2 * math.pi * f * t + phase)
        x[:100] = x[100]  # held, then released
        x = np.round(x / q) * q
        assert _run_dropouts(t, x, q).size == 0


def test_flicker_of_a_still_run_is_no_dropout_but_minus_pi_is():
    q = 2 * math.pi / 4096
    t = np.arange(400) * 0.01
    x = np.full(t.size, 0.2)
    x[200] += q  # an encoder flickers by one count and back
    assert _run_dropouts(t, x, q).size == 0
    x[300] = -math.pi
    assert _run_dropouts(t, x, q).tolist() == [300]
