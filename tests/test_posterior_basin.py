"""Never sample around a poorer basin (issue 34, item 1): a fit above 1.5× the quantization
floor goes through the fit's limit and restart checks first, and if it stays above, the
posterior says in one line — before any sampling, first in its warnings and at the top of
its report — that its intervals would describe the wrong basin."""

from __future__ import annotations

import json
import math
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

import hdid
from hdid._posterior.basin import BASIN_FACTOR, basin_check
from hdid.cli import main

PAPER = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"


def _hidden_ripple_log(path: Path, steps: float = 3.0, wavelength: float = 0.05) -> Path:
    """The shipped paper log with a hidden effect no model of hdid has: a reading error
    periodic in the angle, ``steps``·q·sin(2πθ/λ), λ = 0.05 rad (several periods over the
    ±0.17 rad swings), re-rounded to the 4000-count encoder grid. Holds and rests read a
    constant shift (they stay still runs' constant readings). Its RMS over a swing is about
    ``steps/√2`` = 2.1 steps against the floor's 0.29, and a smooth ring-down cannot
    follow a ripple of wavelength ≪ its amplitude: every optimum of the model stays far
    above 1.5× the floor (measured 3.6× after the fit's limit checks)."""
    df = pd.read_csv(PAPER)
    q = 2 * np.pi / 4000
    th = df["theta"].to_numpy()
    df["theta"] = np.round((th + steps * q * np.sin(2 * np.pi * th / wavelength)) / q) * q
    df.to_csv(path, index=False, float_format="%.12g")
    return path


@pytest.fixture(scope="module")
def ripple_log(tmp_path_factory):
    return _hidden_ripple_log(tmp_path_factory.mktemp("basin") / "ripple.csv")


def test_cli_posterior_never_reports_intervals_without_the_statement(ripple_log, tmp_path):
    """`hdid fit --posterior` on a log that ends in a poorer basin: the statement is printed
    before the posterior's first interval, leads the report and the JSON's warnings, and the
    JSON records the residual against the floor (above 1.5× after the checks)."""
    out = tmp_path / "fit.json"
    res = CliRunner().invoke(main, ["fit", str(ripple_log), "--posterior", "--steps", "100",
                                    "--json", str(out)])
    assert res.exit_code == 0, res.output
    text = res.output
    first_interval = text.index("posterior (median")
    statement = text.index("WRONG BASIN")
    assert statement < first_interval  # said before any interval is reported
    assert text.count("intervals below would describe the wrong basin") >= 2  # stderr + report
    d = json.loads(out.read_text())
    diag = d["posterior_diagnostics"]
    assert diag["warnings"][0].startswith("WRONG BASIN")
    assert diag["basin"]["rms_over_floor"] > BASIN_FACTOR
    assert diag["basin"]["statement"] == diag["warnings"][0]
    assert "\n" not in diag["basin"]["statement"]  # one line
    assert "limit and restart checks" in diag["basin"]["checks"]


def test_checks_run_first_when_the_fit_skipped_them(ripple_log):
    """A fit made without its limit checks (nested=False) above 1.5× the floor: the basin
    check runs them (every limit of the model recorded) before it states anything, and the
    residual it reports is the checked fit's (never above the unchecked one's: the checks
    keep the best optimum)."""
    fit = hdid.fit(ripple_log, nested=False, n_starts=2)
    assert not fit.limits
    before = fit.rms_residual_rad / fit.quantization_floor_rad
    assert before > BASIN_FACTOR
    new, check = basin_check(fit, echo=False)
    assert {r["limit"] for r in new.limits} == {"coulomb", "no_friction", "no_cubic"}
    assert check.checks == "the limit and restart checks run now"
    assert check.rms_over_floor <= before * (1 + 1e-9)
    assert check.statement is not None and check.statement.startswith("WRONG BASIN")


def test_at_the_floor_there_is_nothing_to_say():
    """A residual at or below 1.5× the floor: no check, no statement (the stand-in has no
    model: reaching the limits would fail)."""
    fit = SimpleNamespace(rms_residual_rad=1.4 * 1e-3 / math.sqrt(12),
                          quantization_floor_rad=1e-3 / math.sqrt(12), restarted_from=None)
    same, check = basin_check(fit, echo=False)
    assert same is fit and check.statement is None and check.rms_over_floor == pytest.approx(1.4)


