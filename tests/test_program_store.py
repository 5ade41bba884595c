"""The program store keys each program on the source its trace ran (issue 37,
:mod:`hdid._problems._program_deps`): an edit to a file the trace ran, or to a constant it
read, is a miss (a stale program would be a silent wrong answer); an edit to a module no
trace ran is a hit (the store stays warm across commits that touch other modules).

Each "new process" below is simulated in this one: compiled programs, memoised keys and
cached hashes dropped, the edited modules reloaded, and the process start (files
modified after it are in doubt) moved past the edits."""

from __future__ import annotations

import importlib
import os
import subprocess
import sys
import textwrap
import time
from collections import OrderedDict
from pathlib import Path

import jax.numpy as jnp
import numpy as np
import pytest

from hdid._problems import _program_deps, _program_keys, _program_trace, _programs

SRC = Path(__file__).resolve().parents[1] / "src"

FILES = {
    "__init__.py": "",
    # a.f reads K, which b computes at import from c.C: c is two imports away
    "a.py": "import jax.numpy as jnp\nfrom .b import K\n\n\ndef f(x):\n    return jnp.sin(x) * K\n",
    "b.py": "from .c import C\n\nK = C + 1.0\n",
    "c.py": "C = 1.0\n",
    # a loop body that two programs share (JAX traces it once per process)
    "body.py": "import jax.numpy as jnp\n\n\ndef body(c):\n    return c * 0.5 + jnp.cos(c)\n",
    "loops.py": textwrap.dedent("""\
        from jax import lax
        from .body import body


        def cond(c):
            return c < 5.0


        def first(x):
            return lax.fori_loop(0, 3, lambda i, c: body(c), x)


        def second(x):
            return lax.fori_loop(0, 3, lambda i, c: body(c), x) + 1.0
        """),
    "other.py": "def unrelated():\n    return 1\n",
}


