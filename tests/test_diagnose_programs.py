"""The program store (:mod:`hdid._problems._programs`) that lets ``hdid diagnose`` skip tracing in a
later process: same numbers as the jit path, keyed by everything that shapes the program,
a stored program that uses LAPACK runs in a fresh process without tracing, and the store
is on by default."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from collections import OrderedDict
from pathlib import Path

import equinox as eqx
import jax.numpy as jnp
import numpy as np
import pytest

from hdid._problems import _programs

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
    monkeypatch.delenv("HDID_PROGRAM_STORE", raising=False)  # on by default
    monkeypatch.delenv("HDID_NO_CACHE", raising=False)
    monkeypatch.setattr(_programs, "_LOADED", OrderedDict())
    return tmp_path / "programs" / _programs._salt()[:16]


def _args(power=2.0, n=3):
    a = np.eye(n) * 2.0 + 0.1
    return _Spring(jnp.asarray(1.5), power), a, np.arange(1.0, n + 1)


def test_same_numbers_as_jit_and_a_stored_program(store):
    args = _args()
    out = _programs.call("solve", _solve, *args)
    np.testing.assert_allclose(out, eqx.filter_jit(_solve)(*args), rtol=1e-14)
    assert len(list(store.glob("*.exp"))) == 1


def test_key_follows_static_fields_and_shapes(store, monkeypatch):
    _programs.call("wave", _wave, *_args())
    _programs.call("wave", _wave, *_args(power=3.0))  # static field: another program
    _programs.call("wave", _wave, *_args(n=4))  # another shape: another program
    _programs.call("wave", _wave, *_args())  # the first again: no new file
    assert len(list(store.glob("*.exp"))) == 3
    # a new process (nothing loaded) reads the file — same numbers
    monkeypatch.setattr(_programs, "_LOADED", OrderedDict())
    args = _args(power=3.0)
    np.testing.assert_allclose(_programs.call("wave", _wave, *args),
                               eqx.filter_jit(_wave)(*args), rtol=1e-14)


def test_stored_lapack_program_runs_in_a_fresh_process(store, tmp_path, monkeypatch):
    """A fresh process reads the program from the store (it does not trace ``_solve``)
    and gets the same numbers; the LAPACK kernels it calls are registered on load (a
    segfault when they were not). Whatever other tests ran in this process before: a
    process that had used ``hdid.Model`` (kept by ``hdid.__getattr__``) once recorded
    ``hdid``'s constants with it, and the fresh process missed."""
    from hdid._problems import _program_deps

    import hdid

    monkeypatch.setattr(_program_deps, "DEBUG", True)  # (a miss names the constants)
    monkeypatch.delitem(vars(hdid), "Model", raising=False)
    assert hdid.Model  # (kept in hdid's namespace, as after any test that used it)
    n_unstored = len(_programs.UNSTORED)
    _programs.call("solve", _solve, *_args())
    # the parent stored it (else the child's miss below is the parent's doubt, not a load)
    assert len(_programs.UNSTORED) == n_unstored and list(store.glob("*.exp")), \
        f"not stored: {_programs.UNSTORED[n_unstored:]}"
    code = textwrap.dedent(f"""
        import sys, numpy as np
        sys.path.insert(0, {str(Path(__file__).parent)!r})
        import hdid
        hdid.configure()  # as the CLI (and conftest.py) set a process up: float64
        from hdid._problems import _programs, _program_deps
        import test_diagnose_programs as t
        def untraceable(*a):
            raise AssertionError(f"traced although stored: {{list(_program_deps.MISSES)}}")
        print([s["how"] for s in _programs.STATS])
        print(repr(np.asarray(_programs.call("solve", untraceable, *t._args())).tolist()))
        print([s["how"] for s in _programs.STATS])
    """)
    env = {**os.environ, "HDID_CACHE_DIR": str(tmp_path),
           "PYTHONPATH": os.pathsep.join([str(SRC), os.environ.get("PYTHONPATH", "")])}
    r = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env,
                       timeout=120)
    assert r.returncode == 0, r.stderr[-2000:]
    lines = r.stdout.strip().splitlines()
    assert lines[-1] == "['stored']", r.stdout
    got = np.array(eval(lines[-2]))
    np.testing.assert_allclose(got, eqx.filter_jit(_solve)(*_args()), rtol=1e-14)


def test_a_program_that_fails_to_restore_is_compiled_and_never_loaded_again(store, monkeypatch):
    _programs.call("solve", _solve, *_args())
    monkeypatch.setattr(_programs, "_LOADED", OrderedDict())

    class Broken:  # a stored program whose call fails (a stale file, say)
        def call(self, *a):
            raise RuntimeError("NOT_FOUND: Function wrapped_iota not found")

    real_load = _programs._load
    monkeypatch.setattr(_programs, "_load", lambda key: Broken() if real_load(key) else None)
    args = _args()
    np.testing.assert_allclose(_programs.call("solve", _solve, *args),
                               eqx.filter_jit(_solve)(*args), rtol=1e-14)
    assert len(list(store.glob("*.bad"))) == 1
    monkeypatch.setattr(_programs, "_load", real_load)
    monkeypatch.setattr(_programs, "_LOADED", OrderedDict())
    key = next(store.glob("*.bad")).stem
    assert _programs._load(key) is None


