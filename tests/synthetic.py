"""The synthetic-data modules of ``data/synthetic`` (not a package) for the tests.

``GEN`` is ``generate.py`` (``make_log``, ``TRUTH_CSF8``, designs), ``HID`` is
``hidden.py`` (effects hidden in logs through the reference simulator).
"""

from __future__ import annotations

import importlib.util
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SYNTH = ROOT / "data" / "synthetic"


def _load(name: str, path: Path):
    spec = importlib.util.spec_from_file_location(name, path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


GEN = _load("hdid_tests_generate", SYNTH / "generate.py")
HID = _load("hdid_tests_hidden", SYNTH / "hidden.py")


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
