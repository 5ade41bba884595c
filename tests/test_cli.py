"""Command-line behaviour: reports, JSON schema, one-line errors with exit status 2."""

from __future__ import annotations

import hashlib
import json
import subprocess
import sys
from pathlib import Path

import pytest
from click.testing import CliRunner

from hdid.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "data" / "synthetic" / "csf8_paper.csv"
COUNTS = ROOT / "data" / "synthetic" / "csf8_paper_counts.csv"
NAMES = ["k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v", "inertia"]


def _digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def test_help_does_not_import_jax():
    # `hdid --help` must answer at once: the CLI module may not pull in jax.
    code = "import sys, hdid.cli; print('jax' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
    res = CliRunner().invoke(main, ["--help"])
    assert res.exit_code == 0 and "fit" in res.output and "simulate" in res.output


@pytest.fixture(scope="module")
def example_fit(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("cli")
    before = _digest(EXAMPLE)
    res = CliRunner().invoke(
        main, ["fit", str(EXAMPLE), "--json", str(tmp / "fit.json"), "--plot", str(tmp / "fit.png")]
    )
    return res, tmp, before


def test_fit_report_json_and_plot(example_fit):
    res, tmp, before = example_fit
    assert res.exit_code == 0, res.output
    assert "RMS residual" in res.output and "stick band" in res.output
    data = json.loads((tmp / "fit.json").read_text())
    assert list(data["parameters"]) == NAMES
    for name in NAMES:
        assert set(data["parameters"][name]) >= {"value", "unit", "std", "fixed"}
    assert data["parameters"]["inertia"]["fixed"] is True
    assert data["parameters"]["inertia"]["std"] is None
    assert set(data["nuisance"]) == {"1", "2", "3", "4"}
    for run in data["nuisance"].values():
        assert {"release_time", "offset"} <= set(run)
    assert isinstance(data["warnings"], list)
    for key in ("rms_residual_rad", "stick_band_halfwidth_rad", "runs"):
        assert key in data
    # The encoder step is 2π/4000; quantization alone gives RMS step/√12 (0.289 counts).
    # The fit has ~19 unknowns for ~30 effective observations, so it can sit below the
    # floor, but it must not sit far above it on noiseless quantized data.
    assert data["rms_residual_counts"] < 1.3 / 12**0.5
    assert (tmp / "fit.png").stat().st_size > 10_000
    assert _digest(EXAMPLE) == before, "the input log was modified"


def test_counts_log_with_scale(tmp_path):
    res = CliRunner().invoke(
        main, ["fit", str(COUNTS), "--counts-per-rev", "4000", "-q", "--json", str(tmp_path / "c.json")]
    )
    assert res.exit_code == 0, res.output
    k1 = json.loads((tmp_path / "c.json").read_text())["parameters"]["k1"]["value"]
    # Same readings as csf8_paper.csv (true k1 = 940): the 2.8 % std of the paper design
    # allows ±10 % comfortably.
    assert abs(k1 / 940 - 1) < 0.10


def _run_cli(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "hdid.cli", *args], capture_output=True, text=True, cwd=ROOT
    )


@pytest.mark.parametrize(
    "make, args, fragment",
    [
        (None, ["fit", "does/not/exist.csv"], "exist.csv"),
        ("time,winkel\n0,0\n", ["fit", "{path}"], "theta"),  # no angle-column name
        ("".join(f"{i*0.004},{i % 7 * 100}\n" for i in range(50)), ["fit", "{path}"], "--counts-per-rev"),
        ("time,theta\n0,0.1\n0.004,abc\n", ["fit", "{path}"], "row 3"),
        (None, ["fit", str(EXAMPLE), "--json", str(EXAMPLE)], "overwrite"),
        (None, ["fit", str(EXAMPLE), "--fix", "k9=1"], "k9"),
        (None, ["fit", str(EXAMPLE), "--inertia-prior", "7e-7"], "MEAN,REL"),
        # click's own usage errors are one line too, with the command's --help to read
        (None, ["fit", str(EXAMPLE), str(EXAMPLE), "--workers", "0"], "--workers"),
        (None, ["fit", str(EXAMPLE), "--no-such-option"], "fit --help"),
    ],
)
def test_bad_input_is_one_line_exit_2(tmp_path, make, args, fragment):
    # In process (click's runner, stderr apart): the command's whole error path — the
    # group's usage errors, hdid's LogError/HdidError → one line, exit 2 — runs inside
    # `main`, and an escaping exception is a failure (`_one_line_exit_2`). The real
    # process (what `python -m hdid.cli` adds: sys.exit of that status, no traceback
    # printed by the interpreter) is checked once per error path below.
    path = tmp_path / "bad.csv"
    if make is not None:
        text = make if make.startswith("time") else "time,theta\n" + make
        path.write_text(text)
        before = _digest(path)
    args = [a.replace("{path}", str(path)) for a in args]
    _one_line_exit_2(CliRunner().invoke(main, args), fragment)
    if make is not None:
        assert _digest(path) == before