def test_cli_posterior_errors_are_one_line_naming_flag_and_argument(tmp_path):
    """No traceback from `--posterior` (issue 34, item 2): the paper log printed with 8
    decimals and a wrong --resolution (1e-7 rad, 15 700× finer than its step), asked for
    fewer walkers than emcee needs — exit 2, one line that names the flag (the library's
    message names the Python argument too; the command line shows the flag alone, issue 35),
    refused before anything is sampled (no basin statement before it)."""
    df = pd.read_csv(PAPER)
    log = tmp_path / "eight.csv"
    df.to_csv(log, index=False, float_format="%.8f")
    for args, needles in ((["--walkers", "4"], ("--walkers = 4", "at least")),
                          (["--prior", "foo=1,0.3"], ("(--prior NAME=VALUE,SD)", "'foo'"))):
        res = CliRunner().invoke(main, ["fit", str(log), "-q", "--resolution", "1e-7",
                                        "--posterior", "--steps", "100", *args])
        assert res.exit_code == 2, (args, res.output)
        line = res.output.strip()
        assert "\n" not in line and "Traceback" not in line, line
        assert all(n in line for n in needles), line


def test_a_log_with_sensor_noise_at_its_noise_is_not_a_wrong_basin():
    """Readings with Gaussian noise of half a step before rounding (after each release; the
    holds as the clamp reads them): the fit's residual is at that noise, about 0.55 step
    RMS, which is 1.9× the quantization floor (0.29 step). The floor is the scatter of the
    readings at rest (the gear is still there: sensor noise alone), so no WRONG BASIN
    statement; the noiseless log of the same plant keeps the quantization floor exactly."""
    from hdid._posterior.basin import noise_floor
    from hdid.reference import logs

    q = 2 * np.pi / logs.COUNTS_PER_REV
    sigma = 0.5 * q
    design = dict(logs.PAPER_DESIGN, seed=11)
    clean, info = logs.make_log(logs.TRUTH_CSF8, **design, return_truth=True)
    noisy = logs.make_log(logs.TRUTH_CSF8, **design, noise_std=sigma)
    release = clean["run"].map({r["run"]: r["t_release"] for r in info["runs"]})
    held = (clean["time"] <= release).to_numpy()
    noisy.loc[held, "theta"] = clean.loc[held, "theta"]
    fit = hdid.fit(noisy, inertia=logs.TRUTH_CSF8["inertia"], nested=False, n_starts=2)
    total = math.sqrt(sigma**2 + q**2 / 12)
    # the rest scatter's estimate: 4 runs' tails, truncated to the flicker of the last
    # reading (a slight underestimate); 25 % holds it to the noise, the quantization floor
    # alone is 48 % below
    assert noise_floor(fit) == pytest.approx(total, rel=0.25)
    assert fit.rms_residual_rad > BASIN_FACTOR * fit.quantization_floor_rad  # the old alarm
    same, check = basin_check(fit, echo=False)
    assert same is fit and check.statement is None
    fit0 = hdid.fit(clean, inertia=logs.TRUTH_CSF8["inertia"], nested=False, n_starts=2)
    assert noise_floor(fit0) == fit0.quantization_floor_rad


#: A stiff gear on the paper design (4 releases of ±0.157 rad read at 250 Hz): k1 13 600
#: N m/rad on 7e-7 kg m² through 100:1 swings at 222 Hz, above the log's 125 Hz Nyquist
#: frequency; light friction rings it down over ~10 periods. (The truth of the SBC's paper
#: seed 36016, rounded: drawn from the default priors, not tuned.)
STIFF = dict(k1=13600.0, k2=6.9e8, tau_c=3.8e-3, tau_s=1.13e-2, v_s=0.99, delta=0.49,
             c_v=2.3e-5, inertia=7e-7)


@pytest.fixture(scope="module")
def stiff_aliased():
    """The stiff gear's quantized log, its noiseless unrounded twin, and its fit as
    ``hdid.fit`` makes it (limit checks included: without them it stays at the swing's
    alias) at the 1 ms substep the log's turning points (~28 Hz) give; the substep is
    given, so the fit's own refit at the substep its swing wants
    (tests/test_fit_substep.py) does not run and the basin check meets the coarse fit."""
    from hdid.reference import logs

    design = dict(logs.PAPER_DESIGN, seed=5)
    df = logs.make_log(STIFF, **design)
    clean, info = logs.make_log(STIFF, **design, quantize=False, return_truth=True)
    return df, clean, info, hdid.fit(df, inertia=STIFF["inertia"], max_substep=1e-3)


