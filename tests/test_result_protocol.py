"""One result protocol (issue 35 item 7): every result type — :class:`hdid.FitResult`,
:class:`hdid.DrivenFitResult`, :class:`hdid.Diagnosis`, :class:`hdid.PosteriorResult` and
:class:`hdid.DesignResult` — has ``report()``, ``to_dict()`` (strict JSON), ``save(path)``, the
classmethod ``load(path)`` and ``plot(ax=None)`` returning the axes drawn into.

Each is tested by a round trip: save → load gives the same ``to_dict()`` and the same
``report()``, and the loaded object still plots. Three computations feed all of it
(module-scoped): a diagnosis of a shipped log with one candidate (its base fit is the
FitResult and the start of a small SMC posterior), and a driven fit of a short piece of
the shipped driven log. The DesignResult is built by hand (no computation), with every
kind of value its file must carry back: NaN, ±inf, a failed candidate, the check.
"""

from __future__ import annotations

import inspect
import json
import math
from pathlib import Path

import pytest

import hdid
from hdid._errors import HdidError

ROOT = Path(__file__).resolve().parents[1]
FREE = ROOT / "data" / "synthetic" / "csf8_paper.csv"
DRIVEN = ROOT / "data" / "synthetic" / "driven_csf8.csv"


TYPES = ["FitResult", "DrivenFitResult", "Diagnosis", "PosteriorResult", "DesignResult"]


@pytest.mark.parametrize("name", TYPES)
def test_every_result_type_has_the_protocol(name):
    cls = getattr(hdid, name)
    for method in ("report", "to_dict", "save", "plot"):
        assert callable(getattr(cls, method, None)), f"{name}.{method}"
    assert isinstance(inspect.getattr_static(cls, "load"), classmethod), f"{name}.load"
    ax = inspect.signature(cls.plot).parameters["ax"]
    assert ax.kind is inspect.Parameter.KEYWORD_ONLY and ax.default is None, name


@pytest.fixture(scope="module")
def diagnosis():
    """A diagnosis of the shipped paper log with one candidate (one refit besides the base)."""
    return hdid.diagnose(str(FREE), candidates=["backlash"])


@pytest.fixture(scope="module")
def driven(tmp_path_factory):
    """A driven fit of a short piece of the shipped driven log (run 1, its first 0.4 s:
    two 0.2 s windows), positional order given (no order scan)."""
    import pandas as pd

    df = pd.read_csv(DRIVEN)
    log = tmp_path_factory.mktemp("driven") / "driven_short.csv"
    df[(df["run"] == df["run"].iloc[0]) & (df["time"] < 0.4)].to_csv(log, index=False)
    return hdid.fit_driven(str(log), order=2)


def _json(d: dict) -> dict:
    """``d`` as strict JSON reads it back (a NaN or infinity left in would raise here)."""
    return json.loads(json.dumps(d, allow_nan=False))


def _round_trip(result, path: Path, cls, kind: str):
    """Save, check the file against its schema, load; same JSON and report."""
    from importlib.resources import files

    import jsonschema

    result.save(path)
    written = json.loads(path.read_text())
    schema = json.loads(files("hdid").joinpath(f"schema/{kind}.schema.json").read_text())
    errors = sorted(jsonschema.Draft202012Validator(schema).iter_errors(written), key=str)
    assert not errors, errors[0]
    loaded = cls.load(path)
    assert type(loaded) is cls
    assert _json(loaded.to_dict()) == _json(result.to_dict())
    assert loaded.report() == result.report()
    assert {k: v for k, v in written.items() if k in loaded.to_dict()} == _json(loaded.to_dict())
    # a loaded result saves the same file again
    loaded.save(path.with_name("again.json"))
    assert json.loads(path.with_name("again.json").read_text()) == written
    return loaded


def _plots(result, ax_kind):
    """``plot()`` draws into the Axes it is given and returns it, and makes its own figure
    without one (bare: no backend is touched); nothing is saved."""
    from matplotlib.figure import Figure

    with hdid.bare_figures():
        made = result.plot()
    first = made if hasattr(made, "plot") else made.ravel()[0]
    assert first.has_data()
    ax = Figure().subplots()
    assert result.plot(ax=ax) is ax and ax.has_data(), ax_kind


def test_fit_result_round_trip(diagnosis, tmp_path):
    fit = diagnosis.base
    assert isinstance(fit, hdid.FitResult)
    loaded = _round_trip(fit, tmp_path / "fit.json", hdid.FitResult, "fit")
    _plots(fit, "fit")
    _plots(loaded, "loaded fit")  # without the log: the runs' RMS against the floor
    with pytest.raises(HdidError, match="loaded from a file"):
        loaded.predict()