@pytest.fixture
def pkg(tmp_path, monkeypatch):
    """A package ``storepkg`` of the files above, and a store of its own."""
    root = tmp_path / "src"
    (root / "storepkg").mkdir(parents=True)
    for name, text in FILES.items():
        (root / "storepkg" / name).write_text(text)
    monkeypatch.syspath_prepend(str(root))
    monkeypatch.setattr(sys, "dont_write_bytecode", True)
    monkeypatch.setenv("HDID_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("HDID_PROGRAM_STORE", raising=False)
    monkeypatch.delenv("HDID_NO_CACHE", raising=False)
    _new_process(monkeypatch)
    yield root / "storepkg"
    for m in [m for m in sys.modules if m.split(".")[0] == "storepkg"]:
        del sys.modules[m]
    _program_deps.forget()


def _new_process(monkeypatch):
    monkeypatch.setattr(_programs, "_LOADED", OrderedDict())
    monkeypatch.setattr(_program_keys, "KEYS", OrderedDict())
    monkeypatch.setattr(_program_keys, "MODULES", OrderedDict())
    monkeypatch.setattr(_program_keys, "TOKENS", {})
    _program_deps.forget()
    monkeypatch.setattr(_program_deps, "T0", time.time() + 1.0)


def _edit(path: Path, old: str, new: str, monkeypatch, *reload):
    """Edit a file, then start a "new process" that imports the package afresh."""
    text = path.read_text()
    assert old in text
    path.write_text(text.replace(old, new))
    importlib.invalidate_caches()
    for m in [m for m in sys.modules if m.split(".")[0] == "storepkg"]:
        del sys.modules[m]
    _new_process(monkeypatch)


def _how(name, fn, *args):
    n = len(_programs.STATS)
    out = _programs.call(name, fn, *args)
    rows = _programs.STATS[n:]
    return (rows[-1]["how"] if rows else "loaded"), np.asarray(out)


def _imported_f_is(x, how: str, want) -> None:
    """``storepkg.a.f(x)`` imported afresh is ``how`` ("traced"/"stored") and gives ``want``."""
    a = importlib.import_module("storepkg.a")
    got, out = _how("f", a.f, x)
    assert got == how
    np.testing.assert_allclose(out, want, rtol=1e-14)


def test_an_edit_to_a_traced_file_or_a_constant_it_reads_misses_and_another_hits(pkg, monkeypatch):
    x = np.linspace(0.1, 1.0, 4)
    a = importlib.import_module("storepkg.a")
    how, out = _how("f", a.f, x)
    assert how == "traced"
    np.testing.assert_allclose(out, np.sin(x) * 2.0, rtol=1e-14)
    rec = _program_deps.record(_program_trace.object_files([a.f]))
    assert rec is not None and str(pkg / "a.py") in rec["files"]

    # an unrelated module changes: the stored program is used (no trace)
    _edit(pkg / "other.py", "return 1", "return 2", monkeypatch)
    _imported_f_is(x, "stored", np.sin(x) * 2.0)

    # c.C changes: a.f's file is the same, but K (b's constant, from c) is not
    _edit(pkg / "c.py", "C = 1.0", "C = 2.25", monkeypatch)
    _imported_f_is(x, "traced", np.sin(x) * 3.25)

    # the traced file itself changes
    _edit(pkg / "a.py", "jnp.sin(x) * K", "jnp.cos(x) * K", monkeypatch)
    _imported_f_is(x, "traced", np.cos(x) * 3.25)

    # and back: the first version is still stored, and its numbers come back
    _edit(pkg / "a.py", "jnp.cos(x) * K", "jnp.sin(x) * K", monkeypatch)
    _edit(pkg / "c.py", "C = 2.25", "C = 1.0", monkeypatch)
    _imported_f_is(x, "stored", np.sin(x) * 2.0)


def test_a_loop_body_jax_reuses_from_its_cache_is_still_a_dependency(pkg, monkeypatch):
    """The second program's trace does not run ``body`` (JAX reuses the loop body traced
    for the first): the body's file must still be recorded, so an edit to it misses."""
    x = np.asarray(0.3)
    loops = importlib.import_module("storepkg.loops")
    assert _how("first", loops.first, x)[0] == "traced"
    how, before = _how("second", loops.second, x)
    assert how == "traced"

    _edit(pkg / "body.py", "c * 0.5", "c * 0.75", monkeypatch)
    loops = importlib.import_module("storepkg.loops")
    how, after = _how("second", loops.second, x)
    assert how == "traced"
    c = 0.3
    for _ in range(3):
        c = c * 0.75 + np.cos(c)
    np.testing.assert_allclose(after, c + 1.0, rtol=1e-14)
    assert not np.allclose(after, before)
    # every stored version (first; second before and after the edit) names the body
    store = _programs._store()
    deps = [v["deps"]["files"] for f in store.glob("*.deps")
            for v in _programs._versions(store, f.name[:-len(".deps")])]
    assert len(deps) == 3 and all(str(pkg / "body.py") in d for d in deps)


def test_a_file_written_after_the_process_started_is_not_trusted(pkg, monkeypatch):
    """Code imported from a file modified after this process started may not be the
    file's: the program runs, but is not stored."""
    monkeypatch.setattr(_program_deps, "T0", time.time() - 60.0)
    a = importlib.import_module("storepkg.a")
    n = len(_programs.UNSTORED)
    how, _ = _how("f", a.f, np.ones(2))
    assert how == "traced" and [u[0] for u in _programs.UNSTORED[n:]] == ["f"]
    assert not list(_programs._store().glob("*.exp"))

    # files hdid noted as read after a moment (the command line's --effect-file) are
    # trusted until modified after it
    _new_process(monkeypatch)
    monkeypatch.setattr(_program_deps, "T0", time.time() - 60.0)
    monkeypatch.setattr(_program_deps, "LOADED", {})
    for m in [m for m in sys.modules if m.split(".")[0] == "storepkg"]:
        del sys.modules[m]
    before = time.time()
    a = importlib.import_module("storepkg.a")
    for f in pkg.iterdir():
        _program_deps.loaded(f, before)
    assert _how("f", a.f, np.ones(2))[0] == "traced"
    assert len(list(_programs._store().glob("*.exp"))) == 1
    _new_process(monkeypatch)
    monkeypatch.setattr(_program_deps, "T0", time.time() - 60.0)
    assert _how("f", a.f, np.ones(2))[0] == "stored"
    time.sleep(0.01)
    (pkg / "a.py").write_text((pkg / "a.py").read_text() + "# edited after it was read\n")
    _new_process(monkeypatch)
    monkeypatch.setattr(_program_deps, "T0", time.time() - 60.0)
    assert _how("f", a.f, np.ones(2))[0] == "traced"


TINY = textwrap.dedent("""\
    import numpy as np
    from hdid._models import _transforms


    def interval(u):
        return _transforms.interval_from_u(u, 0.5, 2.0)
    """)

RUN = textwrap.dedent("""\
    import sys, numpy as np
    import hdid
    hdid.configure()
    from hdid._problems import _programs
    import tiny
    out = _programs.call("interval", tiny.interval, np.linspace(-2.0, 2.0, 5))
    print([s["how"] for s in _programs.STATS], np.asarray(out).tolist())
    """)


def test_hdid_edits_outside_the_trace_keep_the_store_warm(tmp_path):
    """A copy of hdid in three fresh processes: the program is traced and stored; after
    an edit to the posterior (no trace runs it) a new process reads it; after an edit to
    the transform the program runs (``_models/_transforms.py``), a new process traces
    it again."""
    import shutil

    src = tmp_path / "src"
    shutil.copytree(SRC / "hdid", src / "hdid", ignore=shutil.ignore_patterns("__pycache__"))
    (tmp_path / "tiny.py").write_text(TINY)
    env = {**os.environ, "HDID_CACHE_DIR": str(tmp_path / "cache"),
           "PYTHONPATH": os.pathsep.join([str(src), str(tmp_path)]),
           "PYTHONDONTWRITEBYTECODE": "1"}
    env.pop("HDID_PROGRAM_STORE", None)
    env.pop("HDID_NO_CACHE", None)

    def run():
        time.sleep(0.2)  # (files edited before the process starts are trusted)
        r = subprocess.run([sys.executable, "-c", RUN], capture_output=True, text=True,
                           env=env, timeout=300, cwd=tmp_path)
        assert r.returncode == 0, r.stderr[-3000:]
        return r.stdout.strip().splitlines()[-1]

    first = run()
    assert first.startswith("['traced']")
    with open(src / "hdid" / "_posterior" / "density.py", "a") as f:
        f.write("\n# an edit no trace runs\n")
    assert run() == first.replace("traced", "stored")
    with open(src / "hdid" / "_models" / "_transforms.py", "a") as f:
        f.write("\n# an edit to a file the trace ran\n")
    assert run() == first


def test_a_recorded_file_left_in_place_does_not_stand_for_another_copy(tmp_path, monkeypatch):
    """Two copies of one effect file (a test's temporary folders, say): a program traced
    with the first copy's class must not be used for the second's, even while the first
    file still exists unchanged — the second copy's code may differ."""
    import importlib.util

    monkeypatch.setenv("HDID_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.delenv("HDID_PROGRAM_STORE", raising=False)
    monkeypatch.delenv("HDID_NO_CACHE", raising=False)

    def load(folder, factor):
        folder.mkdir()
        path = folder / "gain.py"
        path.write_text(f"def gain(x):\n    return x * {factor}\n")
        spec = importlib.util.spec_from_file_location("gain_effect", path)
        module = importlib.util.module_from_spec(spec)
        before = time.time()
        spec.loader.exec_module(module)  # (as the command line's --effect-file)
        _program_deps.loaded(path, before)
        return module.gain

    _new_process(monkeypatch)
    monkeypatch.setattr(_program_deps, "LOADED", {})
    x = np.arange(3.0)
    how, out = _how("gain", load(tmp_path / "one", 2.0), x)
    assert how == "traced" and np.allclose(out, 2.0 * x)
    _new_process(monkeypatch)
    monkeypatch.setattr(_program_deps, "LOADED", {})
    how, out = _how("gain", load(tmp_path / "two", 3.0), x)
    assert how == "traced" and np.allclose(out, 3.0 * x)
    # a third copy, byte for byte the first: the first's program serves it
    _new_process(monkeypatch)
    monkeypatch.setattr(_program_deps, "LOADED", {})
    how, out = _how("gain", load(tmp_path / "three", 2.0), x)
    assert how == "stored" and np.allclose(out, 2.0 * x)


def test_a_process_s_state_is_not_a_module_s_constants(pkg, monkeypatch):
    """A module's recorded constants are what its source makes of it, seen as they are
    now: not the public names ``hdid.__getattr__`` keeps once used (a fresh process
    lacks them, so it missed every program stored after ``hdid.Model`` was used), and
    not a cached hash of an earlier state (a constant rebound since is seen, and a miss
    names the module)."""
    import hdid
    from hdid._problems import _program_values

    monkeypatch.delitem(vars(hdid), "Model", raising=False)
    before = _program_values.values("hdid", hdid.__file__)
    assert hdid.Model and "Model" in vars(hdid)
    assert _program_values.values("hdid", hdid.__file__) == before

    b = importlib.import_module("storepkg.b")
    rec = _program_deps.record({b.__file__})
    assert rec is not None and "storepkg.b" in rec["values"]
    assert _program_deps.mismatch(rec) is None
    monkeypatch.setattr(b, "K", 3.0)
    assert _program_deps.mismatch(rec).startswith("constants of storepkg.b: recorded ")
    monkeypatch.setattr(b, "K", 2.0)  # (C + 1.0: the source's value)
    assert _program_deps.mismatch(rec) is None
