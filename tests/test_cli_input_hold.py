"""hdid fit --input-hold zoh|foh (issue 16 item 6 on the command line): the library's
input_hold reaches fit_driven and fit_joint, the default stays the library's (by the
torque column), --help says what each means, and a free-motion log refuses it at once."""

from __future__ import annotations

from pathlib import Path

import pytest
from click.testing import CliRunner

from hdid.cli import main

ROOT = Path(__file__).resolve().parents[1]
FREE = ROOT / "data" / "synthetic" / "csf8_paper.csv"
DRIVEN = ROOT / "data" / "synthetic" / "driven_csf8.csv"


class _Stop(Exception):
    """Raised by the spy: the arguments were seen, no fit is run."""


@pytest.fixture
def spy(monkeypatch):
    import hdid._fitting._driven_fit

    seen = {}

    def record(name):
        def f(*args, **kwargs):
            seen[name] = kwargs
            raise _Stop

        return f

    monkeypatch.setattr(hdid._fitting._driven_fit, "fit_driven", record("fit_driven"))
    monkeypatch.setattr(hdid._fitting._driven_fit, "fit_joint", record("fit_joint"))
    return seen


@pytest.mark.parametrize("hold", ["zoh", "foh"])
def test_input_hold_reaches_the_driven_fit(spy, hold):
    res = CliRunner().invoke(main, ["fit", str(DRIVEN), "--input-hold", hold, "-q"])
    assert isinstance(res.exception, _Stop), res.output
    assert spy["fit_driven"]["input_hold"] == hold


def test_input_hold_reaches_the_joint_fit(spy):
    res = CliRunner().invoke(main, ["fit", str(FREE), str(DRIVEN), "--joint", "--input-hold",
                                    "foh", "-q"])
    assert isinstance(res.exception, _Stop), res.output
    assert spy["fit_joint"]["input_hold"] == "foh"


def test_without_input_hold_the_library_chooses(spy):
    res = CliRunner().invoke(main, ["fit", str(DRIVEN), "-q"])
    assert isinstance(res.exception, _Stop), res.output
    assert "input_hold" not in spy["fit_driven"]  # input_hold_for(log): by the torque column


def test_input_hold_is_documented():
    res = CliRunner().invoke(main, ["fit", "--help"])
    assert res.exit_code == 0
    text = " ".join(res.output.split())
    assert "--input-hold [zoh|foh]" in text
    assert "held from each sample to the next" in text and "linear between samples" in text


@pytest.mark.parametrize("args, message", [
    (["--input-hold", "foh"], "has no motor_torque or motor_current column"),
    (["--input-hold", "linear"], "'linear' is not one of 'zoh', 'foh'"),
])
def test_input_hold_bad_use_is_one_line(spy, args, message):
    res = CliRunner().invoke(main, ["fit", str(FREE), *args])
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hdid: error:") and message in lines[0], lines
    assert not spy  # refused before any work
