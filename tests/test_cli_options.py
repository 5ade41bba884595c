"""A command line a person can scan: options under headings, one meaning per option name,
`--add` offering only what can be added, flags (not Python arguments) in messages, output
paths opened up front, and `hdid simulate` saying and storing the values it used.

Cheap by design: help texts and refusals before any fit; where a command would fit, the
fit is replaced by a stub (the refusal must come before it) and only `simulate` runs.
"""

from __future__ import annotations

import json
import os
import re
from pathlib import Path
from types import SimpleNamespace

import pytest
from click.testing import CliRunner

import hdid
import hdid._diagnosis._diagnose
import hdid._fitting._fit
import hdid._posterior
import hdid._simulation._synthetic
from hdid.cli import main

ROOT = Path(__file__).resolve().parents[1]
EXAMPLE = ROOT / "data" / "synthetic" / "csf8_paper.csv"
DRIVEN = ROOT / "data" / "synthetic" / "driven_csf8.csv"
TRUTH = ROOT / "data" / "synthetic" / "truth.json"


class _Stop(Exception):
    """A stubbed fit or diagnosis was reached: every check before it passed."""


def _stop(*args, **kwargs):
    raise _Stop


@pytest.fixture
def no_fit(monkeypatch):
    monkeypatch.setattr(hdid._fitting._fit, "fit", _stop)
    monkeypatch.setattr(hdid._diagnosis._diagnose, "diagnose", _stop)
    monkeypatch.setattr(hdid._simulation._synthetic, "synthesize", _stop)


def _help_sections(command: str) -> dict[str, str]:
    """``{heading: text under it}`` of ``hdid COMMAND --help``, in order."""
    res = CliRunner().invoke(main, [command, "--help"])
    assert res.exit_code == 0, res.output
    sections, current = {}, None
    for line in res.output.splitlines():
        if line and not line.startswith(" ") and line.endswith(":"):
            current = line[:-1]
            sections[current] = ""
        elif current is not None:
            sections[current] += line + "\n"
    return sections


def _options_in(text: str) -> list[str]:
    return re.findall(r"^  (?:-\w, )?(--[\w-]+)", text, flags=re.M)


def _one_line_exit_2(res, fragment: str) -> str:
    assert res.exception is None or isinstance(res.exception, SystemExit), repr(res.exception)
    assert res.exit_code == 2, res.output
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hdid: error:"), res.stderr
    assert fragment in lines[0], lines[0]
    return lines[0]


# --- 1. options under headings, in the order a user needs them -------------------------

EXPECTED_GROUPS = {
    "fit": [("Input", "--counts-per-rev"), ("Model", "--add"), ("Fit", "--starts"),
            ("Output", "--json"), ("Posterior", "--steps"), ("Batch", "--summary"),
            ("Driven", "--torque-constant")],
    "diagnose": [("Input", "--resolution"), ("Model", "--fix"),
                 ("Diagnosis", "--selection-steps"), ("Output", "--json")],
    "simulate": [("Model", "--set"), ("Design", "--amplitudes"),
                 ("Encoder", "--counts-per-rev"), ("Output", "--overwrite")],
}


@pytest.mark.parametrize("command", sorted(EXPECTED_GROUPS))
def test_help_groups_the_options_under_headings(command):
    sections = _help_sections(command)
    headings = [h for h in sections if h not in ("Usage", "Other options")]
    expected = EXPECTED_GROUPS[command]
    assert [h.split()[0].rstrip(":") for h in headings] == [w for w, _ in expected], headings
    for (word, option), heading in zip(expected, headings):
        assert option in _options_in(sections[heading]), (heading, sections[heading])
    # every option of the command sits under some heading but --help
    grouped = [o for h in headings for o in _options_in(sections[h])]
    assert _options_in(sections.get("Other options", "")) == ["--help"]
    assert len(grouped) == len(set(grouped))


def test_fit_help_lists_output_before_batch_posterior_and_driven():
    order = [o for h, text in _help_sections("fit").items() for o in _options_in(text)]
    for late in ("--summary", "--workers", "--dask", "--posterior", "--torque-constant"):
        assert order.index("--json") < order.index(late) and order.index("--plot") < order.index(late)


# --- 2. one meaning per option name -----------------------------------------------------

def test_steps_means_the_chain_length_only():
    fit = _help_sections("fit")
    assert "--steps" in _options_in(next(t for h, t in fit.items() if h.startswith("Posterior")))
    diag = _help_sections("diagnose")
    shown = [o for t in diag.values() for o in _options_in(t)]
    assert "--steps" not in shown and "--selection-steps" in shown


