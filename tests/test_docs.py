"""The documentation site builds without a warning, and holds what the package holds.

``mkdocs build --strict`` (``mkdocs.yml``, ``docs/``) turns every warning into a failure: a
broken link, a docstring whose parameters do not match its signature, a page missing from
the build. The built site is then checked against the package itself: every public name
of ``hdid`` has its API entry, every field of the shipped JSON Schemas its row, every
command and option its place in the command-line reference. README.md and the pages cite
repository paths that must exist, and the README's test command is the one CI runs.
"""

from __future__ import annotations

import html
import importlib.util
import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PAGES = [ROOT / "README.md", *sorted((ROOT / "docs").rglob("*.md"))]
#: The issue's bound on the README (the rest lives in docs/).
README_MAX_LINES = 350
#: What the site build needs: the test extras install them (pyproject.toml).
BUILD_MODULES = ["mkdocs", "mkdocstrings", "mkdocstrings_handlers.python", "material"]


@pytest.fixture(scope="module")
def site(tmp_path_factory) -> Path:
    missing = [m for m in BUILD_MODULES if importlib.util.find_spec(m.split(".")[0]) is None
               or importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"the docs build needs {', '.join(missing)}: pip install '.[test]'")
    out = tmp_path_factory.mktemp("site")
    proc = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out),
         "--config-file", str(ROOT / "mkdocs.yml")],
        cwd=ROOT, capture_output=True, text=True, timeout=600,
        env={**__import__("os").environ, "NO_MKDOCS_2_WARNING": "1"},
    )
    log = proc.stdout + proc.stderr
    warnings = [line for line in log.splitlines() if re.match(r"\s*(WARNING|ERROR)\b", line)]
    assert proc.returncode == 0 and not warnings, "mkdocs build --strict failed:\n" + "\n".join(
        warnings or log.splitlines()[-30:])
    return out


def _text(path: Path) -> str:
    return html.unescape(path.read_text(encoding="utf-8"))


def test_every_public_name_has_its_api_entry(site):
    import hdid
    import hdid.effects

    anchors = set()
    for page in (site / "api").rglob("*.html"):
        anchors |= set(re.findall(r'id="(hdid[\w.]*)"', _text(page)))
    effects = set(hdid.effects.__all__)
    missing = [n for n in hdid.__all__
               if f"hdid.{n}" not in anchors and not (n in effects and f"hdid.effects.{n}" in anchors)]
    assert not missing, f"public names with no API entry (add `::: hdid.NAME` to docs/api/): {missing}"


def test_every_json_field_is_documented(site):
    page = _text(site / "json" / "index.html")
    for schema in sorted((ROOT / "src" / "hdid" / "schema").glob("*.schema.json")):
        fields = json.loads(schema.read_text(encoding="utf-8")).get("properties", {})
        missing = [f for f in fields if f"<code>{f}</code>" not in page]
        assert not missing, f"{schema.name}: fields missing from docs/json.md: {missing}"


def test_every_command_and_option_is_in_the_cli_reference(site):
    from hdid.cli import main

    page = _text(site / "cli" / "index.html")
    for name, command in main.commands.items():
        assert f"hdid {name}" in page, f"command {name} missing from docs/cli.md"
        for param in command.params:
            for opt in getattr(param, "opts", []):
                if opt.startswith("-"):
                    assert opt in page, f"hdid {name} {opt} missing from docs/cli.md"


def test_readme_is_short():
    lines = len((ROOT / "README.md").read_text(encoding="utf-8").splitlines())
    assert lines <= README_MAX_LINES, f"README.md has {lines} lines: move detail into docs/"


def test_readme_test_command_is_the_one_ci_runs():
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8").splitlines()
    install = next(line.strip() for line in ci if line.strip().startswith("pip install"))
    run = next(line.strip() for line in ci if line.strip().startswith("python -m pytest"))
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert f"{install} && {run}" in readme, (
        f"README.md's test command must be .ci/run's: `{install} && {run}`")


#: A repository path written in code style: `data/…`, `tests/…`, `benchmarks/…`, ….
_PATH = re.compile(r"`((?:src|tests|data|benchmarks|calibration|notebooks|docs|\.ci)/[^`\s]*)`")


def test_cited_repository_paths_exist():
    # a file renamed or retired leaves its citations behind: they must move with it
    missing = []
    for page in PAGES:
        for cited in _PATH.findall(page.read_text(encoding="utf-8")):
            path = cited.split("::")[0].rstrip(".,;:")
            if any(c in path for c in "<>*{}…") or path.endswith("/"):
                continue  # a pattern, not a file (src/hdid/effects/<key>.py)
            if not (ROOT / path).exists():
                missing.append(f"{page.relative_to(ROOT)}: {cited}")
    assert not missing, "cited paths that do not exist:\n" + "\n".join(missing)