def test_a_substep_picked_from_an_aliased_swing_is_refined_before_any_statement(stiff_aliased):
    """The fit picks its RK4 substep from the log's turning points; a swing above Nyquist
    shows its slow alias there (~28 Hz), so the substep is picked for that and RK4's phase
    error over the ring-down leaves readings several steps off at the truth itself: every
    optimum stays above the floor, and the statement blamed a basin or a missing effect.
    The basin check refits at the substep the fitted swing needs (the fit's own rule,
    h·ω ≲ 0.26) and, there at the floor, says nothing; its problem (the one sampled)
    carries the finer substep."""
    from hdid._posterior.basin import substep_wanted

    df, clean, info, fit = stiff_aliased
    q = 2 * np.pi / 4000
    # the cause: at the truth, hdid's simulation against the reference's noiseless readings
    model = hdid.Model.default().replace(**{k: v for k, v in STIFF.items() if k != "inertia"},
                                         inertia=STIFF["inertia"])

    def worst_gap(h):  # encoder steps
        return max(float(np.max(np.abs(np.asarray(hdid.simulate(
            model, g.time.to_numpy(), r["theta0"], r["t_release"], max_substep=h))
            - (g.theta.to_numpy() - r["offset"])))) / q
            for r in info["runs"] for g in [clean[clean.run == r["run"]]])

    h = substep_wanted(fit)
    assert h is not None and h < fit.problem.max_substep
    # off by more than a step at the fit's substep (no fit reaches the floor), within
    # rounding (half a step) at the one the fitted swing asks for
    assert worst_gap(fit.problem.max_substep) > 1.0
    assert worst_gap(h) < 0.5
    assert fit.rms_residual_rad > BASIN_FACTOR * fit.quantization_floor_rad
    new, check = basin_check(fit, df, echo=False)
    assert check.statement is None, check.statement
    assert check.rms_over_floor <= BASIN_FACTOR and "substep" in check.checks
    assert new.problem.max_substep == h
    assert check.unchecked is None  # the log was at hand: the refit ran
    assert substep_wanted(new) is None  # the refit is at the substep its own swing asks for


def test_at_the_floor_only_a_clearly_under_resolved_swing_is_refined():
    """At the floor the basin check refits finer only where the fit's substep under-resolves
    its fitted swing by more than half an octave past ``hdid.fit``'s own rule (h·ω above
    AT_FLOOR_HW): a 1 ms substep for a 150 Hz swing (h·ω 0.94, an aliased paper log's fit)
    asks for the rule's 0.25 ms; the same fit at 0.5 ms for a 60 Hz swing (h·ω 0.19, the
    rule's own centre) is left as it is, as is any fit whose frequency is not known. Above
    the floor any finer substep of the rule is asked for (60 Hz at 1 ms: h·ω 0.38)."""
    from hdid._posterior.basin import AT_FLOOR_HW, substep_wanted

    def stand_in(f_hz, h, k2=0.0):  # 4 runs released at 0.15 rad, decaying to rest
        k1 = (2 * math.pi * f_hz) ** 2 * 7e-7 * 100**2
        th = np.tile(0.15 * np.cos(np.linspace(0, 20, 50)) * np.exp(-np.linspace(0, 5, 50)), (4, 1))
        w = np.ones_like(th)
        w[:, :10] = 0.0  # the first swings unweighted (a paper log's weighted readings span less)
        prob = SimpleNamespace(theta=th, weight=w, hold=th[:, 0], max_substep=h)
        return SimpleNamespace(problem=prob,
                               derived={"natural_frequency_hz": (f_hz, 0.0)},
                               parameters={"k1": SimpleNamespace(value=k1),
                                           "k2": SimpleNamespace(value=k2)},
                               model=SimpleNamespace(ratio=100.0))

    assert 1e-3 * 2 * math.pi * 150 > AT_FLOOR_HW
    assert substep_wanted(stand_in(150.0, 1e-3), at_floor=True) == 2.5e-4
    assert substep_wanted(stand_in(60.0, 5e-4), at_floor=True) is None
    assert substep_wanted(stand_in(60.0, 5e-4)) is None
    assert substep_wanted(stand_in(55.0, 1e-3), at_floor=True) is None  # h·ω 0.35: within
    assert substep_wanted(stand_in(60.0, 1e-3)) == 5e-4
    assert substep_wanted(stand_in(math.nan, 1e-3), at_floor=True) is None
    # a hardening spring swings the 0.15 rad release at f0·√(1 + ¾·k2·A²/k1), A = 1.5 mrad at
    # the spring: 45 Hz → 88 Hz at k2 = 2.78·k1/(¾·A²) (SBC seed 36025's fit at 1 ms: h·ω 0.55)
    k1 = (2 * math.pi * 45.0) ** 2 * 7e-3
    assert substep_wanted(stand_in(45.0, 1e-3, k2=2.78 * k1 / (0.75 * 1.5e-3**2)),
                          at_floor=True) == 2.5e-4
    assert substep_wanted(stand_in(45.0, 1e-3), at_floor=True) is None  # linear: h·ω 0.28


