"""The shipped real log (issue 16): EMPS, a ball-screw positioning axis in SI units.

``hdid fit ../shared/data/real/emps/emps_train.csv --ratio 1 --add torque_offset`` — no
other option —
must land near the benchmark authors' IDIM-LS estimates and predict the validation log
(never fitted) at least as well as they do. IDIM-LS is itself an estimate (an inverse
model on filtered derivatives), not the truth: the tolerances are the issue's (5 % on
the mass, 10 % on the friction coefficients, 25 % on the few-newton offset).

The logs are not kept in this repository: they are read from ``../shared/data/real/emps``
beside it (``data/real/emps/README.md`` says where to get and how to convert them), and
the tests that need them skip, naming that folder, when it is absent.
"""

from __future__ import annotations

import importlib.util
import json
import math

import numpy as np
import pandas as pd
import pytest

from synthetic import ROOT, cli_fit_json

EMPS = ROOT / "data" / "real" / "emps"
DATA = ROOT.parent / "shared" / "data" / "real" / "emps"
TRAIN, PULSES = DATA / "emps_train.csv", DATA / "emps_pulses.csv"
_spec = importlib.util.spec_from_file_location("hdid_emps_compare", EMPS / "compare.py")
COMPARE = importlib.util.module_from_spec(_spec)
_spec.loader.exec_module(COMPARE)
IDIM_LS = COMPARE.IDIM_LS
TOLERANCE = {"inertia": 0.05, "c_v": 0.10, "tau_c": 0.10, "tau_0": 0.25}




def _need(*paths):
    for path in paths:
        if not path.exists():
            pytest.skip(f"{path.name} not in {path.parent} (the EMPS logs stay outside the "
                        "repository; data/real/emps/README.md says how to get them)")


@pytest.fixture(scope="module")
def emps_fit(tmp_path_factory):
    _need(TRAIN)
    out = tmp_path_factory.mktemp("emps") / "fit.json"
    return cli_fit_json(TRAIN, out, "--ratio", "1", "--add", "torque_offset")


def test_emps_csv_is_si_and_uniform():
    _need(TRAIN, PULSES)
    for path in (TRAIN, PULSES):
        d = pd.read_csv(path)
        assert list(d.columns)[:3] == ["time", "theta", "motor_torque"]
        assert len(d) == 24841
        np.testing.assert_allclose(np.diff(d["time"]), 1e-3, atol=1e-9)
        # metres of a 0.25 m ball-screw stroke, newtons of a 35 N/V drive at ±10 V
        assert 0.2 < np.ptp(d["theta"]) < 0.3
        assert 50 < np.max(np.abs(d["motor_torque"])) < 400


def test_no_emps_csv_in_the_repository():
    """Fetched data stay in ../shared: only the project's scripts and README are here."""
    assert sorted(p.name for p in EMPS.iterdir() if p.suffix == ".csv") == []


def test_compare_shooting_with_every_parameter_fixed_runs(tmp_path):
    """``compare.py``'s criterion 2 (a driven fit with every parameter fixed) runs.

    It crashed with ``TracerBoolConversionError`` (the simulator's inertia check called
    ``bool`` on a constant traced under ``jit``). The first 1.5 s of the pulses log keep it
    short; a held IDIM-LS model tracks the ball screw to well under a millimetre (the
    full log gives 3.2e-5 m): a crash or a wild simulation fails.
    """
    _need(PULSES)
    rms = COMPARE.shooting_rms(_pulses_head(tmp_path), IDIM_LS)
    assert math.isfinite(rms) and 0 < rms < 1e-3, rms


@pytest.mark.slow  # one CLI fit of 24 841 samples (Coulomb, then Stribeck): minutes
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
    e_ours = COMPARE.inverse_model_error(PULSES, ours)
    e_idim = COMPARE.inverse_model_error(PULSES, IDIM_LS)
    assert e_ours <= e_idim, (e_ours, e_idim)
    # The report is honest about the Stribeck law the data do not support, about the
    # model error far above the encoder floor, and it fitted the nested Coulomb case.
    assert any("tau_s" in w or "v_s" in w for w in fit["warnings"]), fit["warnings"]
    assert any("quantization floor" in w for w in fit["warnings"])
    assert "Coulomb friction (tau_c = tau_s) fitted first" in report


def _pulses_head(folder):
    """The first 1.5 s of the validation log (what the shooting test above runs on: the
    same length, so the same compiled programs)."""
    part = folder / PULSES.name
    d = pd.read_csv(PULSES)
    d[d["time"] < 1.5].to_csv(part, index=False, float_format="%.10g")
    return part


@pytest.mark.slow  # compare.py to its end on the CLI fit of 24 841 samples
def test_compare_script_runs_to_its_end(emps_fit, tmp_path, capsys):
    """``compare.py``'s own code to its last line: the fit's JSON read, both criteria for
    both parameter sets printed, finite. What the numbers are worth is checked above (the
    fit against IDIM-LS, criterion 1 on the whole validation log; criterion 2's held
    simulation on its first 1.5 s); here the validation log is that same 1.5 s head — a
    crash, a missing key or a NaN anywhere in the script shows on any length, and the
    two shooting fits of the full 24 841 samples took minutes."""
    _need(PULSES)
    fit, _ = emps_fit
    path = tmp_path / "fit.json"
    path.write_text(json.dumps(fit))
    data = tmp_path / "data"
    data.mkdir()
    (data / TRAIN.name).symlink_to(TRAIN)  # only checked to exist: the fit is given
    _pulses_head(data)
    COMPARE.main([str(path), "--data", str(data)])
    out = capsys.readouterr().out
    assert "multiple-shooting position RMS" in out and "nan" not in out, out


def test_conversion_reproduces_the_csv_in_shared(tmp_path):
    _need(DATA / "DATA_EMPS.mat", TRAIN)
    spec = importlib.util.spec_from_file_location("hdid_emps_convert", EMPS / "convert.py")
    conv = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(conv)
    out = tmp_path / "emps_train.csv"
    conv.convert(DATA / "DATA_EMPS.mat", out)
    assert out.read_bytes() == TRAIN.read_bytes()
