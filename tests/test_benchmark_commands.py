"""The benchmark and calibration commands the repository shows can still be typed.

README.md, ``docs/``, ``benchmarks/README.md``, ``calibration/README.md``, the scripts' own
usage lines and the comments of ``src/`` and ``tests/`` show commands such as
``taskset -c 1 python benchmarks/diagnose_independent.py --floor-rule [--seeds S,…]``.
``tests/test_readme.py`` runs the ``hdid`` commands that print their output; these take
minutes to hours, so here each is checked as written: the script exists, and every
``--option`` after it is one the script takes. The scripts are read, not run (each would
import JAX): a script takes the options its source spells as strings
(``add_argument("--seeds", …)``, ``"--threshold" in argv``), ``--render`` and
``--interpretation`` where it uses ``_common.parse_or_render``, and ``--help``. The results
files are records of what was run at the time, and are not read.
"""

from __future__ import annotations

import ast
import functools
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
FOLDERS = ("benchmarks", "calibration")
#: Tests that show retired paths and options on purpose, to check their checkers.
PLANTED = {"test_benchmark_commands.py", "test_citations.py"}
#: Text that shows commands: pages, and the scripts and sources whose docstrings and
#: comments cite a command.
SCANNED = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md")),
           *(ROOT / f / "README.md" for f in FOLDERS),
           *(p for f in (*FOLDERS, "src", "tests") for p in sorted((ROOT / f).rglob("*.py"))
             if p.name not in PLANTED)]

#: A script, with or without its folder (``benchmarks/long_log.py``, ``long_log.py``).
_SCRIPT = re.compile(r"(?<![\w/.-])(?:(benchmarks|calibration)/)?([a-z_][a-z0-9_]*)\.py\b")
_OPTION = re.compile(r"(?<![\w-])--[a-z][a-z0-9-]*")
#: ``git checkout <commit> -- <paths>``: how a record brings back a script retired from the tree.
_RESTORE = re.compile(r"git checkout [0-9a-f]{7,40} --")
#: Where a shown command ends: a table cell's edge (``\|`` is a pipe inside the cell; the
#: cell's later code spans, such as ``--fixed-plant``, continue the command), a shell comment, the
#: next script named on the line, or outside a table the end of its code span.
_CELL_END = re.compile(r"(?<!\\)\||\s#\s")


@functools.cache
def options(script: Path) -> frozenset[str]:
    """The options ``script`` takes: every ``--word`` string of its source, the ones
    ``_common.parse_or_render`` adds, and ``--help``."""
    tree = ast.parse(script.read_text(encoding="utf-8"))
    spelled = {n.value for n in ast.walk(tree) if isinstance(n, ast.Constant)
               and isinstance(n.value, str) and re.fullmatch(r"--[a-z][a-z0-9-]*", n.value)}
    render = any(isinstance(n, (ast.Name, ast.Attribute)) and "parse_or_render" in
                 (n.id if isinstance(n, ast.Name) else n.attr) for n in ast.walk(tree))
    return frozenset(spelled | {"--help"} | ({"--render", "--interpretation"} if render else set()))


def _resolve(folder: str | None, name: str, root: Path) -> Path | None:
    """The script a mention names; ``None`` for a bare name that is no benchmark or
    calibration script (``test_fit.py``, ``_rates.py`` of ``src``)."""
    if folder:
        return root / folder / f"{name}.py"
    found = [root / f / f"{name}.py" for f in FOLDERS if (root / f / f"{name}.py").exists()]
    return found[0] if len(found) == 1 and not name.startswith("_") else None


def wrong_commands(text: str, root: Path = ROOT) -> list[str]:
    """``script: problem`` for every shown command of ``text`` whose script is missing or
    whose options the script does not take."""
    bad = []
    for line in text.splitlines():
        if _RESTORE.search(line):
            continue  # a retired script's restore command names a file gone on purpose
        mentions = list(_SCRIPT.finditer(line))
        for k, m in enumerate(mentions):
            script = _resolve(m.group(1), m.group(2), root)
            if script is None:
                continue
            shown = f"{m.group(1) + '/' if m.group(1) else ''}{m.group(2)}.py"
            if not script.exists():
                bad.append(f"{shown}: no such script")
                continue
            stop = mentions[k + 1].start() if k + 1 < len(mentions) else len(line)
            ticks = [t.start() for t in re.finditer(r"`+", line)]
            if not line.lstrip().startswith("|") and sum(t < m.start() for t in ticks) % 2:
                stop = min(stop, next((t for t in ticks if t > m.end()), stop))
            tail = _CELL_END.split(line[m.end():stop], maxsplit=1)[0]
            bad += [f"{shown}: {o} is not an option of it"
                    for o in _OPTION.findall(tail) if o not in options(script)]
    return bad


def test_shown_benchmark_commands_name_real_scripts_and_options():
    wrong = []
    for page in SCANNED:
        wrong += [f"{page.relative_to(ROOT)}: {w}"
                  for w in wrong_commands(page.read_text(encoding="utf-8"))]
    assert not wrong, "commands that cannot be typed as shown:\n" + "\n".join(wrong)


#: Options of other programs the two READMEs show (``git worktree add --detach``).
OTHER_PROGRAMS = {"--detach"}


def test_every_option_the_readmes_name_is_a_script_s():
    # prose names options without the script too ("both trees in one run: `--before TREE`")
    known = set().union(*(options(p) for f in FOLDERS for p in (ROOT / f).glob("*.py")))
    wrong = [f"{f}/README.md: {o}" for f in FOLDERS for o in sorted(set(_OPTION.findall(
        (ROOT / f / "README.md").read_text(encoding="utf-8"))) - known - OTHER_PROGRAMS)]
    assert not wrong, "options no benchmark or calibration script takes:\n" + "\n".join(wrong)


def test_a_retired_script_or_option_is_caught(tmp_path):
    # the checker itself: a command of a script that is gone, and an option a script lost
    (tmp_path / "benchmarks").mkdir()
    (tmp_path / "benchmarks" / "gpu_path.py").write_text(
        'import argparse\nap = argparse.ArgumentParser()\nap.add_argument("--tag")\n')
    retired = "benchmarks/" + "diagnose_suite.py"  # (joined here: written whole it would be a
    # dangling citation for test_citations)
    page = ("| `gpu_path.py` | the GPU path | `python benchmarks/gpu_path.py --tag cpu`; then"
            " `--tag gpu --reference cpu.json` | 7 min |\n"
            f"    python {retired} --removed   # base pieces\n"
            "`gpu_path.py --tag gpu` on the GPU, `--fresh` elsewhere | `--other` |\n"
            f"restore it: `git checkout 5dde407 -- {retired}`\n")
    # (the prose after a command's code span is not the command: `--fresh` is not read)
    assert wrong_commands(page, tmp_path) == [
        "benchmarks/gpu_path.py: --reference is not an option of it", f"{retired}: no such script"]
