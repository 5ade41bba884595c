"""Results that can be reused (issue 18 item 5): the fit JSON follows the schema shipped
with the package, carries what a reuse needs (model structure, correlation/covariance,
version, input checksum, options), reloads to the same result and re-simulates."""

from __future__ import annotations

import hashlib
import json
from importlib.metadata import version
from pathlib import Path

import numpy as np
import pytest
from click.testing import CliRunner

import hdid
from hdid.cli import main

jsonschema = pytest.importorskip("jsonschema")

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "data" / "synthetic" / "csf8_paper.csv"


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    """One CLI fit of the example (2 starts: cheap) and its JSON, and the same fit from the
    library as a live FitResult."""
    import hdid._fitting._fit

    tmp = tmp_path_factory.mktemp("schema")
    out = tmp / "fit.json"
    real, kept = hdid._fitting._fit.fit, []

    def keep(*args, **kwargs):  # the CLI's own fit, kept for the library-level tests
        kept.append(real(*args, **kwargs))
        return kept[-1]

    mp = pytest.MonkeyPatch()
    mp.setattr(hdid._fitting._fit, "fit", keep)
    try:
        res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--starts", "2", "--fix", "delta=1",
                                        "-q", "--json", str(out)])
    finally:
        mp.undo()
    assert res.exit_code == 0, res.output
    # the CLI's fit returns last: fit() calls itself for the nested Coulomb check first
    return json.loads(out.read_text()), kept[-1], tmp


def _validator():
    from hdid._results._saved import schema

    s = schema()  # read through importlib.resources: the file ships with the package
    jsonschema.Draft202012Validator.check_schema(s)
    return jsonschema.Draft202012Validator(s), s


def test_cli_json_follows_the_shipped_schema(fitted):
    data, _, _ = fitted
    validator, s = _validator()
    errors = sorted(validator.iter_errors(data), key=str)
    assert not errors, errors[0]
    # Every field the JSON has is written down in the schema.
    assert set(data) <= set(s["properties"]), set(data) - set(s["properties"])


@pytest.mark.parametrize("breakage", ["k1 text", "no model", "bad sha", "ragged matrix"])
def test_schema_rejects_broken_json(fitted, breakage):
    data = json.loads(json.dumps(fitted[0]))
    if breakage == "k1 text":
        data["parameters"]["k1"]["value"] = "976"
    elif breakage == "no model":
        del data["model"]
    elif breakage == "bad sha":
        data["input"]["sha256"] = "abc"
    else:
        data["correlation"]["matrix"][0] = "x"
    validator, _ = _validator()
    assert list(validator.iter_errors(data))


def test_json_carries_what_reuse_needs(fitted):
    data, _, _ = fitted
    assert data["hdid_version"] == version("hdid")
    assert data["input"]["sha256"] == hashlib.sha256(EXAMPLE.read_bytes()).hexdigest()
    assert data["options"] == {"starts": 2, "fix": ["delta=1"]}
    model = data["model"]
    assert model["gear_ratio"] == 100.0
    assert [e["name"] for e in model["effects"]] == ["stiffness", "stribeck", "viscous"]
    assert model["effects"][0]["fields"]["k1"] == data["parameters"]["k1"]["value"]
    # correlation: the full symmetric matrix of the free parameters, unit diagonal
    names = data["correlation"]["parameters"]
    assert names == [n for n, p in data["parameters"].items() if not p["fixed"]]
    corr = np.array(data["correlation"]["matrix"], dtype=float)
    assert np.allclose(corr, corr.T) and np.allclose(np.diag(corr), 1.0)
    assert np.all(np.abs(corr) <= 1 + 1e-9)
    # covariance in physical units: its diagonal is the report's std squared
    cov = np.array(data["covariance"]["matrix"], dtype=float)
    std = np.array([data["parameters"][n]["std"] for n in names], dtype=float)
    assert np.allclose(np.sqrt(np.diag(cov)), std, rtol=1e-12)
    assert data["covariance"]["units"][names.index("k1")] == "N m/rad"


def test_save_load_round_trip(fitted, tmp_path):
    _, result, _ = fitted
    path = tmp_path / "fit.json"
    result.save(path)
    again = hdid.FitResult.load(path)
    assert again.report() == result.report()
    from hdid._results._saved import finite

    assert finite(again.to_dict()) == finite(result.to_dict())
    assert again.model.values()["k1"] == pytest.approx(result.values["k1"], rel=1e-15)
    with pytest.raises(hdid.HdidError, match="refit"):
        again.predict()  # the log is not in the file (plot() draws the runs' RMS only)