@pytest.fixture
def diagnose_spy(monkeypatch):
    seen = {}

    def spy(data, model, **kwargs):
        seen.update(kwargs)
        raise _Stop

    monkeypatch.setattr(hdid._diagnosis._diagnose, "diagnose", spy)
    return seen


@pytest.mark.parametrize("args, steps, warned", [
    ([], 1, False),
    (["--selection-steps", "2"], 2, False),
    (["--steps", "3"], 3, True),  # the former name: still accepted, with a warning
    (["--steps", "2", "--selection-steps", "2"], 2, True),
])
def test_diagnose_selection_steps_and_its_former_name(diagnose_spy, args, steps, warned):
    res = CliRunner().invoke(main, ["diagnose", str(EXAMPLE), *args])
    assert isinstance(res.exception, _Stop), res.output
    assert diagnose_spy["steps"] == steps
    assert ("--steps is now --selection-steps" in res.stderr) is warned, res.stderr


def test_diagnose_steps_and_selection_steps_that_disagree_are_refused(diagnose_spy):
    res = CliRunner().invoke(main, ["diagnose", str(EXAMPLE), "--steps", "2",
                                    "--selection-steps", "3"])
    _one_line_exit_2(res, "--selection-steps alone")
    assert not diagnose_spy


# --- 3. --add offers what can be added ---------------------------------------------------

def _add_help() -> str:
    model = _help_sections("fit")["Model"]
    block = model.split("  --add", 1)[1].split("\n  --", 1)[0]
    return " ".join(block.split())


def _base_keys() -> set[str]:
    return {type(e).key for e in hdid.Model.default().effects}


def test_add_help_offers_only_effects_that_can_be_added():
    from hdid.effects import registry

    text = _add_help()
    offered = set()
    for part in re.findall(r"(?:New terms|replacing \w+): ([\w, ]+)", text):
        offered |= {k.strip() for k in part.split(",") if k.strip()}
    addable = {cls.key for cls in registry().values()} - _base_keys()
    assert offered == addable, text
    assert "in already" in text and all(k in text for k in _base_keys())  # says why


@pytest.mark.parametrize("key", sorted({"stiffness", "stribeck", "viscous"}))
def test_add_of_a_base_effect_is_refused_before_the_fit(no_fit, key):
    assert key in _base_keys()
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--add", key])
    _one_line_exit_2(res, "already")


@pytest.mark.parametrize("args", [
    ["--add", "gravity"],
    ["--remove", "viscous", "--add", "viscous"],  # put back after --remove: allowed
])
def test_addable_effects_reach_the_fit(no_fit, args):
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), *args])
    assert isinstance(res.exception, _Stop), res.output


def test_an_old_effect_name_stays_an_alias(no_fit, monkeypatch):
    # A renamed effect keeps its former key in the registry, mapping to the same class:
    # --add takes it, and --help offers the class once, by its current key.
    from hdid.effects import registry

    reg = registry()
    monkeypatch.setitem(reg, "old_gravity", reg["gravity"])
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--add", "old_gravity"])
    assert isinstance(res.exception, _Stop), res.output
    assert "old_gravity" not in _add_help()


# --- 4. messages name flags, not Python arguments ----------------------------------------

@pytest.mark.parametrize("library, shown", [
    # the posterior's messages name the Python argument and the flag: the flag stays
    ("n_walkers (--walkers) = 4: raise n_walkers (--walkers) to 16",
     "--walkers = 4: raise --walkers to 16"),
    ("the prior (prior= / --prior NAME=VALUE,SD) names ['foo']",
     "the prior (--prior NAME=VALUE,SD) names ['foo']"),
    ("try method='smc' (--sampler smc) or fix it, --fix / fix=", "try --sampler smc or fix it, --fix"),
    ("Raise n_particles (--particles) to 600", "Raise --particles to 600"),
])
def test_a_message_naming_argument_and_flag_shows_the_flag(library, shown):
    from hdid.cli._flags import to_flags

    assert to_flags(library, "fit") == shown


def test_a_library_error_reaches_the_user_as_flags():
    # read_log's message names its keyword argument torque_constant
    res = CliRunner().invoke(main, ["fit", str(DRIVEN), "--torque-constant", "0.05"])
    line = _one_line_exit_2(res, "--torque-constant")
    assert "torque_constant" not in line


