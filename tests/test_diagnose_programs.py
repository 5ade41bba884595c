"""The program store (:mod:`hdid._programs`) that lets ``hdid diagnose`` skip tracing in a
later process: same numbers as the jit path, keyed by everything that shapes the program,
and a stored program that uses LAPACK runs in a fresh process (it segfaulted before the
CPU handlers were registered on load)."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from hdid import _programs

SRC = Path(__file__).resolve().parents[1] / "src"


class _Spring(eqx.Module):
    k: jnp.ndarray
    power: float = eqx.field(static=True)


def _solve(spring, a, b):
    """A LAPACK program (Cholesky and a triangular solve, as the LM's damped step)."""
    import jax.scipy.linalg as jsl

    c = jnp.linalg.cholesky(a * spring.k + a.T * spring.k)
    return jsl.solve_triangular(c, b, lower=True) ** spring.power


def _wave(spring, a, b):
    """A program without LAPACK calls."""
    return (jnp.sin(a * spring.k) @ b) ** spring.power


@pytest.fixture
def store(tmp_path, monkeypatch):
    monkeypatch.setenv("HDID_CACHE_DIR", str(tmp_path))
    monkeypatch.setenv("HDID_PROGRAM_STORE", "1")
    monkeypatch.delenv("HDID_NO_CACHE", raising=False)
    monkeypatch.setattr(_programs, "_LOADED", {})
    return tmp_path / "programs"


def _args(power=2.0, n=3):
    a = np.eye(n) * 2.0 + 0.1
    return _Spring(jnp.asarray(1.5), power), a, np.arange(1.0, n + 1)


def test_same_numbers_as_jit_and_a_stored_program(store):
    args = _args()
    out = _programs.call("solve", _solve, *args)
    np.testing.assert_allclose(out, eqx.filter_jit(_solve)(*args), rtol=1e-14)
    assert len(list(store.glob("*.bin"))) == 1


def test_key_follows_static_fields_and_shapes(store, monkeypatch):
    _programs.call("wave", _wave, *_args())
    _programs.call("wave", _wave, *_args(power=3.0))  # static field: another program
    _programs.call("wave", _wave, *_args(n=4))  # another shape: another program
    _programs.call("wave", _wave, *_args())  # the first again: no new file
    assert len(list(store.glob("*.bin"))) == 3
    # a new process (nothing loaded) reads the file (or, where XLA cannot restore it,
    # compiles again: seen with several programs sharing kernel names) — same numbers
    monkeypatch.setattr(_programs, "_LOADED", {})
    args = _args(power=3.0)
    np.testing.assert_allclose(_programs.call("wave", _wave, *args),
                               eqx.filter_jit(_wave)(*args), rtol=1e-14)


def test_stored_lapack_program_runs_in_a_fresh_process(store, tmp_path):
    """A fresh process loads (or, where XLA cannot restore it, recompiles) the program and
    gets the same numbers: before the CPU LAPACK handlers were registered on load this
    was a segfault, and an unrestorable executable an exception."""
    _programs.call("solve", _solve, *_args())
    code = textwrap.dedent(f"""
        import sys, numpy as np
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        from hdid import _programs
        import test_diagnose_programs as t
        print(repr(np.asarray(_programs.call("solve", t._solve, *t._args())).tolist()))
    """)
    env = {**os.environ, "HDID_CACHE_DIR": str(tmp_path), "HDID_PROGRAM_STORE": "1",
           "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    got = np.array(eval(r.stdout.strip().splitlines()[-1]))
    np.testing.assert_allclose(got, eqx.filter_jit(_solve)(*_args()), rtol=1e-14)


def test_a_program_that_fails_to_restore_is_compiled_and_never_loaded_again(store, monkeypatch):
    _programs.call("solve", _solve, *_args())
    monkeypatch.setattr(_programs, "_LOADED", {})

    def broken(*a):
        raise RuntimeError("NOT_FOUND: Function wrapped_iota not found")

    real_load = _programs._load
    monkeypatch.setattr(_programs, "_load", lambda key: broken if real_load(key) else None)
    args = _args()
    np.testing.assert_allclose(_programs.call("solve", _solve, *args),
                               eqx.filter_jit(_solve)(*args), rtol=1e-14)
    assert len(list(store.glob("*.bad"))) == 1
    monkeypatch.setattr(_programs, "_load", real_load)
    monkeypatch.setattr(_programs, "_LOADED", {})
    key = next(store.glob("*.bad")).stem
    assert _programs._load(key) is None


def test_no_store_when_caching_is_off(store, monkeypatch):
    monkeypatch.setenv("HDID_NO_CACHE", "1")
    _programs.call("solve", _solve, *_args())
    assert not store.exists() or not list(store.glob("*.bin"))