def test_load_refuses_other_json(tmp_path):
    path = tmp_path / "x.json"
    path.write_text('[{"source": "a.csv", "error": "bad"}]')
    with pytest.raises(hdid.HdidError, match="not the JSON of one hdid fit"):
        hdid.FitResult.load(path)


def test_simulate_from_fit_json(fitted, tmp_path):
    data, result, tmp = fitted
    out = tmp_path / "again.csv"
    res = CliRunner().invoke(main, ["simulate", str(out), "--from", str(tmp / "fit.json")])
    assert res.exit_code == 0, res.output
    log = hdid.read_log(out)
    assert len(log.runs) == len(data["runs"])
    assert log.sample_period == pytest.approx(data["sample_period_s"], rel=1e-9)
    step = 2 * np.pi / 4000
    for run, fit_run in zip(log.runs, data["runs"]):
        # the hold reading is the fitted release angle plus the set-up offset, to a count
        assert abs(run.theta[0] - (fit_run["theta0"] + data["setups"]["A"]["offset"])) <= step
        assert len(run.theta) == fit_run["n_samples"]
    # options given on the command line override the fitted design
    res = CliRunner().invoke(main, ["simulate", str(tmp_path / "two.csv"), "--from",
                                    str(tmp / "fit.json"), "--amplitudes", "0.1,-0.1"])
    assert res.exit_code == 0, res.output
    assert len(hdid.read_log(tmp_path / "two.csv").runs) == 2


def test_start_values_reach_the_fit(fitted, monkeypatch):
    import hdid._fitting._fit

    _, result, _ = fitted
    seen = {}

    def spy(log, model=None, **kw):
        seen["model"], seen["kw"] = model, kw
        return result

    monkeypatch.setattr(hdid._fitting._fit, "fit", spy)
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--start", "k1=1200", "--start", "tau_c=3e-3", "-q"])
    assert res.exit_code == 0, res.output
    assert seen["kw"]["start_from_model"] is True
    assert seen["model"].values()["k1"] == 1200.0 and seen["model"].values()["tau_c"] == 3e-3
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--start", "k9=1"])
    assert res.exit_code == 2 and "no such parameter" in res.stderr


def test_plot_into_one_axes_or_a_clear_error(fitted):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _, result, _ = fitted
    fig, ax = plt.subplots()
    assert result.plot(ax=ax) is ax
    assert len(ax.lines) >= 2 * len(result.runs)
    fig, axes = plt.subplots(1, 3)
    with pytest.raises(hdid.HdidError, match=r"\(2, 4\)"):
        result.plot(ax=axes)
    plt.close("all")


def test_fit_plot_band_centred_and_legend(fitted):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _, result, _ = fitted
    fig = result.plot()[0, 0].figure
    top = fig.axes[0]
    # The stick band is drawn from the spring zero: centred on 0, as in the report.
    band = [p for p in top.patches if p.get_label() == "stick band (fit)"][0]
    y0, y1 = band.get_y(), band.get_y() + band.get_height()
    assert y0 == pytest.approx(-y1, rel=1e-9)
    assert y1 == pytest.approx(result.stick_band_halfwidth_rad, rel=1e-9)
    # and the measured angles of run 1 are from the spring zero too: they start near theta0
    enc = [line for line in top.lines if line.get_label() == "encoder"][0]
    assert abs(enc.get_ydata()[0] - result.runs[0].theta0) < 0.01
    res_ax = fig.axes[1]
    assert res_ax.get_legend() is not None
    assert any("½ count" in t.get_text() for t in res_ax.get_legend().get_texts())
    assert "cropped" in fig._suptitle.get_text()
    plt.close("all")


def test_ten_runs_wrap_into_rows():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from hdid._results._plot import RUNS_PER_ROW, _fit_axes

    fig, axes = _fit_axes(10)
    assert axes.shape == (2, 10)
    width, height = fig.get_size_inches()
    assert width <= 3.2 * RUNS_PER_ROW + 1 and height > 5.2 * 2  # 3 rows of 4, 4, 2
    plt.close("all")


# -- driven and diagnose JSON: the same provenance as the fit JSON (issue 18 item 5) ------