def test_posterior_advice_names_the_steps_flag(monkeypatch):
    # The posterior's own wording (hdid._posterior.driver), printed through the CLI.
    advice = ("NOT CONVERGED: after 20000 steps (400 burn-in before) the worst quantity is "
              "k2 (R-hat 1.2). Run longer (max_steps ≥ 40000); supply "
              "prior={'k2': (value, sd)} from a datasheet; raise n_particles")
    fake_fit = SimpleNamespace(report=lambda: "fit report", to_dict=lambda: {})
    fake_post = SimpleNamespace(report=lambda: advice, to_dict=lambda: {})
    monkeypatch.setattr(hdid._fitting._fit, "fit", lambda *a, **k: fake_fit)
    monkeypatch.setattr(hdid._posterior, "sample_posterior", lambda *a, **k: fake_post)
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--posterior"])
    assert res.exit_code == 0, res.output
    assert "--steps ≥ 40000" in res.stdout and "max_steps" not in res.stdout
    assert "--prior k2=VALUE,SD" in res.stdout and "--particles" in res.stdout


def test_particles_is_a_flag_for_smc(monkeypatch):
    seen = {}
    fake_fit = SimpleNamespace(report=lambda: "", to_dict=lambda: {})

    def post(fit, **kwargs):
        seen.update(kwargs)
        return SimpleNamespace(report=lambda: "", to_dict=lambda: {})

    monkeypatch.setattr(hdid._fitting._fit, "fit", lambda *a, **k: fake_fit)
    monkeypatch.setattr(hdid._posterior, "sample_posterior", post)
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "-q", "--posterior", "--sampler",
                                    "smc", "--particles", "600"])
    assert res.exit_code == 0, res.output
    assert seen["method"] == "smc" and seen["n_particles"] == 600



def test_default_prior_is_a_posterior_flag(monkeypatch, no_fit):
    # weak by default; flat (the earlier flat-in-value priors) one flag away; only with
    # the posterior, refused before any fit otherwise
    seen = {}
    fake_fit = SimpleNamespace(report=lambda: "", to_dict=lambda: {})

    def post(fit, **kwargs):
        seen.update(kwargs)
        return SimpleNamespace(report=lambda: "", to_dict=lambda: {})

    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--default-prior", "flat"])
    assert "--posterior" in _one_line_exit_2(res, "--default-prior")
    monkeypatch.setattr(hdid._fitting._fit, "fit", lambda *a, **k: fake_fit)
    monkeypatch.setattr(hdid._posterior, "sample_posterior", post)
    for args, want in (([], "weak"), (["--default-prior", "flat"], "flat")):
        seen.clear()
        res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "-q", "--posterior", *args])
        assert res.exit_code == 0, res.output
        assert seen["default_prior"] == want

#: The library's Python names that have a flag (hdid/cli/_flags.py maps them).
_PYTHON_NAMES = re.compile(r"(?<![-.\w])(max_steps|n_steps|n_walkers|n_particles|max_rounds|"
                           r"torque_constant|output_counts_per_rev|band_bracket|workers=|"
                           r"method=|prior=\{)")


def _library_messages():
    """Every string the library builds outside docstrings (an f-string with X for each
    value), with its place: where a message the command line prints is written."""
    import ast

    for path in sorted((ROOT / "src" / "hdid").rglob("*.py")):
        if "cli" in path.relative_to(ROOT / "src" / "hdid").parts:
            continue
        tree = ast.parse(path.read_text())
        skip = set()
        for node in ast.walk(tree):
            body = getattr(node, "body", None)
            if (isinstance(node, (ast.Module, ast.ClassDef, ast.FunctionDef, ast.AsyncFunctionDef))
                    and body and isinstance(body[0], ast.Expr)
                    and isinstance(body[0].value, ast.Constant)):
                skip.add(id(body[0].value))
            if isinstance(node, ast.JoinedStr):
                skip |= {id(v) for v in node.values}
        for node in ast.walk(tree):
            if id(node) in skip:
                continue
            if isinstance(node, ast.JoinedStr):
                text = "".join(v.value if isinstance(v, ast.Constant) else "X" for v in node.values)
            elif isinstance(node, ast.Constant) and isinstance(node.value, str):
                text = node.value
            else:
                continue
            if " " in text:  # a message, not a dict key
                yield f"{path.relative_to(ROOT)}:{node.lineno}", text


def test_every_library_message_naming_a_python_argument_is_mapped_to_its_flag():
    from hdid.cli._flags import to_flags

    found = [(where, text) for where, text in _library_messages() if _PYTHON_NAMES.search(text)]
    assert found  # the library does speak Python: the posterior's advice, read_log's errors
    left = [(where, to_flags(text, "fit")) for where, text in found
            if _PYTHON_NAMES.search(to_flags(text, "fit"))]
    assert not left, f"add a rule to hdid/cli/_flags.py for: {left}"
    # a message naming both ("n_walkers (--walkers)", "prior= / --prior") shows the flag once
    doubled = [(where, to_flags(text, "fit")) for where, text in found
               if re.search(r"(--[\w-]+)\W+\1\b", to_flags(text, "fit"))]
    assert not doubled, doubled


