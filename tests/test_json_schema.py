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
    import hdid._fit

    tmp = tmp_path_factory.mktemp("schema")
    out = tmp / "fit.json"
    real, kept = hdid._fit.fit, []

    def keep(*args, **kwargs):  # the CLI's own fit, kept for the library-level tests
        kept.append(real(*args, **kwargs))
        return kept[-1]

    mp = pytest.MonkeyPatch()
    mp.setattr(hdid._fit, "fit", keep)
    try:
        res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--starts", "2", "--fix", "delta=1",
                                        "-q", "--json", str(out)])
    finally:
        mp.undo()
    assert res.exit_code == 0, res.output
    return json.loads(out.read_text()), kept[0], tmp


def _validator():
    from hdid._saved import schema

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
    from hdid._saved import finite

    assert finite(again.to_dict()) == finite(result.to_dict())
    assert again.model.values()["k1"] == pytest.approx(result.values["k1"], rel=1e-15)
    with pytest.raises(hdid.HdidError, match="refit"):
        again.plot()


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
    import hdid._fit

    _, result, _ = fitted
    seen = {}

    def spy(log, model=None, **kw):
        seen["model"], seen["kw"] = model, kw
        return result

    monkeypatch.setattr(hdid._fit, "fit", spy)
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
    assert result.plot(axes=ax) is fig
    assert len(ax.lines) >= 2 * len(result.runs)
    fig, axes = plt.subplots(1, 3)
    with pytest.raises(hdid.HdidError, match=r"\(2, 4\)"):
        result.plot(axes=axes)
    plt.close("all")


def test_fit_plot_band_centred_and_legend(fitted):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    _, result, _ = fitted
    fig = result.plot()
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

    from hdid._plot import RUNS_PER_ROW, _fit_axes

    fig, axes = _fit_axes(plt, 10)
    assert axes.shape == (2, 10)
    width, height = fig.get_size_inches()
    assert width <= 3.2 * RUNS_PER_ROW + 1 and height > 5.2 * 2  # 3 rows of 4, 4, 2
    plt.close("all")