@pytest.mark.parametrize("env", [("HDID_NO_CACHE", "1"), ("HDID_PROGRAM_STORE", "0")])
def test_no_store_when_caching_is_off(store, monkeypatch, env):
    monkeypatch.setenv(*env)
    args = _args()
    np.testing.assert_allclose(_programs.call("solve", _solve, *args),
                               eqx.filter_jit(_solve)(*args), rtol=1e-14)
    assert not store.exists() or not list(store.glob("*.exp"))


def test_starts_in_groups_of_one_program_give_fit_s_iterates():
    """:func:`hdid._fitting._refit._local_fits` runs the starts ``LANES`` at a time (one program
    per structure, any number of starts); lanes do not interact, so every start must end
    where :func:`hdid._fitting._lm._local_fits` (all starts in one call) leaves it: same point,
    cost, convergence flag and iteration count (Rosenbrock from 7 starts: 3 groups in
    phase 1, the 3 best in phase 2)."""
    import types

    import jax

    from hdid._fitting import _refit
    from hdid._fitting._lm import _lm_lanes, _local_fits

    def res(U):
        return jnp.stack([10.0 * (U[:, 1] - U[:, 0] ** 2), 1.0 - U[:, 0]], axis=1)

    def res_jac(U):
        J = jax.vmap(jax.jacfwd(lambda u: res(u[None])[0]))(U)
        return res(U), J

    program = jax.jit(lambda U, active, k, state: _lm_lanes(res, res_jac, U, active, k, state))

    def solve(problem, U, active, k, state):
        return program(U, active, k, state)

    problem = types.SimpleNamespace(times=np.zeros((1, 2)), n_physical=0)
    U0 = np.random.default_rng(3).normal(size=(7, 2)) * 1.5
    want = _local_fits(problem, U0, 60, solve=solve)
    got = _refit._local_fits(problem, U0, 60, lanes=3, solve=solve)
    for w, g in zip(want, got[:4]):
        np.testing.assert_array_equal(np.asarray(g), np.asarray(w))
    assert np.sum(np.asarray(want[2])) >= 1  # some start converged: the schedule ran


def test_trapped_runs_from_the_residuals_match_the_simulation():
    """:func:`hdid._fitting._refit.trapped_runs` reads the runs the model never releases off the
    residuals the LM already has (no simulation program per structure); it must name the
    runs :func:`hdid._fitting._fit.trapped_runs` finds by simulating: none at a fitted-like start,
    all of them where static friction exceeds every release's spring torque."""
    import hdid
    from hdid._fitting import _refit
    from hdid._fitting._fit import trapped_runs
    from hdid._log import read_log
    from hdid._models._transforms import to_unconstrained

    log = read_log(SRC.parent / "data" / "synthetic" / "hidden_hysteresis_1khz.csv")
    s = _refit.setup(log, hdid.Model.default(), {})
    p = s.problem
    u = _refit.grid(s, 1)[0]
    residuals = eqx.filter_jit(lambda p, u: p.residuals(u))
    specs = s.model.parameter_specs()
    stuck = np.array(u)
    for name, value in (("tau_c", 1.0), ("tau_s", 2.0)):  # N m: far above k·θ at release
        stuck[p.free.index(name)] = float(to_unconstrained(specs[name], value))
    for v in (u, stuck):
        want = trapped_runs(p, s.prep, jnp.asarray(v))
        got = _refit.trapped_runs(p, s.prep, np.asarray(residuals(p, jnp.asarray(v))))
        np.testing.assert_array_equal(got, want)
    assert len(want) == p.n_runs  # the second case holds every run


def test_residuals_and_jacobian_from_the_lm_program_are_the_problem_s():
    """The order scan's one-step screen takes ``r`` and ``J`` from the structure's LM
    program (a lane stopped at its start) instead of a program of its own: they must be
    the problem's own, to rounding (forward mode in both: 1e-9 relative)."""
    import hdid
    from hdid._fitting import _refit
    from hdid._log import read_log

    log = read_log(SRC.parent / "data" / "synthetic" / "hidden_hysteresis_1khz.csv")
    s = _refit.setup(log, hdid.Model.default(), {})
    u = _refit.grid(s, 1)[0]
    r, J = _refit.residuals_and_jacobian(s.problem, u)
    r0, J0 = map(np.asarray, eqx.filter_jit(lambda p, u: p.residuals_and_jacobian(u))(
        s.problem, jnp.asarray(u)))
    assert r.shape == r0.shape and J.shape == J0.shape
    np.testing.assert_allclose(r, r0, rtol=1e-9, atol=1e-9 * np.max(np.abs(r0)))
    np.testing.assert_allclose(J, J0, rtol=1e-9, atol=1e-9 * np.max(np.abs(J0)))