def _options(command) -> set[str]:
    """The options a user may type (a hidden, renamed one is no longer documented)."""
    return {o for p in command.params if not getattr(p, "hidden", False)
            for o in [*getattr(p, "opts", []), *getattr(p, "secondary_opts", [])]}


def test_shown_hdid_commands_use_real_options():
    # every `hdid COMMAND …` line of a bash/console block, on every page, names a command
    # and options that exist: a renamed or retired option must leave the docs with it
    from hdid.cli import main

    wrong = []
    for page in PAGES:
        blocks = re.findall(r"^```(bash|console)\n(.*?)^```", page.read_text(encoding="utf-8"),
                            re.S | re.M)
        for kind, block in blocks:
            for line in block.splitlines():
                if kind == "console" and not line.startswith("$ "):
                    continue  # printed output
                for part in line.removeprefix("$ ").split("#")[0].split("&&"):
                    argv = shlex.split(part)
                    if not argv or argv[0] != "hdid" or argv[1:2] in (["--help"], ["--version"], []):
                        continue
                    if argv[1] not in main.commands:
                        wrong.append(f"{page.relative_to(ROOT)}: `{part.strip()}`: no command {argv[1]}")
                        continue
                    known = _options(main.commands[argv[1]]) | {"--help", "-h"}
                    unknown = [a.split("=")[0] for a in argv[2:]
                               if a.startswith("-") and a.split("=")[0] not in known and not _NUMBERLIKE.match(a)]
                    if unknown:
                        wrong.append(f"{page.relative_to(ROOT)}: `{part.strip()}`: unknown {unknown}")
    assert not wrong, "\n".join(wrong)


_NUMBERLIKE = re.compile(r"^-[\d.]")
#: Options of other programs the pages show (pytest, mkdocs, the reference-number script).
OTHER_PROGRAMS = {"--help", "--version", "--dist", "--strict", "--write"}


def test_every_option_named_in_the_docs_exists():
    # prose names options too ("with `--selection-steps N` it adds …"): each must be one a
    # user can type today
    from hdid.cli import main

    known = set().union(*(_options(c) for c in main.commands.values())) | OTHER_PROGRAMS
    wrong = []
    # the decision records are history, and name the options of the scripts that measured
    for page in (p for p in PAGES if "decisions" not in p.parts):
        named = set(re.findall(r"(?<![\w-])--[a-z][a-z0-9-]*", page.read_text(encoding="utf-8")))
        wrong += [f"{page.relative_to(ROOT)}: {o}" for o in sorted(named - known)]
    assert not wrong, "options the docs name that hdid does not have:\n" + "\n".join(wrong)


def test_effects_the_docs_name_are_the_library_s():
    # `--add NAME` / `--remove NAME` anywhere, and the effect table of the effects page
    # (`key` | `Class`), use the effects' current keys and class names (an old name still
    # works as an alias, but the docs teach the current one)
    from hdid.effects import registry

    reg = registry()
    current = {key for key, cls in reg.items() if cls.key == key}
    examples = {"cogging"}  # the effect a user writes in the effects page's example
    wrong = []
    for page in (p for p in PAGES if "decisions" not in p.parts):
        text = page.read_text(encoding="utf-8")
        for key in re.findall(r"--(?:add|remove) ([a-z_]+)", text):
            if key not in current | examples:
                wrong.append(f"{page.relative_to(ROOT)}: --add/--remove {key}")
        for key, cls in re.findall(r"^\| `([a-z_]+)` \| `([A-Z]\w+)` \|", text, re.M):
            if key not in current or reg[key].__name__ != cls:
                wrong.append(f"{page.relative_to(ROOT)}: table row {key} | {cls}")
    assert not wrong, "effect names that are not the library's current ones:\n" + "\n".join(wrong)


def test_python_the_docs_show_names_what_hdid_has():
    # every `hdid.NAME…` the pages write (prose and code) resolves, and every python block
    # compiles: a renamed or retired API leaves the docs with it
    import importlib

    import hdid

    wrong = []
    for page in (p for p in PAGES if "decisions" not in p.parts):
        text = page.read_text(encoding="utf-8")
        for dotted in sorted(set(re.findall(r"\bhdid((?:\.[A-Za-z_]\w*)+)", text))):
            parts, obj = dotted.lstrip(".").split("."), hdid
            for i, part in enumerate(parts):
                try:
                    obj = getattr(obj, part)
                except AttributeError:
                    try:
                        obj = importlib.import_module("hdid." + ".".join(parts[: i + 1]))
                    except ImportError:
                        wrong.append(f"{page.relative_to(ROOT)}: hdid{dotted}")
                        break
        for code in re.findall(r"^```python\n(.*?)^```", text, re.S | re.M):
            try:
                compile(code, str(page), "exec")
            except SyntaxError as exc:
                wrong.append(f"{page.relative_to(ROOT)}: python block does not compile: {exc}")
    assert not wrong, "\n".join(wrong)