def test_diagnose_advice_names_its_own_flag():
    from hdid.cli._flags import to_flags

    # hdid._diagnosis._verdict's advice, as diagnose prints it
    text = "probably not in the library (or several effects are missing: try --steps 2)"
    assert to_flags(text, "diagnose").endswith("try --selection-steps 2)")
    for where, text in _library_messages():  # and wherever the diagnosis says it
        if "_diagnosis" in where and "--steps" in text:
            assert not re.search(r"--steps\b", to_flags(text, "diagnose")), where


# --- 5. output paths are opened up front -------------------------------------------------

@pytest.mark.skipif(not Path("/proc/self").is_dir(), reason="needs /proc")
@pytest.mark.parametrize("command, args", [
    ("fit", [str(EXAMPLE), "--json"]),
    ("fit", [str(EXAMPLE), "--plot"]),
    ("diagnose", [str(EXAMPLE), "--json"]),
    ("simulate", []),
])
def test_an_unwritable_output_fails_at_once(no_fit, command, args):
    # /proc accepts no new file, even for root (whom os.access lets write anywhere)
    target = "/proc/x.png" if args[-1:] == ["--plot"] else "/proc/x.json"
    res = CliRunner().invoke(main, [command, *args, target])
    _one_line_exit_2(res, "cannot write")


def test_the_probe_leaves_files_as_they_were(no_fit, tmp_path):
    kept = tmp_path / "kept.json"
    kept.write_text("the user's file\n")
    os.utime(kept, (1_000_000_000, 1_000_000_000))
    new = tmp_path / "new.json"
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--json", str(kept)])
    assert isinstance(res.exception, _Stop)  # got past the check to the (stub) fit
    assert kept.read_text() == "the user's file\n" and kept.stat().st_mtime == 1_000_000_000
    res = CliRunner().invoke(main, ["fit", str(EXAMPLE), "--json", str(new)])
    assert isinstance(res.exception, _Stop)
    assert not new.exists()  # the probe file is gone


# --- 6. hdid simulate says and stores what it used --------------------------------------

def test_simulate_defaults_are_the_readmes_example_truth():
    from hdid.cli.simulate import EXAMPLE_TRUTH

    truth = json.loads(TRUTH.read_text())
    for name in ("csf8_paper.csv", "csf8_rich_1khz.csv"):
        assert truth[name]["params"] == EXAMPLE_TRUTH, name


@pytest.fixture(scope="module")
def simulated(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "my.csv"
    res = CliRunner().invoke(main, ["simulate", str(out), "--amplitudes", "0.1,-0.1",
                                    "--duration", "0.06", "--set", "k1=1200"])
    return res, out


def test_simulate_prints_the_values_it_used(simulated):
    res, out = simulated
    assert res.exit_code == 0, res.output
    from hdid.cli.simulate import EXAMPLE_TRUTH

    expected = {**EXAMPLE_TRUTH, "k1": 1200.0}
    printed = dict(re.findall(r"^  (\w+)\s+(\S+)", res.stdout, flags=re.M))
    assert set(printed) == set(expected), res.stdout
    for name, value in expected.items():
        # printed to 6 significant digits
        assert float(printed[name]) == pytest.approx(value, rel=1e-6), name


def test_simulate_stores_the_values_beside_the_log(simulated):
    res, out = simulated
    from hdid._results._saved import model_from_structure
    from hdid.cli.simulate import EXAMPLE_TRUTH

    stored = json.loads(out.with_suffix(".truth.json").read_text())
    assert stored["params"] == {**EXAMPLE_TRUTH, "k1": 1200.0}
    assert stored["fs"] == 1000.0 and [r["theta0"] for r in stored["runs"]] == [0.1, -0.1]
    rebuilt = model_from_structure(stored["model"])
    assert rebuilt.float_values() == stored["params"]
    assert len(hdid.read_log(out).runs) == 2  # the log itself reads as before


def test_simulate_never_replaces_a_parameter_file_unasked(tmp_path):
    (tmp_path / "x.truth.json").write_text("{}")
    res = CliRunner().invoke(main, ["simulate", str(tmp_path / "x.csv")])
    _one_line_exit_2(res, "x.truth.json exists")
    assert not (tmp_path / "x.csv").exists()


def test_simulate_set_of_an_unknown_parameter_names_the_flag(tmp_path, no_fit):
    res = CliRunner().invoke(main, ["simulate", str(tmp_path / "x.csv"), "--set", "k9=1"])
    _one_line_exit_2(res, "--set k9")
    assert not list(tmp_path.iterdir())  # nothing written