def test_residual_frame_and_whiteness_reuse_the_analysis_parts_unchanged():
    """A refit's analysed result carries the Jacobian and simulations its analysis
    program computed (``hdid._results._residuals.PARTS``); the residual frame and the whiteness
    test must give the same numbers from them as from their own programs."""
    import pandas as pd

    import hdid
    from hdid._fitting import _refit
    from hdid._results import _residuals
    from hdid._log import read_log

    log = read_log(SRC.parent / "data" / "synthetic" / "hidden_hysteresis_1khz.csv")
    s = _refit.setup(log, hdid.Model.default(), {})
    sf = _refit.run("base", s, [("grid", u) for u in _refit.grid(s, 2)])
    res = sf.result()
    assert _residuals._parts(res)  # computed at the result's u
    first = len(_programs.STATS)
    frame, white = _residuals.residual_frame(res), _residuals.whiteness(res)
    # no program of their own was needed (none prepared, none reused from before)
    assert len(_programs.STATS) == first
    delattr(res, _residuals.PARTS)
    frame0, white0 = _residuals.residual_frame(res), _residuals.whiteness(res)
    pd.testing.assert_frame_equal(frame, frame0, rtol=1e-9)
    assert white.p_value == pytest.approx(white0.p_value, rel=1e-6)
    assert white.rms_ratio == pytest.approx(white0.rms_ratio, rel=1e-9)


def test_a_prefetched_program_is_read_in_the_background_with_the_same_numbers(store, monkeypatch):
    """:func:`hdid._problems._programs.prefetch` reads a stored program in a background
    thread; the later call uses it (no tracing: the function given raises if traced) and
    gets the jit path's numbers. Nothing is started for a program not stored yet (tracing
    stays in the caller's thread) or already loaded."""
    args = _args()
    assert not _programs.prefetch("solve", _solve, *args)  # not stored yet
    _programs.call("solve", _solve, *args)
    assert not _programs.prefetch("solve", _solve, *args)  # loaded in this process
    monkeypatch.setattr(_programs, "_LOADED", OrderedDict())  # as a new process
    assert _programs.prefetch("solve", _solve, *args)
    assert not _programs.prefetch("solve", _solve, *args)  # already being read

    def untraceable(*a):
        raise AssertionError("traced although prefetched")

    n = len(_programs.STATS)
    out = _programs.call("solve", untraceable, *args)
    np.testing.assert_allclose(out, eqx.filter_jit(_solve)(*args), rtol=1e-14)
    rows = _programs.STATS[n:]
    assert [(r["how"], r.get("background")) for r in rows] == [("stored", True)]
    assert rows[0]["span"][1] - rows[0]["span"][0] == pytest.approx(
        rows[0]["wait_s"], abs=1e-6)  # (time.time() has ~0.2 µs resolution near 1.8e9 s)
    assert not _programs._PENDING


def test_a_background_read_that_fails_is_prepared_by_the_caller(store, monkeypatch):
    args = _args()
    _programs.call("solve", _solve, *args)
    monkeypatch.setattr(_programs, "_LOADED", OrderedDict())
    monkeypatch.setattr(_programs, "_load", lambda key: None)  # unreadable in the background
    assert _programs.prefetch("solve", _solve, *args)
    np.testing.assert_allclose(_programs.call("solve", _solve, *args),
                               eqx.filter_jit(_solve)(*args), rtol=1e-14)
    assert _programs.STATS[-1]["how"] == "traced"


def test_refit_prefetch_asks_for_the_program_run_calls(monkeypatch):
    """:func:`hdid._fitting._refit.prefetch` builds the arguments by shape; its key must be
    the one :func:`hdid._fitting._refit.run`'s first call computes (same tree, static
    fields, shapes, dtypes and weak types), or the background read is wasted."""
    import jax

    import hdid
    from hdid._fitting import _refit
    from hdid._log import read_log

    keys = []

    class Stop(Exception):
        pass

    def key_of(name, fn, *args):
        dyn, static = eqx.partition(args, eqx.is_array)
        leaves, treedef = jax.tree_util.tree_flatten(dyn)
        keys.append(_programs._key(name, treedef, static, leaves))

    def call(name, fn, *args):
        key_of(name, fn, *args)
        raise Stop

    monkeypatch.setattr(_programs, "prefetch", lambda *a: key_of(*a) or True)
    monkeypatch.setattr(_programs, "call", call)
    log = read_log(SRC.parent / "data" / "synthetic" / "hidden_hysteresis_1khz.csv")
    s = _refit.setup(log, hdid.Model.default(), {})
    assert _refit.prefetch(s)
    with pytest.raises(Stop):
        _refit.run("base", s, [("zero", np.zeros(s.problem.n_unknowns))])
    assert len(keys) == 2 and keys[0] == keys[1]