def _no_log_stand_in(rms_over_floor, **kw):
    """A fit of a DataFrame (``source`` None: no file to reread) that did not run its limit
    checks (``limits`` empty), of the default model; its residual ``rms_over_floor`` × the
    quantization floor of a 4000-count encoder."""
    q = 2 * math.pi / 4000
    fields = dict(rms_residual_rad=rms_over_floor * q / math.sqrt(12),
                  quantization_floor_rad=q / math.sqrt(12), restarted_from=None, problem=None,
                  model=hdid.Model.default(), parameters={}, source=None, limits=[],
                  derived={})
    fields.update(kw)
    return SimpleNamespace(**fields)


def test_a_needed_check_without_the_log_says_so_in_the_warnings():
    """A fit of a DataFrame has no file for the basin check to refit from: above the floor
    (the limit checks needed, not run) or at it with a substep that does not resolve its
    fitted swing (150 Hz at 1 ms, h·ω 0.94), the check cannot run without ``log=``, and
    the result's warnings must say so and name the fix, not the JSON's ``basin.checks``
    alone. A fit at the floor whose substep resolves its swing needs nothing: no line."""
    fit = _no_log_stand_in(3.0)  # 3× the floor: above BASIN_FACTOR, the limit checks needed
    same, check = basin_check(fit, echo=False)
    assert same is fit and check.statement.startswith("WRONG BASIN")
    assert check.unchecked.startswith("BASIN NOT CHECKED")
    assert "pass log= (the DataFrame) to sample_posterior" in check.unchecked
    assert "no limit checks" in check.unchecked and "\n" not in check.unchecked

    # at the floor, a 150 Hz swing at a 1 ms substep: the refit it asks for cannot run
    th = np.tile(0.15 * np.cos(np.linspace(0, 20, 50)) * np.exp(-np.linspace(0, 5, 50)), (4, 1))
    prob = SimpleNamespace(theta=th, weight=np.ones_like(th), hold=th[:, 0], max_substep=1e-3)
    k1 = (2 * math.pi * 150.0) ** 2 * 7e-7 * 100**2
    fine = _no_log_stand_in(1.0, problem=prob, derived={"natural_frequency_hz": (150.0, 0.0)},
                            parameters={"k1": SimpleNamespace(value=k1, fixed=False),
                                        "k2": SimpleNamespace(value=0.0, fixed=False)},
                            model=SimpleNamespace(ratio=100.0))
    same, check = basin_check(fine, echo=False)
    assert same is fine and check.statement is None
    assert check.unchecked.startswith("BASIN NOT CHECKED")
    assert "1 ms RK4 substep does not resolve its fitted swing" in check.unchecked
    assert "pass log= (the DataFrame) to sample_posterior" in check.unchecked
    # the same fit at a substep that resolves its swing (h·ω 0.24): nothing needed, no line
    prob.max_substep = 2.5e-4
    _, check = basin_check(fine, echo=False)
    assert check.unchecked is None and check.statement is None


def test_sample_posterior_without_the_log_warns_and_with_it_does_not(stiff_aliased):
    """Through ``sample_posterior`` (a few steps: the warnings, not the draws, are tested):
    the stiff gear's fit of a DataFrame, whose substep its fitted swing does not resolve,
    sampled without ``log=`` carries the BASIN NOT CHECKED line naming the fix; with
    ``log=`` the refit runs (test above: ``check.unchecked`` None)."""
    _, _, _, fit = stiff_aliased
    assert fit.source is None or not Path(str(fit.source)).is_file()  # no file to reread
    post = hdid.sample_posterior(fit, n_steps=5, burn_in=0, seed=0, modes="fit")
    lines = [w for w in post.warnings if w.startswith("BASIN NOT CHECKED")]
    assert len(lines) == 1, post.warnings
    assert "pass log= (the DataFrame) to sample_posterior" in lines[0]
    assert post.warnings[0].startswith("WRONG BASIN")  # the statement stays first
