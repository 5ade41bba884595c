"""Batch identification: one row per log, bad files reported in their row."""

from __future__ import annotations

import math
from pathlib import Path

import pandas as pd
from click.testing import CliRunner

import hdid
from hdid.cli import main

EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"


def test_fit_many_reports_bad_files_in_their_row(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,theta\n0,abc\n")
    table = hdid.fit_many([EXAMPLE, bad, tmp_path / "missing.csv"])
    assert list(table["log"]) == [str(EXAMPLE), str(bad), str(tmp_path / "missing.csv")]
    ok, wrong, missing = table.itertuples()
    assert pd.isna(ok.error) and math.isfinite(ok.k1) and ok.result is not None
    assert ok.result.parameters["k1"].value == ok.k1  # the per-log result stays available
    assert "row 2" in wrong.error and "theta" in wrong.error and wrong.result is None
    assert "missing.csv" in missing.error


def test_cli_summary(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,theta\n0,1\n")
    out = tmp_path / "summary.csv"
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), str(bad), "--summary", str(out), "-q"])
    assert res.exit_code == 0, res.output

    table = pd.read_csv(out)
    assert len(table) == 2 and table["error"].isna().tolist() == [True, False]
    assert {"k1", "k1_std", "stick_band_halfwidth_rad", "rms_residual_rad", "warnings"} <= set(table)
