"""Fuzz the command line (issue 18): whatever bytes a user hands `hdid fit` as a log, and
whatever output paths they type, the answer is exit 0 or 2 and never a traceback.

Kept cheap: the fitting itself is replaced by a stub, so an example that gets past every
check costs one read of the log (the fit's own robustness is tested in test_robustness).
"""

from __future__ import annotations

import importlib
import os
import pkgutil
from pathlib import Path

import pytest
from click.testing import CliRunner
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import hdid
import hdid._diagnosis._diagnose
import hdid._fitting._fit
from hdid.cli import main

# Every hdid module is imported before a test swaps `fit` for the stub: a module first
# imported while the stub is in place binds it (`from ._fit import fit` in _batch,
# _driven_fit, _ladder) for the rest of the process, and a later test module on the same
# worker then "fits" with the stub (seen: test_driven's joint fit and the reference
# numbers' joint case raising _Reached when this file ran first in one process).
for _m in pkgutil.walk_packages(hdid.__path__, "hdid."):
    if not _m.name.endswith("__main__"):
        importlib.import_module(_m.name)

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "data" / "synthetic" / "csf8_paper.csv"
FUZZ = settings(max_examples=40, deadline=None, derandomize=True,
                suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow])


class _Reached(Exception):
    """The stub fit was called: every check before the fit passed."""


def _stub(*args, **kwargs):
    raise _Reached


def _check(res) -> None:
    """Exit 0, or one 'hdid: error:' line and exit 2, or the stub fit reached."""
    if isinstance(res.exception, _Reached):
        return
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code in (0, 2), (res.exit_code, res.output)
    if res.exit_code == 2:
        lines = res.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("hdid: error:"), res.stderr
    assert "Traceback" not in res.output


# Bytes shaped like what users have: random bytes, text with odd delimiters and
# encodings, a valid header followed by junk, BOMs and spreadsheet magic numbers.
_HEADERS = st.sampled_from([b"", b"time,theta\n", b"time;theta\n", b"\xef\xbb\xbftime,theta\n",
                            b"\xff\xfe", b"PK\x03\x04", b"time,theta,run\n", b"time,motor_torque\n"])
_BODY = st.one_of(
    st.binary(max_size=600),
    st.text(alphabet="0123456789.,;-+eE \t\r\nabc\"'\x00", max_size=400).map(str.encode),
    st.text(max_size=200).map(lambda t: t.encode("utf-8", "surrogatepass")),
    st.text(max_size=200).map(lambda t: t.encode("latin-1", "replace")),
)


@FUZZ
@given(head=_HEADERS, body=_BODY, command=st.sampled_from(["fit", "diagnose"]))
def test_fuzz_log_bytes(tmp_path, monkeypatch, head, body, command):
    monkeypatch.setattr(hdid._fitting._fit, "fit", _stub)
    monkeypatch.setattr(hdid._diagnosis._diagnose, "diagnose", _stub)
    path = tmp_path / "log.csv"
    path.write_bytes(head + body)
    _check(CliRunner().invoke(main, [command, str(path)]))
    assert path.read_bytes() == head + body  # never written to


# A command line cannot carry a NUL byte (argv strings end at it), so names have none.
_NAMES = st.one_of(
    st.text(st.characters(blacklist_characters="\x00"), max_size=30),
    st.text(alphabet="abc./\\ -_:~*?é\n", max_size=30),
    st.sampled_from(["", ".", "..", "/", "out/", "fit.json/", "fit.PNG", "fit.xyz", "fit",
                     "/proc/nope.json", "a" * 300 + ".png", "log.csv"]),
)


@FUZZ
@given(name=_NAMES, option=st.sampled_from(["--json", "--plot", "--summary"]))
def test_fuzz_output_paths(tmp_path, monkeypatch, name, option):
    monkeypatch.setattr(hdid._fitting._fit, "fit", _stub)
    monkeypatch.setattr("hdid._fitting._batch.fit_many", _stub, raising=False)
    monkeypatch.chdir(tmp_path)
    log = tmp_path / "log.csv"
    if not log.exists():
        log.write_bytes(EXAMPLE.read_bytes())
    before = set(os.listdir(tmp_path))
    _check(CliRunner().invoke(main, ["fit", "log.csv", option, name]))
    assert set(os.listdir(tmp_path)) == before  # nothing written before the (stub) fit


@FUZZ
@given(name=_NAMES)
def test_fuzz_simulate_output(tmp_path, monkeypatch, name):
    import hdid._simulation._synthetic

    monkeypatch.setattr(hdid._simulation._synthetic, "synthesize", _stub)
    monkeypatch.chdir(tmp_path)
    (tmp_path / "log.csv").write_text("existing\n")
    _check(CliRunner().invoke(main, ["simulate", name]))
    assert (tmp_path / "log.csv").read_text() == "existing\n"


if __name__ == "__main__":  # pragma: no cover
    pytest.main([__file__, "-q"])