@pytest.mark.parametrize(
    "args, fragment",
    [(["fit", "does/not/exist.csv"], "exist.csv"),  # hdid's own error (LogError)
     (["fit", str(EXAMPLE), "--no-such-option"], "fit --help")],  # click's usage error
)
def test_bad_input_in_a_real_process_is_one_line_exit_2(args, fragment):
    out = _run_cli(*args)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith("hdid: error:") and fragment in lines[0]
    assert "Traceback" not in out.stderr


def test_simulate_then_fit_round_trip(tmp_path):
    out = tmp_path / "sim.csv"
    res = CliRunner().invoke(
        main,
        ["simulate", str(out), "--amplitudes", "0.157,-0.157,0.157,-0.157", "--counts",
         "--rate", "250", "--duration", "0.5", "--set", "k1=1200", "--seed", "3"],
    )
    assert res.exit_code == 0, res.output
    again = CliRunner().invoke(main, ["simulate", str(out)])
    assert again.exit_code == 2 and "overwrite" in again.output
    res = CliRunner().invoke(main, ["fit", str(out), "--counts-per-rev", "4000", "-q", "--json", str(tmp_path / "s.json")])
    assert res.exit_code == 0, res.output
    k1 = json.loads((tmp_path / "s.json").read_text())["parameters"]["k1"]["value"]
    # Same simulator, same inertia, quantized at 4000 counts/rev: k1 within the ~3 %
    # (1σ) of the 250 Hz design, allowing 3σ.
    assert abs(k1 / 1200 - 1) < 0.09


EFFECT_FILE = '''
from typing import ClassVar
import jax.numpy as jnp
import hdid

class Cogging(hdid.AbstractEffect):
    amplitude: float
    name: ClassVar[str] = "cogging"
    parameters: ClassVar = (hdid.Parameter("amplitude", "N m", "cogging torque",
                                           transform="identity", scale=1e-3),)

    def torque(self, motion, state):
        return -self.amplitude * jnp.sin(24 * motion.theta)

effect = Cogging(amplitude=1e-4)
'''


def test_effects_from_the_command_line(tmp_path):
    # A user's effect from a file and a removed base effect: no change to hdid needed.
    path = tmp_path / "my_effect.py"
    path.write_text(EFFECT_FILE)
    out = tmp_path / "e.json"
    res = CliRunner().invoke(
        main, ["fit", str(EXAMPLE), "--remove", "viscous", "--effect-file", str(path), "-q", "--json", str(out)]
    )
    assert res.exit_code == 0, res.output
    names = list(json.loads(out.read_text())["parameters"])
    assert "amplitude" in names and "c_v" not in names
    # Free play from the library replaces the cubic spring.
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--add", "backlash", "-q", "--json", str(out)])
    assert res.exit_code == 0, res.output
    params = json.loads(out.read_text())["parameters"]
    assert params["backlash"]["unit"] == "rad" and params["backlash"]["value"] > 0


@pytest.mark.parametrize(
    "args, fragment",
    [(["--add", "nope"], "unknown effect"), (["--remove", "nope"], "the model has"),
     (["--effect-file", "missing.py"], "no such file")],
)
def test_effect_option_errors(args, fragment):
    _one_line_exit_2(CliRunner().invoke(main, ["fit", str(EXAMPLE), *args]), fragment)


