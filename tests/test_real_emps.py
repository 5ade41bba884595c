"""The shipped real log (issue 16): EMPS, a ball-screw positioning axis in SI units.

``hdid fit data/real/emps/train.csv --ratio 1 --add torque_offset`` — no other option —
must land near the benchmark authors' IDIM-LS estimates and predict the validation log
(never fitted) at least as well as they do. IDIM-LS is itself an estimate (an inverse
model on filtered derivatives), not the truth: the tolerances are the issue's (5 % on
the mass, 10 % on the friction coefficients, 25 % on the few-newton offset).
"""

from __future__ import annotations

import importlib.util
import json
import math
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from synthetic import ROOT

EMPS = ROOT / "data" / "real" / "emps"
_spec = importlib.util.spec_from_file_location("hdid_emps_compare", EMPS / "compare.py")
COMPARE = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(COMPARE)
IDIM_LS = COMPARE.IDIM_LS
TOLERANCE = {"inertia": 0.05, "c_v": 0.10, "tau_c": 0.10, "tau_0": 0.25}


# One CLI fit of 24 841 samples (two fits inside: Coulomb, then Stribeck): minutes.
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def emps_fit(tmp_path_factory):
    out = tmp_path_factory.mktemp("emps") / "fit.json"
    proc = subprocess.run(
        [sys.executable, "-m", "hdid.cli", "fit", str(EMPS / "train.csv"), "--ratio", "1",
         "--add", "torque_offset", "--json", str(out)],
        capture_output=True, text=True, cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(out.read_text()), proc.stdout


def test_shipped_csv_is_small_si_and_uniform():
    for name in ("train.csv", "validate.csv"):
        path = EMPS / name
        assert path.stat().st_size < 2_000_000
        d = pd.read_csv(path)
        assert list(d.columns) == ["time", "theta", "motor_torque"]
        assert len(d) == 24841
        np.testing.assert_allclose(np.diff(d["time"]), 1e-3, atol=1e-9)
        # metres of a 0.25 m ball-screw stroke, newtons of a 35 N/V drive at ±10 V
        assert 0.2 < np.ptp(d["theta"]) < 0.3
        assert 50 < np.max(np.abs(d["motor_torque"])) < 400


def test_emps_fit_matches_idim_ls_and_predicts_validation_as_well(emps_fit):
    fit, report = emps_fit
    p = fit["parameters"]
    for name, ref in IDIM_LS.items():
        value, std = p[name]["value"], p[name]["std"]
        assert abs(value / ref - 1) <= TOLERANCE[name], (name, value, ref)
        assert math.isfinite(std) and std > 0, (name, std)
    # The validation log predicted at least as well as with the IDIM-LS parameters, by
    # the authors' own cross-test criterion (relative error of the force the inverse
    # model predicts on DATA_EMPS_PULSES; compare.py, criterion 1; measured 5.88 % vs
    # 6.00 %). No margin.
    ours = {k: v["value"] for k, v in p.items()}
    e_ours = COMPARE.inverse_model_error(EMPS / "validate.csv", ours)
    e_idim = COMPARE.inverse_model_error(EMPS / "validate.csv", IDIM_LS)
    assert e_ours <= e_idim, (e_ours, e_idim)
    # The report is honest about the Stribeck law the data do not support, about the
    # model error far above the encoder floor, and it fitted the nested Coulomb case.
    assert any("tau_s" in w or "v_s" in w for w in fit["warnings"]), fit["warnings"]
    assert any("quantization floor" in w for w in fit["warnings"])
    assert "Coulomb friction (tau_c = tau_s) fitted first" in report


def test_conversion_reproduces_the_shipped_csv(tmp_path):
    src = ROOT.parent / "shared" / "data" / "real" / "emps"
    if not (src / "DATA_EMPS.mat").exists():
        pytest.skip("the benchmark's .mat files are not beside the repository")
    spec = importlib.util.spec_from_file_location("hdid_emps_convert", EMPS / "convert.py")
    conv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(conv)
    out = tmp_path / "train.csv"
    conv.convert(src / "DATA_EMPS.mat", out)
    assert out.read_bytes() == (EMPS / "train.csv").read_bytes()
