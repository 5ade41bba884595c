"""Adding an effect is one file: a module with one ``AbstractEffect`` whose ``key`` is the
file stem (the library's own, ``hdid/effects/<key>.py``) or an installed package's module
under the ``hdid.effects`` entry-point group. Here a plugin package is "installed" on
``PYTHONPATH`` (a ``.dist-info`` with its entry point beside the module) and seen by
``--add``'s help, by ``hdid.effects.library``, by a fit and in the fit's derived table (the
quantities the effect declares, with their standard errors), by ``hdid diagnose`` (the
candidate it declares: starts, trial place, residual mark) and by the posterior (the
prior it declares), with no other edit.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

import hdid
from hdid.effects import _registry

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "data" / "synthetic" / "csf8_paper.csv"

COGGING = '''
from typing import ClassVar

import jax.numpy as jnp

import hdid


class Cogging(hdid.AbstractEffect):
    """Cogging: ``T = −a·sin(24 θ)`` [N m]. Residual mark: a 24-per-turn ripple."""

    amplitude: float = hdid.effects.parameter("N m", "cogging torque", transform="identity",
                                              scale=1e-4)
    name: ClassVar[str] = "cogging"
    key: ClassVar[str] = "cogging"
    candidate: ClassVar = hdid.effects.Candidate(
        trial=5, starts=lambda v: [{"amplitude": 0.01 * v["_k_wg"] * v["_swing"]}],
        mark="a 24-per-turn ripple in the residual", experiment="turn the motor slowly")
    posterior_prior: ClassVar[dict] = {"amplitude": (0.0, 1e-3)}

    @classmethod
    def start_from(cls, values):
        return cls(amplitude=values.get("amplitude", 0.0))

    def derived(self, inertia, k_wg):
        return {"cogging/inertia": self.amplitude / inertia}

    def torque(self, motion, state):
        return -self.amplitude * jnp.sin(24.0 * motion.theta)
'''


@pytest.fixture(scope="module")
def plugin(tmp_path_factory):
    site = tmp_path_factory.mktemp("site")
    (site / "hdid_cogging.py").write_text(COGGING)
    info = site / "hdid_cogging-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: hdid-cogging\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[hdid.effects]\ncogging = hdid_cogging\n")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join([str(site), os.environ.get("PYTHONPATH", "")])}
    return site, env


def _run(args, env, cwd):
    out = subprocess.run(args, capture_output=True, text=True, env=env, cwd=cwd, timeout=900)
    assert out.returncode == 0, out.stderr[-2000:]
    return out.stdout


def test_library_is_built_from_the_files():
    files = sorted(p.stem for p in (ROOT / "src" / "hdid" / "effects").glob("*.py")
                   if not p.stem.startswith("_"))
    assert _registry.builtin_keys() == files
    reg = _registry.registry()
    for key in files:
        assert reg[key].key == key and reg[key].__module__ == f"hdid.effects.{key}"
    assert sorted(hdid.effects.library(hdid.Model.default().float_values())) == sorted(reg)


def test_a_plugin_package_adds_an_effect_everywhere(plugin, tmp_path):
    site, env = plugin
    cli = [sys.executable, "-m", "hdid.cli"]
    assert "cogging" in _run([*cli, "fit", "--help"], env, tmp_path).replace("\n", " ")
    # hdid.effects.library and hdid.effects.Cogging: in the next test's process
    _run([*cli, "fit", str(PAPER), "--add", "cogging", "--starts", "2", "-q", "--json",
          "fit.json"], env, tmp_path)
    d = json.loads((tmp_path / "fit.json").read_text())
    assert "amplitude" in d["parameters"]
    assert any(e["class"] == "Cogging" for e in d["model"]["effects"])
    # the quantity it declares is in the derived table, with its delta-method std
    # (amplitude / inertia: the same relative error as the amplitude, the inertia fixed)
    amp = d["parameters"]["amplitude"]
    per_i = d["derived"]["cogging/inertia"]
    inertia = d["parameters"]["inertia"]["value"] if "inertia" in d["parameters"] else d["model"]["inertia"]
    assert per_i["value"] == pytest.approx(amp["value"] / inertia, rel=1e-9)
    assert per_i["std"] == pytest.approx(amp["std"] / inertia, rel=1e-6)


DIAGNOSE_AND_POSTERIOR = """
import json, sys
import hdid
hdid.configure()  # as the CLI does: programs from the persistent cache (tests/test_config.py checks the library without it)
from hdid._diagnosis._diagnose import default_candidates
from hdid._posterior.density import gaussian_prior

cands = [c.key for c in default_candidates()]
fit = hdid.fit(sys.argv[1], hdid.Model.default().with_effect(
    hdid.effects.library({})["cogging"]), n_starts=2)
G, _ = gaussian_prior(fit.problem, None)
i = list(fit.problem.free).index("amplitude")
d = hdid.diagnose(sys.argv[1], candidates=["cogging"], n_starts=1)
print(json.dumps({"library": sorted(hdid.effects.library({})),
                  "attribute": hdid.effects.Cogging is hdid.effects.registry()["cogging"],
                  "first": cands[0], "prior": [float(x) for x in G[:, i]],
                  "tried": [c.key for c in d.candidates],
                  "reasons": [c.reason for c in d.candidates]}))
"""


def test_a_plugins_candidate_and_prior_reach_diagnose_and_the_posterior(plugin, tmp_path):
    site, env = plugin
    out = json.loads(_run([sys.executable, "-c", DIAGNOSE_AND_POSTERIOR, str(PAPER)], env,
                          tmp_path).strip().splitlines()[-1])
    assert "cogging" in out["library"] and out["attribute"]  # hdid.effects.Cogging too
    assert out["first"] == "cogging"  # trial=5 puts it before the library's (10 …)
    assert out["prior"] == [0.0, 1e-3, 1.0]  # the declared (centre, sd) in use
    assert out["tried"] == ["cogging"]
    assert "24-per-turn ripple" in out["reasons"][0]  # the declared mark is reported


def test_a_plugin_may_not_take_a_library_key(tmp_path):
    site = tmp_path
    (site / "bad_plugin.py").write_text(COGGING.replace('"cogging"', '"viscous"'))
    info = site / "bad_plugin-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text("Metadata-Version: 2.1\nName: bad-plugin\nVersion: 0.1\n")
    (info / "entry_points.txt").write_text("[hdid.effects]\nviscous = bad_plugin\n")
    env = {**os.environ, "PYTHONPATH": str(site)}
    out = subprocess.run([sys.executable, "-c", "import hdid; hdid.effects.library({})"],
                         capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    assert out.returncode != 0 and "the name of a library effect" in out.stderr