# --- issue 18, item 1: every bad input is one line, exit 2, before any work -------------

def _one_line_exit_2(res, fragment: str) -> str:
    """The CLI refused with one 'hdid: error:' line on stderr, exit 2, no traceback."""
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("hdid: error:") and fragment in lines[0], lines[0]
    return lines[0]


BAD_FILES = {
    # what a user may hand hdid instead of a UTF-8 CSV, and what the message must name
    "utf16.csv": ("time,theta\n0,0.1\n0.004,0.2\n".encode("utf-16"), "UTF-16"),
    "latin1.csv": ("time,theta °\n0,0.1\n0.004,0.2\n".encode("latin-1"), "UTF-8"),
    "excel.csv": (b"PK\x03\x04\x14\x00\x06\x00" + bytes(range(256)) * 4, "spreadsheet"),
    "old_excel.csv": (b"\xd0\xcf\x11\xe0\xa1\xb1\x1a\xe1" + bytes(range(256)) * 4, "spreadsheet"),
    "binary.csv": (bytes(range(256)) * 8, "binary"),
}


@pytest.mark.parametrize("name", sorted(BAD_FILES))
@pytest.mark.parametrize("command", ["fit", "diagnose"])
def test_undecodable_log_is_one_line(tmp_path, name, command):
    content, fragment = BAD_FILES[name]
    path = tmp_path / name
    path.write_bytes(content)
    res = CliRunner().invoke(main, [command, str(path)])
    line = _one_line_exit_2(res, fragment)
    assert name in line
    assert path.read_bytes() == content


def test_european_csv_is_read(tmp_path):
    # ';' between cells and ',' as decimal separator (a German/French Excel export):
    # the same numbers as the example log, so the same fit.
    text = EXAMPLE.read_text()
    euro = tmp_path / "euro.csv"
    euro.write_text(text.replace(",", ";").replace(".", ","))
    from hdid import read_log

    a, b = read_log(EXAMPLE), read_log(euro)
    assert len(a.runs) == len(b.runs)
    for ra, rb in zip(a.runs, b.runs):
        assert (ra.time == rb.time).all() and (ra.theta == rb.theta).all()
    assert a.resolution == b.resolution


def test_semicolon_csv_with_decimal_points_is_read(tmp_path):
    text = EXAMPLE.read_text()
    semi = tmp_path / "semi.csv"
    semi.write_text(text.replace(",", ";"))
    from hdid import read_log

    a, b = read_log(EXAMPLE), read_log(semi)
    assert all((ra.theta == rb.theta).all() for ra, rb in zip(a.runs, b.runs))


@pytest.mark.parametrize(
    "option, make, fragment",
    [
        ("--json", "dir", "directory"),
        ("--plot", "dir", "directory"),
        ("--plot", "fit.xyz", "xyz"),
        ("--plot", "fit", "extension"),
        ("--json", "missing/fit.json", "does not exist"),
    ],
)
def test_bad_output_path_refused_before_fitting(tmp_path, monkeypatch, option, make, fragment):
    import hdid._fitting._fit

    def no_fit(*a, **k):  # the refusal must come before any fitting
        raise AssertionError("fit started before the output path was checked")

    monkeypatch.setattr(hdid._fitting._fit, "fit", no_fit)
    target = tmp_path / "out_dir" if make == "dir" else tmp_path / make
    if make == "dir":
        target.mkdir()
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), option, str(target)])
    _one_line_exit_2(res, fragment)


def test_diagnose_bad_plot_refused_before_fitting(tmp_path, monkeypatch):
    import hdid._diagnosis._diagnose

    def no_diagnose(*a, **k):
        raise AssertionError("diagnosed before the output path was checked")

    monkeypatch.setattr(hdid._diagnosis._diagnose, "diagnose", no_diagnose)
    res = CliRunner().invoke(main, ["diagnose", str(EXAMPLE), "--residuals", str(tmp_path / "r.xyz")])
    _one_line_exit_2(res, "xyz")


