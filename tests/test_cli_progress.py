"""The command line's progress output: drawing the figure is a phase of its own on a
terminal (it compiles a Jacobian), and every command takes ``-q`` to silence it."""

from __future__ import annotations

from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

from hdid.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "data" / "synthetic" / "csf8_paper.csv"


@pytest.mark.parametrize("tty", [True, False])
def test_drawing_the_figure_is_a_phase_on_a_terminal(monkeypatch, tmp_path, tty):
    """fit.png's confidence band compiles a Jacobian the first time (~10 s): on a terminal
    that wait is named like the others; redirected, stderr stays empty."""
    import hdid._fitting._fit
    import hdid._results._plot
    import hdid.cli

    drawn = []
    fake = SimpleNamespace(report=lambda: "report", to_dict=lambda: {}, plot=lambda: "axes")
    monkeypatch.setattr(hdid._fitting._fit, "fit", lambda *a, **k: fake)
    monkeypatch.setattr(hdid._results._plot, "save_figure", lambda ax, path: drawn.append((ax, path)))
    monkeypatch.setattr(hdid.cli._common, "_stderr_is_tty", lambda: tty)
    out = tmp_path / "fit.png"
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--plot", str(out)])
    assert res.exit_code == 0, res.output
    assert drawn == [("axes", str(out))]
    lines = res.stderr.strip().splitlines()
    if tty:
        assert lines[-1].startswith(f"hdid: drawing {out}") and lines[-1].endswith(" s"), lines
    else:
        assert lines == []


def test_every_command_takes_q(tmp_path):
    for cmd in ("fit", "diagnose", "simulate"):
        res = CliRunner().invoke(main, [cmd, "--help"])
        assert "-q, --quiet" in res.output, cmd
    out = tmp_path / "s.csv"
    res = CliRunner().invoke(main, ["simulate", str(out), "--amplitudes", "0.1", "--duration",
                                    "0.05", "-q"])
    assert res.exit_code == 0, res.output
    assert res.stdout == "" and out.exists()