def test_driven_fit_result_round_trip(driven, tmp_path):
    loaded = _round_trip(driven, tmp_path / "driven.json", hdid.DrivenFitResult, "driven")
    assert loaded.joint.positional.order == driven.joint.positional.order == 2
    assert loaded.values == driven.values
    # the positional error comes back as a function, not only its coefficients
    import numpy as np

    theta = np.linspace(0.0, 2 * np.pi, 16)
    assert np.allclose(np.asarray(loaded.joint.positional(theta)),
                       np.asarray(driven.joint.positional(theta)), rtol=1e-12, atol=0)
    _plots(driven, "driven")
    _plots(loaded, "loaded driven")  # without the log: the positional error
    with pytest.raises(HdidError, match="loaded from a file"):
        loaded.plot_kinematic_error()


def test_diagnosis_round_trip(diagnosis, tmp_path):
    loaded = _round_trip(diagnosis, tmp_path / "diagnosis.json", hdid.Diagnosis, "diagnose")
    assert [c.key for c in loaded.candidates] == [c.key for c in diagnosis.candidates]
    assert loaded.base.model.effect_names == diagnosis.base.model.effect_names
    _plots(diagnosis, "diagnosis")
    _plots(loaded, "loaded diagnosis")
    ax = loaded.plot_ladder()  # the other figure reads the file's numbers too
    assert ax.has_data()


def test_each_load_refuses_the_others_file(diagnosis, driven, posterior, designed, tmp_path):
    """A file of one kind given to another type's load: one line naming the file."""
    files = {"fit": tmp_path / "f.json", "driven": tmp_path / "d.json",
             "diagnose": tmp_path / "g.json", "posterior": tmp_path / "p.nc",
             "design": tmp_path / "e.json"}
    diagnosis.base.save(files["fit"])
    driven.save(files["driven"])
    diagnosis.save(files["diagnose"])
    posterior.save(files["posterior"])
    designed.save(files["design"])
    for cls, own in ((hdid.FitResult, "fit"), (hdid.DrivenFitResult, "driven"),
                     (hdid.Diagnosis, "diagnose"), (hdid.PosteriorResult, "posterior"),
                     (hdid.DesignResult, "design")):
        for kind, path in files.items():
            if kind != own:
                with pytest.raises(HdidError, match=str(path)) as err:
                    cls.load(path)
                assert "\n" not in str(err.value), (cls.__name__, kind)


@pytest.fixture(scope="module")
def posterior(diagnosis):
    """A deliberately small tempered SMC from the diagnosis's base fit (plumbing, not
    convergence: the round trip must hold for any posterior)."""
    from hdid._posterior.smc import sample_smc

    return sample_smc(diagnosis.base, n_particles=60, modes="fit", seed=2, max_rounds=12)


def test_posterior_result_round_trip(posterior, tmp_path):
    post, cls = posterior, hdid.PosteriorResult
    path = tmp_path / "posterior.nc"
    post.save(path)
    loaded = cls.load(path)
    assert type(loaded) is cls
    assert _json(loaded.to_dict()) == _json(post.to_dict())
    assert loaded.report() == post.report()
    # given the live fit it was sampled from, the same again
    assert _json(cls.load(path, fit=post.fit).to_dict()) == _json(post.to_dict())
    _plots(post, "posterior")
    _plots(loaded, "loaded posterior")


