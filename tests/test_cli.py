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
        ("time,angle\n0,0\n", ["fit", "{path}"], "theta"),
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
    path = tmp_path / "bad.csv"
    if make is not None:
        text = make if make.startswith("time") else "time,theta\n" + make
        path.write_text(text)
        before = _digest(path)
    args = [a.replace("{path}", str(path)) for a in args]
    out = _run_cli(*args)
    assert out.returncode == 2, out.stderr
    lines = out.stderr.strip().splitlines()
    assert len(lines) == 1, out.stderr
    assert lines[0].startswith("hdid: error:") and fragment in lines[0]
    assert "Traceback" not in out.stderr
    if make is not None:
        assert _digest(path) == before


def test_simulate_then_fit_round_trip(tmp_path):
    out = tmp_path / "sim.csv"
    res = CliRunner().invoke(
        main,
        ["simulate", str(out), "--amplitudes", "0.157,-0.157,0.157,-0.157", "--counts",
         "--set", "k1=1200", "--seed", "3"],
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
    out = _run_cli("fit", str(EXAMPLE), *args)
    assert out.returncode == 2 and fragment in out.stderr and "Traceback" not in out.stderr
