"""The commands that README.md and docs/ show with their output still print that output.

A fenced block written as ```` ```console ```` holds commands (lines starting with ``$ ``),
each followed by the output it prints. Every such block of ``README.md`` and
``docs/**/*.md`` is run here, command by command, as a user runs it: ``hdid ARGS`` is
``python -m hdid.cli ARGS`` in a fresh process, from a scratch folder that holds the
repository's ``data/`` (so relative paths read the shipped logs and the files a command
writes land in the scratch folder). Its standard output is compared with the block's text:

- words, symbols and integers must agree exactly (runs of spaces count as one, so a column
  may shift);
- a duration (a number followed by ``s``, ``ms`` or ``min``) is masked: timings vary;
- any other number must agree to its *float tail* (``_close``).

A command shown twice (README and docs) runs once. Write any command whose output is not
shown, or too slow to run here, as a ``bash`` block instead.
"""

from __future__ import annotations

import functools
import math
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]

_BLOCK = re.compile(r"^```console[ \t]*\n(.*?)^```[ \t]*$", re.S | re.M)
_NUMBER = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?")
#: A duration as hdid prints one ("6.36 s", "0.1 s", "12 min"): masked before comparing.
_DURATION = re.compile(r"[-+]?(?:\d+\.\d*|\.\d+|\d+)(?:[eE][-+]?\d+)?\s?(?:s|ms|min)(?![\w/^])")

#: Relative float tail. The report prints fitted numbers that another CPU (or the order of
#: XLA's sums on another core count) may move by up to 1e-3 of their standard error
#: (tests/reference_numbers.py: the optimiser stops at a relative cost change of 1e-8, ≈
#: 5e-4 σ along the flattest direction). The loosest printed parameter has a standard error
#: of ~2.4× its value (c_v, 236 % on the paper log), so such a move is ≤ 2.4e-3 of the
#: value: 5e-3 is twice that, and far below anything a reader would call a different number.
REL_TAIL = 5e-3


def _blocks() -> list[tuple[str, str, str]]:
    """``(page:line, command, expected output)`` for every command of every console block."""
    out = []
    for page in PAGES:
        text = page.read_text(encoding="utf-8")
        for match in _BLOCK.finditer(text):
            line = text.count("\n", 0, match.start()) + 2
            command, expected = None, []
            for row in match.group(1).splitlines():
                if row.startswith("$ "):
                    if command is not None:
                        out.append((f"{page.relative_to(ROOT)}:{line}", command, "\n".join(expected)))
                    command, expected = row[2:].strip(), []
                elif command is not None:
                    expected.append(row)
            if command is not None:
                out.append((f"{page.relative_to(ROOT)}:{line}", command, "\n".join(expected)))
    return out


def _unit(token: str) -> float:
    """One unit in the last printed digit of ``token`` (0 for an integer: exact)."""
    mantissa, _, exponent = token.lower().partition("e")
    if "." not in mantissa and not exponent:
        return 0.0
    decimals = len(mantissa.partition(".")[2])
    return 10.0 ** (-decimals + (int(exponent) if exponent else 0))


def _close(expected: str, got: str) -> bool:
    """Numbers printed in the docs and now agree to their float tail: within ``REL_TAIL``
    of their size or one unit in the last printed digit (a rounding that flipped);
    integers exactly."""
    a, b = float(expected), float(got)
    if _unit(expected) == 0.0 and _unit(got) == 0.0:
        return a == b
    tol = max(REL_TAIL * max(abs(a), abs(b)), _unit(expected), _unit(got))
    return math.isclose(a, b, rel_tol=0.0, abs_tol=tol)


def _tokens(text: str) -> tuple[list[str], list[str]]:
    """The text with durations masked and numbers cut out (runs of spaces as one), and
    the numbers, in order."""
    text = _DURATION.sub("<duration>", text)
    words = [re.sub(r"[ \t]+", " ", w).strip() for w in _NUMBER.split(text)]
    return words, _NUMBER.findall(text)


def differences(expected: str, got: str) -> list[str]:
    """Where ``got`` (a command's output now) differs from ``expected`` (as documented),
    line by line; empty when they agree."""
    exp_lines, got_lines = expected.strip("\n").splitlines(), got.strip("\n").splitlines()
    diffs = []
    if len(exp_lines) != len(got_lines):
        diffs.append(f"{len(exp_lines)} lines documented, {len(got_lines)} printed")
    for i, (e, g) in enumerate(zip(exp_lines, got_lines), start=1):
        (ew, en), (gw, gn) = _tokens(e), _tokens(g)
        if ew != gw or len(en) != len(gn) or not all(map(_close, en, gn)):
            diffs.append(f"line {i}:\n  documented: {e}\n  printed:    {g}")
    return diffs


@functools.cache
def _run(command: str, workdir: str) -> str:
    argv = shlex.split(command)
    assert argv[0] == "hdid", f"{command!r}: a console block runs hdid commands only"
    proc = subprocess.run(
        [sys.executable, "-m", "hdid.cli", *argv[1:]], capture_output=True, text=True,
        cwd=workdir, timeout=600,
    )
    assert proc.returncode == 0, f"{command}: exit {proc.returncode}\n{proc.stderr}"
    return proc.stdout


@pytest.fixture(scope="module")
def workdir(tmp_path_factory) -> str:
    path = tmp_path_factory.mktemp("readme")
    (path / "data").symlink_to(ROOT / "data", target_is_directory=True)
    return str(path)


BLOCKS = _blocks()


def test_readme_shows_a_checked_command():
    # the short tour's fit is shown with its report: losing the block would silently end
    # this check
    assert any(where.startswith("README.md") for where, _, _ in BLOCKS)


@pytest.mark.parametrize("where, command, expected", BLOCKS, ids=[f"{w} {c}" for w, c, _ in BLOCKS])
def test_shown_command_prints_what_is_shown(where, command, expected, workdir):
    diffs = differences(expected, _run(command, workdir))
    assert not diffs, (
        f"{where}: `{command}` no longer prints what the page shows; rerun it and paste its "
        "output into the page if the change is meant:\n" + "\n".join(diffs)
    )


# The comparison itself (no command run): it must catch what a reader would call a change.
_REPORT = """k1               939.96        27.9    3.0%  N m/rad
starts: Δχ² to the best = 0, 0.00531, 4.24e+04; 3 of 6 within Δχ² < 1; 6.36 s"""


@pytest.mark.parametrize("now, same", [
    (_REPORT, True),
    (_REPORT.replace("6.36 s", "11.2 s"), True),                 # a timing
    (_REPORT.replace("939.96", "939.97"), True),                 # the last digit
    (_REPORT.replace("939.96 ", "939.961"), True),               # a column shifted
    (_REPORT.replace("4.24e+04", "4.25e+04"), True),             # float tail of a cost
    (_REPORT.replace("939.96", "949.96"), False),                # a value moved 1 %
    (_REPORT.replace("3 of 6", "4 of 6"), False),                # a count
    (_REPORT.replace("N m/rad", "N m/deg"), False),              # a unit
    (_REPORT.replace("27.9", "27.9 (fixed)"), False),            # a word
    (_REPORT + "\nwrote fit.json", False),                       # a line more
    (_REPORT.replace("0.00531", "0.0531"), False),               # a decade
])
def test_comparison_masks_timings_and_float_tails_only(now, same):
    assert (differences(_REPORT, now) == []) is same
