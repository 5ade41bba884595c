"""Repository paths that the code, the tests and the notebooks cite exist.

Docstrings and comments cite the measurement behind a number: a benchmark script or its
result (``benchmarks/results/batch_speed.md``), a calibration (``calibration/results/
floor_thresholds.json``), a decision record (``docs/decisions/simulator-scheme.md``). A
file renamed or retired leaves such citations behind, and a reader cannot follow them;
the former benchmark diary's sections ("benchmarks/README.md, section …") are gone too,
their content is in ``docs/decisions/``. ``tests/test_docs.py`` checks the links and the
code-style paths of README.md and ``docs/``; this test checks every path written in the
repository's text, in prose and comments too: ``src/``, ``tests/``, the notebooks' cells
(not their outputs), the scripts and pages of ``benchmarks/`` and ``calibration/``, and
``docs/`` and README.md for bare paths and diary sections.
"""

from __future__ import annotations

import json
import re
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

#: A repository path: a top-level folder of the repository, then a path (``{a,b}``
#: alternatives allowed), as prose, comments and code-style quotes write it.
_PATH = re.compile(
    r"(?<![\w./-])((?:src|tests|data|benchmarks|calibration|notebooks|docs|\.ci)/[\w./{},*$-]*[\w}*])")
#: A citation of a section of the former benchmark diary, by file ("benchmarks/README.md,
#: section "…"") or by issue ("issue 17, section "…"").
_DIARY = re.compile(r'benchmarks/README(?:\.md)?[,;]?\s+(?:issue\s+\d+,\s*)?(?:sections?\s+)?"'
                    r'|benchmarks/README(?:\.md)?,\s+[A-Z]|issue\s+\d+,\s+sections?\s+"')
#: ``git checkout <commit> -- <paths>``: how a record brings back a file retired from the tree.
_RESTORE = re.compile(r"git checkout [0-9a-f]{7,40} --")
#: Folders and files whose text is checked.
SCANNED = [("src", "*.py"), ("src", "*.json"), ("tests", "*.py"), ("notebooks", "*.ipynb"),
           ("benchmarks", "*.py"), ("benchmarks", "*.md"), ("calibration", "*.py"),
           ("calibration", "README.md"), ("docs", "*.md")]


def _expand(path: str) -> list[str]:
    """``a/b.{json,md}`` → ``a/b.json``, ``a/b.md`` (one brace group); ``a/{name}.py`` (a
    placeholder, as an f-string writes it) → nothing to check."""
    m = re.search(r"\{([^{}]*)\}", path)
    if not m:
        return [path]
    if "," not in m.group(1):
        return []
    return [path[: m.start()] + alt + path[m.end():] for alt in m.group(1).split(",")]


def dangling(text: str, root: Path = ROOT) -> list[str]:
    """The citations in ``text`` that point nowhere: cited paths missing under ``root`` and
    citations of a section of the former benchmark diary."""
    bad = [f"a section of the former benchmark diary: {m.group(0)!r} (now docs/decisions/)"
           for m in _DIARY.finditer(text)]
    # a record's restore command names a file retired on purpose (``git checkout <commit> --
    # benchmarks/x.py``): the commit holds it
    kept = "\n".join(line for line in text.splitlines() if not _RESTORE.search(line))
    for cited in _PATH.findall(kept):
        path = cited.rstrip(".")
        if path.endswith("/") or re.search(r"[<>*…]", path):
            continue  # a folder or a pattern (src/hdid/effects/<key>.py), not a file
        bad += [p for p in _expand(path) if not (root / p).exists()]
    return bad


def _text(path: Path) -> str:
    if path.suffix != ".ipynb":
        return path.read_text(encoding="utf-8")
    cells = json.loads(path.read_text(encoding="utf-8"))["cells"]
    return "\n".join("".join(c["source"]) for c in cells)  # sources only, never outputs


def _files() -> list[Path]:
    skip = {Path(__file__).resolve()}  # this file's examples of bad citations
    found = {p for folder, pattern in SCANNED for p in (ROOT / folder).rglob(pattern)
             if p.resolve() not in skip and "results" not in p.relative_to(ROOT).parts}
    return sorted(found | {ROOT / "README.md"})


def test_every_cited_repository_path_exists():
    missing = [f"{f.relative_to(ROOT)}: {c}" for f in _files() for c in dangling(_text(f))]
    assert not missing, "citations that point nowhere (move them with the file they cite):\n" + "\n".join(missing)


@pytest.mark.parametrize("text, expected", [
    # a retired benchmark, and a result of it
    ("scheme chosen by measurement (benchmarks/simulator_schemes.py)", ["benchmarks/simulator_schemes.py"]),
    ("see ``benchmarks/results/posterior_profile.md``.", ["benchmarks/results/posterior_profile.md"]),
    # one alternative of a brace group missing
    ("writes ``calibration/results/rival_scale.{json,txt}``", ["calibration/results/rival_scale.txt"]),
    # a section of the former diary, with or without the issue, across a line break
    ('(benchmarks/README.md, issue 17, section "emcee back as the engine")', ["diary"]),
    ('(section X, benchmarks/README.md) and benchmarks/README, "the rival test"',
     ["diary", "benchmarks/README"]),
    ('data allow (issue 17,\n    section "tau_c flat in value")', ["diary"]),
    ("Calibration: benchmarks/README.md, Posterior.", ["diary"]),
    # a restore command's paths are retired on purpose; the same path in prose is not
    ("restore: `git checkout 5dde407 -- benchmarks/simulator_schemes.py`\n"
     "measured by benchmarks/simulator_schemes.py", ["benchmarks/simulator_schemes.py"]),
    # what stays: existing files, records, folders, patterns, a test node
    ("``docs/decisions/simulator-scheme.md``, calibration/results/rival_scale.{json,md}, "
     "benchmarks/results/, src/hdid/effects/<key>.py, f'src/hdid/{name}', "
     "tests/test_docs.py::test_x, issue 17 and its section.", []),
])
def test_dangling_citations_are_found(text, expected):
    found = dangling(text)
    assert len(found) == len(expected), found
    for f, e in zip(found, expected):
        assert e in f