@pytest.fixture(scope="module")
def designed():
    """A DesignResult built by hand (what :func:`hdid.design` returns, without computing
    it): an undetermined std (inf) beside one not computed (NaN), scores of -inf (a target
    undetermined now, determined by the candidate), NaN and +inf (a failed candidate), a
    separation with one direction not evaluated, and a check of one fit whose spread does
    not exist (NaN) and whose truth lacks a quantity. The report prints inf and NaN
    differently ("undet." / "n/a"), so a file that wrote both as null without saying
    which would not read back to the same report."""
    from hdid._design._candidates import Experiment
    from hdid._design._check import CheckResult
    from hdid._design._fisher import Prediction

    inf, nan = math.inf, math.nan

    def exp(name, amps, rate=250.0):
        return Experiment(name=name, amplitudes=amps, rate=rate, duration=0.4, hold=0.04,
                          resolution=2 * math.pi / 4000, note=f"{name}: by hand",
                          releases=tuple(0.041 + 0.001 * k for k in range(len(amps))))

    paper = (0.157, -0.157, 0.157, -0.157)
    band, f_n = "stick_band_halfwidth_rad", "natural_frequency_hz"
    now = Prediction(exp("this log", paper), std={"k1": 25.0, "tau_c": inf},
                     std_data={"k1": 25.0, "tau_c": inf}, prior_ratio={"tau_c": nan},
                     derived_std={band: 0.014, f_n: nan}, names=("k1", "tau_c"),
                     n_effective=1600.0, sigma=4.5e-4,
                     honesty=["tau_c: log-normal spread (std > 30 % of the value)"])
    more = Prediction(exp("repeats x2", paper * 2), std={"k1": 12.0, "tau_c": 1.1e-3},
                      std_data={"k1": 12.5, "tau_c": 1.2e-3}, prior_ratio={"tau_c": 0.97},
                      derived_std={band: 0.007, f_n: 0.4}, names=("k1", "tau_c"),
                      n_effective=3200.0, sigma=4.5e-4, separation=(3.5, nan),
                      separation_kind="upper bound")
    fast = Prediction(exp("1 kHz", paper, rate=1000.0), std={"k1": 20.0, "tau_c": 2e-3},
                      derived_std={band: 0.02, f_n: 0.5}, names=("k1", "tau_c"))
    failed = Prediction(exp("bigger", (0.3, -0.3)), error="simulation failed: by hand")
    check = CheckResult(experiment="this log", n_logs=3, n_fitted=1,
                        mean={"tau_c": 2.4e-3, band: nan}, spread={"tau_c": nan, band: nan},
                        predicted={"tau_c": inf, band: 0.014}, truth={"tau_c": 2.5e-3},
                        failures=["log 2: no fit converged (by hand)"], above_floor=1,
                        seconds=12.0)
    return hdid.DesignResult(
        source="by_hand.csv", criterion="targets", targets=("tau_c", band),
        values={"k1": 940.0, "tau_c": 2.5e-3}, derived={band: 0.036, f_n: nan},
        predictions=[now, more, fast, failed],
        ranking=[(1, -inf), (0, 0.0), (2, nan), (3, inf)], noise_rad=0.0, check=check,
        warnings=["by hand: not a computed design"], wall_time_s=nan)


def test_design_result_round_trip(designed, tmp_path):
    """Save → load: the same JSON and report (every NaN and infinity back as itself, not
    as whatever one null reads back as), and a plot of the same bars."""
    import numpy as np
    from matplotlib.figure import Figure

    report = designed.report()
    assert "undet." in report and "n/a" in report  # both kinds of non-finite are printed
    path = tmp_path / "design.json"
    loaded = _round_trip(designed, path, hdid.DesignResult, "design")
    written = json.loads(path.read_text())
    assert written["non_finite"]["/candidates/0/std/tau_c"] == "inf"
    assert written["non_finite"]["/candidates/0/derived_std/natural_frequency_hz"] == "nan"
    assert written["non_finite"]["/ranking/0/score"] == "-inf"
    assert math.isnan(loaded.wall_time_s) and math.isnan(loaded.check.spread["tau_c"])
    assert loaded.ranking[0][1] == -math.inf and math.isnan(loaded.ranking[2][1])
    assert "stick_band_halfwidth_rad" not in loaded.check.truth  # absent stays absent
    _plots(designed, "design")
    _plots(loaded, "loaded design")
    widths = []
    for r in (designed, loaded):
        ax = Figure().subplots()
        r.plot(ax=ax)
        widths.append([p.get_width() for p in ax.patches])
    np.testing.assert_array_equal(widths[0], widths[1])  # the same bars, NaN where absent


def test_design_load_refuses_a_wrong_file_in_one_line(designed, tmp_path):
    """Another kind, a newer layout, a missing field, not JSON, no file: one line naming
    the file and what to do."""
    good = tmp_path / "good.json"
    designed.save(good)
    d = json.loads(good.read_text())
    cases = {
        "fit.json": ({"model": {}, "parameters": {}}, "FitResult.load"),
        "newer.json": ({**d, "schema_version": 99}, "upgrade hdid"),
        "short.json": ({k: v for k, v in d.items() if k != "candidates"},
                       "without the field 'candidates'.*write it again"),
        "list.json": ([d], "not a design file"),
    }
    for name, (content, match) in cases.items():
        (tmp_path / name).write_text(json.dumps(content))
    (tmp_path / "text.json").write_text("not json")
    cases["text.json"] = (None, "cannot read it as a design JSON")
    cases["missing.json"] = (None, "no such file")
    for name, (_, match) in cases.items():
        with pytest.raises(HdidError, match=match) as err:
            hdid.DesignResult.load(tmp_path / name)
        assert str(tmp_path / name) in str(err.value) and "\n" not in str(err.value), name