DRIVEN = ROOT / "data" / "synthetic" / "driven_csf8.csv"
SHARED = ("schema_version", "hdid_version", "input", "options", "model", "correlation", "covariance")


def _schema_validator(kind):
    from hdid._results._saved import schema

    s = schema(kind)
    jsonschema.Draft202012Validator.check_schema(s)
    return jsonschema.Draft202012Validator(s), s


@pytest.fixture(scope="module")
def driven_json(tmp_path_factory):
    """A CLI driven fit of a short piece of the shipped driven log (run 1, its first
    0.4 s: two 0.2 s windows, positional order given), with --input-hold given."""
    import pandas as pd

    tmp = tmp_path_factory.mktemp("driven")
    df = pd.read_csv(DRIVEN)
    log = tmp / "driven_short.csv"
    df[(df["run"] == df["run"].iloc[0]) & (df["time"] < 0.4)].to_csv(log, index=False)
    out = tmp / "d.json"
    res = CliRunner().invoke(main, ["fit", str(log), "--order", "2", "--input-hold", "zoh",
                                    "-q", "--json", str(out)])
    assert res.exit_code == 0, res.output
    return json.loads(out.read_text()), log


def test_driven_json_follows_its_schema_with_provenance(driven_json):
    data, log = driven_json
    validator, s = _schema_validator("driven")
    errors = sorted(validator.iter_errors(data), key=str)
    assert not errors, errors[0]
    assert set(data) <= set(s["properties"]), set(data) - set(s["properties"])
    assert data["hdid_version"] == version("hdid")
    assert data["input"] == {"path": str(log), "sha256": hashlib.sha256(log.read_bytes()).hexdigest()}
    assert data["inputs"] == [data["input"]]
    assert data["options"] == {"order": 2, "input_hold": "zoh"}
    model = data["model"]
    assert model["gear_ratio"] == 100.0 and model["input_hold"] == "zoh"
    assert model["positional_error_order"] == 2
    assert [e["name"] for e in model["effects"]] == ["stiffness", "stribeck", "viscous"]
    assert model["effects"][0]["fields"]["k1"] == data["parameters"]["k1"]["value"]
    # covariance over the free parameters and positional coefficients: its diagonal is the
    # report's (widened) std squared, and the correlation is its normalised form
    names = data["covariance"]["parameters"]
    free = [n for n, p in data["parameters"].items() if not p["fixed"]]
    assert names[: len(free)] == free
    assert set(names[len(free):]) == set(data["positional_error"]["coefficients"])
    cov = np.array(data["covariance"]["matrix"], dtype=float)
    std = np.array([data["parameters"][n]["std"] if n in data["parameters"]
                    else data["positional_error"]["coefficients"][n]["std"] for n in names], dtype=float)
    ok = np.isfinite(std)
    assert ok.sum() >= len(free) - 2  # the short log still fixes most of them
    assert np.allclose(np.sqrt(np.diag(cov))[ok], std[ok], rtol=1e-9)
    sub = cov[np.ix_(ok, ok)]
    assert np.allclose(sub, sub.T, rtol=1e-9, atol=0)
    corr = np.array(data["correlation"]["matrix"], dtype=float)[np.ix_(ok, ok)]
    assert np.allclose(np.diag(corr), 1.0) and np.all(np.abs(corr) <= 1 + 1e-9)
    assert data["covariance"]["units"][names.index("k1")] == "N m/rad"


@pytest.mark.parametrize("breakage", ["hold", "no covariance", "no inputs"])
def test_driven_schema_rejects_broken_json(driven_json, breakage):
    data = json.loads(json.dumps(driven_json[0]))
    if breakage == "hold":
        data["model"]["input_hold"] = "linear"
    elif breakage == "no covariance":
        del data["covariance"]
    else:
        data["inputs"] = []
    validator, _ = _schema_validator("driven")
    assert list(validator.iter_errors(data))


def test_schemas_share_the_provenance_fields():
    """The provenance fields mean the same in the three files: the driven and diagnose
    schemas define them as the fit schema does (the driven model only adds its keys)."""
    from hdid._results._saved import schema

    fit = schema("fit")["properties"]
    for kind in ("driven", "diagnose"):
        s = schema(kind)
        assert set(SHARED) <= set(s["required"]), kind
        for key in SHARED:
            a, b = json.loads(json.dumps(fit[key])), json.loads(json.dumps(s["properties"][key]))
            a.pop("description", None), b.pop("description", None)
            if key == "model":
                assert set(a["required"]) <= set(b["required"])
                assert {k: v for k, v in b["properties"].items() if k in a["properties"]} == a["properties"]
            else:
                assert a == b, (kind, key)


