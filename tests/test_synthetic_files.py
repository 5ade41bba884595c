"""The shipped synthetic logs are :mod:`hdid.reference.logs`' output: the documented
command ``python data/synthetic/generate.py DIR`` rewrites every CSV of ``data/synthetic``
and its ``truth.json`` byte for byte (fixed seeds, deterministic reference simulators), so
a change of a generator, a design or a truth cannot leave the shipped files behind it."""

from __future__ import annotations

import subprocess
import sys

from synthetic import ROOT, SYNTH


def test_generate_rewrites_every_shipped_file_byte_for_byte(tmp_path):
    proc = subprocess.run([sys.executable, str(SYNTH / "generate.py"), str(tmp_path)],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 0, proc.stderr
    shipped = sorted(p.name for p in SYNTH.iterdir() if p.suffix in (".csv", ".json"))
    assert sorted(p.name for p in tmp_path.iterdir()) == shipped
    differ = [name for name in shipped
              if (tmp_path / name).read_bytes() != (SYNTH / name).read_bytes()]
    assert not differ, f"python data/synthetic/generate.py no longer writes {differ}"
