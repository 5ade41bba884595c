"""What a cold ``hdid fit`` imports: the modules of the fit and of reading a log, and not
the heavy libraries only other commands or options need (matplotlib: ``--plot``; emcee,
arviz: ``--posterior``; scipy.stats: ~0.5 s CPU of every new process, replaced by
scipy.special's functions). Issue 37, "cold start": each of these costs a cold command
0.3-1 s of CPU before any fitting."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
LOG = ROOT / "data" / "synthetic" / "csf8_paper.csv"
#: Not imported by ``hdid fit LOG`` (no --plot, no --posterior) up to the fit itself.
NOT_NEEDED = ("matplotlib", "emcee", "arviz", "scipy.stats")


def test_fit_command_path_imports_no_heavy_library_it_does_not_use():
    # the command's module, the fit's, and reading (and preparing) the shipped log:
    # everything `hdid fit` runs before its first JAX program
    code = (
        "import sys, json\n"
        "from hdid.cli import _main\n"
        "from hdid._fitting import _fit\n"
        f"s = _fit._setup({str(LOG)!r})\n"
        f"print(json.dumps(sorted(m for m in {NOT_NEEDED!r} if m in sys.modules)))\n"
    )
    p = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT,
                       timeout=600)
    assert p.returncode == 0, p.stderr[-2000:]
    assert json.loads(p.stdout.strip().splitlines()[-1]) == []