def test_simulate_refuses_existing_file_before_simulating(tmp_path, monkeypatch):
    import hdid._simulation._synthetic

    def no_sim(*a, **k):
        raise AssertionError("simulated before refusing")

    monkeypatch.setattr(hdid._simulation._synthetic, "synthesize", no_sim)
    out = tmp_path / "existing.csv"
    out.write_text("keep me\n")
    res = CliRunner().invoke(main, ["simulate", str(out)])
    _one_line_exit_2(res, "--overwrite")
    assert out.read_text() == "keep me\n"
    res = CliRunner().invoke(main, ["simulate", str(tmp_path / "no" / "x.csv")])
    _one_line_exit_2(res, "does not exist")


# --- issue 18, item 7: a batch with failed logs exits 3, good rows written -----------------

def test_batch_partial_failure_exit_3(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("time,angle\n0,0\n")
    summary = tmp_path / "s.csv"
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), str(bad), "--summary", str(summary), "-q"])
    assert res.exit_code == 3, res.output
    assert "1 of 2" in res.stderr and "Traceback" not in res.output
    import pandas as pd

    table = pd.read_csv(summary)
    assert len(table) == 2
    assert table["error"].isna().sum() == 1 and abs(table["k1"].dropna().iloc[0] / 940 - 1) < 0.1


# --- issue 18, item 2: no silent wait on a terminal, nothing extra when redirected ----------

def _stub_fit_error(*args, **kwargs):
    from hdid._errors import FitError

    raise FitError("stub: the fit itself is not under test here")


@pytest.mark.parametrize("tty", [True, False])
def test_phases_on_a_terminal_only(monkeypatch, tty):
    import hdid._fitting._fit
    import hdid.cli

    monkeypatch.setattr(hdid._fitting._fit, "fit", _stub_fit_error)
    monkeypatch.setattr(hdid.cli._common, "_stderr_is_tty", lambda: tty)
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE)])
    assert res.exit_code == 2
    lines = res.stderr.strip().splitlines()
    if tty:
        assert lines[0].startswith("hdid: loading JAX") and lines[0].endswith(" s")
        assert lines[1].startswith("hdid: reading") and lines[1].endswith(" s")
        assert lines[2].startswith("hdid: fitting 4 run(s)") and "compiles" in lines[2]
        assert len(lines) == 4 and lines[3].startswith("hdid: error: ")
    else:
        assert len(lines) == 1 and lines[0].startswith("hdid: error: ")
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "-q"])  # -q: no phases either
    monkeypatch.setattr(hdid.cli._common, "_stderr_is_tty", lambda: True)
    assert len(res.stderr.strip().splitlines()) == 1


def test_too_long_log_refused_at_once(monkeypatch):
    import hdid._fitting._fit
    import hdid.cli

    def no_fit(*a, **k):
        raise AssertionError("a log over the limit must be refused before fitting")

    monkeypatch.setattr(hdid._fitting._fit, "fit", no_fit)
    # The example has 125 samples per run: a limit of 100 refuses it, with the hint.
    monkeypatch.setattr(hdid.cli._common, "MAX_SAMPLES_PER_RUN", 100)
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE)])
    line = _one_line_exit_2(res, "125 samples")
    assert "crop" in line and "one row in 2" in line and "250 Hz" in line


def test_simulate_default_is_the_measured_design(tmp_path):
    # issue 18 item 6: the default teaches the experiment that determines the friction
    out = tmp_path / "d.csv"
    res = CliRunner().invoke(main, ["simulate", str(out)])
    assert res.exit_code == 0, res.output
    from hdid import read_log

    log = read_log(out)
    assert len(log.runs) == 8 and abs(log.sample_period - 1e-3) < 1e-12
    amps = sorted({round(abs(r.theta[0]), 2) for r in log.runs})
    assert amps == [0.05, 0.08, 0.12, 0.16]  # four amplitudes, both signs
    help_text = CliRunner().invoke(main, ["simulate", "--help"]).output
    assert "paper's design" in help_text
    assert "v_s" in help_text and "1 kHz" in help_text
