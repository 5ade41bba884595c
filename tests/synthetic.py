"""Paths and a command-line helper shared by the tests. The synthetic-log generators are
:mod:`hdid.reference.logs` (``from hdid.reference import logs``)."""

from __future__ import annotations

from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SYNTH = ROOT / "data" / "synthetic"
REAL = ROOT.parent / "shared" / "data" / "real"


def real_reference(folder: str) -> dict:
    """``../shared/data/real/<folder>/reference.json`` parsed, or the test skipped naming the
    folder (real logs stay outside the repository)."""
    import json

    import pytest

    ref_path = REAL / folder / "reference.json"
    if not ref_path.exists():
        pytest.skip(f"{ref_path.name} not in {REAL / folder} (real logs stay outside the "
                    "repository: ../shared/data/real/README.md says where they come from)")
    return json.loads(ref_path.read_text())


def cli_fit_json(log, out, *options: str):
    """``hdid fit LOG OPTIONS --json OUT`` in a fresh process, as a user runs it: the
    result's JSON and the command's stdout (the test fails with its stderr on exit ≠ 0)."""
    import json
    import subprocess
    import sys

    proc = subprocess.run(
        [sys.executable, "-m", "hdid.cli", "fit", str(log), *options, "--json", str(out)],
        capture_output=True, text=True, cwd=ROOT,
    )
    assert proc.returncode == 0, proc.stderr
    return json.loads(Path(out).read_text()), proc.stdout