def test_diagnose_json_has_the_fit_provenance(fitted, tmp_path, monkeypatch):
    """hdid diagnose --json: the base fit's model, correlation and covariance, the input's
    checksum and the options, validated against diagnose.schema.json. The diagnosis
    itself is stubbed (its content is the diagnose tests' business): this is the JSON."""
    import hdid._diagnosis._diagnose
    from hdid._diagnosis._diagnose import Diagnosis
    from hdid._results._residuals import whiteness

    data, result, _ = fitted

    from hdid._diagnosis._excess import FloorCheck, FloorThreshold

    # the rounding floor's block as diagnose writes it (a threshold, and one without)
    t = FloorThreshold("paper", 250.0, 4, 200, 4, 1.5, "test")
    rf = [FloorCheck(30.0, 20.0, 6.0, 36.0, 17, th).to_dict() for th in (t, None)]

    def stub(log, model=None, **kw):
        return Diagnosis(source=str(EXAMPLE), verdict="adequate", summary="stub", base=result,
                         candidates=[], whiteness_before=whiteness(result), notes=[],
                         ladder=[], floor_rad=result.quantization_floor_rad,
                         rounding_floor=rf.pop(0))

    monkeypatch.setattr(hdid._diagnosis._diagnose, "diagnose", stub)
    validator, _ = _schema_validator("diagnose")
    for i in range(2):
        out = tmp_path / f"diag{i}.json"
        res = CliRunner().invoke(main, ["diagnose", str(EXAMPLE), "--fix", "delta=1", "-q",
                                        "--json", str(out)])
        assert res.exit_code == 0, res.output
        diag = json.loads(out.read_text())
        errors = sorted(validator.iter_errors(diag), key=str)
        assert not errors, errors[0]
        assert diag["rounding_floor"]["chi2_over_floor"] == 1.5
    broken = json.loads(json.dumps(diag))
    broken["rounding_floor"]["floor"] = "20"
    assert list(validator.iter_errors(broken))  # the block is checked, not only allowed
    assert diag["input"]["sha256"] == hashlib.sha256(EXAMPLE.read_bytes()).hexdigest()
    assert diag["options"] == {"fix": ["delta=1"]}
    assert diag["hdid_version"] == version("hdid")
    for key in ("model", "correlation", "covariance"):
        assert diag[key] == data[key], key
    # every key the diagnosis writes is declared in the schema (it allows others, so a
    # validation alone would not notice an undeclared one)
    schema = json.loads((Path(hdid.__file__).parent / "schema" / "diagnose.schema.json").read_text())
    assert set(diag) <= set(schema["properties"]), set(diag) - set(schema["properties"])
    assert diag["verdict"] == "adequate"  # the diagnosis's own fields are kept


def test_load_refuses_a_driven_json_in_one_line(driven_json, tmp_path):
    """A driven fit's JSON has a model and parameters too: FitResult.load and
    simulate --from must say what it is, not fail on a missing field."""
    data, _ = driven_json
    path = tmp_path / "d.json"
    path.write_text(json.dumps(data))
    with pytest.raises(hdid.HdidError, match="the JSON of a driven fit"):
        hdid.FitResult.load(path)
    res = CliRunner().invoke(main, ["simulate", str(tmp_path / "x.csv"), "--from", str(path)])
    assert res.exit_code == 2 and len(res.stderr.strip().splitlines()) == 1, res.output
    assert "the JSON of a driven fit" in res.stderr
    assert not (tmp_path / "x.csv").exists()


def test_every_shipped_schema_is_reachable_through_schema():
    """Every ``hdid/schema/<kind>.schema.json`` the package ships loads through
    ``schema(kind)`` (docs/json.md promises it); "design" was missing from the list once."""
    from importlib.resources import files

    from hdid._results._saved import SCHEMA_KINDS, schema

    shipped = {p.name.removesuffix(".schema.json") for p in files("hdid").joinpath("schema").iterdir()
               if p.name.endswith(".schema.json")}
    assert shipped == set(SCHEMA_KINDS)
    for kind in shipped:
        jsonschema.Draft202012Validator.check_schema(schema(kind))
