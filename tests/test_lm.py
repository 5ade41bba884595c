"""The one Levenberg–Marquardt engine (``hdid._fitting._lm``) against an independent oracle:
optimistix's ``LevenbergMarquardt`` (normal-equations Cholesky), which ``_lm_lanes``
reproduces step for step, on a small nonlinear least-squares problem with a known answer."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from hdid._fitting._lm import LMState, _lm_lanes

T = np.linspace(0.0, 3.0, 40)
TRUE = np.array([2.0, 1.3, 0.4])
Y = TRUE[0] * np.exp(-TRUE[1] * T) + TRUE[2] + 0.01 * np.random.default_rng(0).standard_normal(40)


def residual(u):
    return (u[0] * jnp.exp(-u[1] * T) + u[2] - Y) / 0.01  # in units of the noise σ


def test_lanes_lm_reaches_optimistix_optimum_from_every_start():
    import lineax as lx
    import optimistix as optx

    starts = np.array([[1.0, 0.5, 0.0], [3.0, 3.0, 1.0], [0.5, 0.2, -1.0]])
    batched = jax.vmap(residual)

    def with_jac(U):
        return batched(U), jax.vmap(jax.jacfwd(residual))(U)

    U, cost, done, k, _ = _lm_lanes(batched, with_jac, jnp.asarray(starts),
                                    jnp.ones(3, dtype=bool), 200, LMState.empty(3, 40, 3))
    solver = optx.LevenbergMarquardt(rtol=1e-8, atol=1e-8,
                                     linear_solver=lx.Normal(lx.Cholesky()))
    for i, u0 in enumerate(starts):
        ref = optx.least_squares(lambda u, _: residual(u), solver, jnp.asarray(u0),
                                 max_steps=500).value
        # Tolerance: the lanes LM stops after two accepted steps that each lower χ² by
        # < 0.01 (CHI2_STALL), i.e. within ~0.1 σ of the optimum along any direction; the
        # parameters' σ here are ~1e-2 (a, c) and ~1e-2 (b) relative, so 5e-3 relative.
        np.testing.assert_allclose(np.asarray(U[i]), np.asarray(ref), rtol=5e-3)
        assert bool(done[i])
    # and the optimum is the data's: χ² ≈ dof within 5 σ of its χ²₃₇ spread (√(2·37) ≈ 8.6)
    assert abs(float(cost.min()) - 37) < 5 * 8.6


def test_solve_fresh_runs_on_any_problem_of_the_abstraction():
    """Free, driven and joint problems are instances of one abstraction
    (``hdid._problems._base.AbstractProblem``): the engine needs nothing else, so a problem
    written from scratch — the exponential above — is solved like the library's own,
    and ``cost`` is inherited (χ² = Σ r²)."""
    import equinox as eqx

    from hdid._problems._driven_problem import DrivenProblem, JointProblem
    from hdid._fitting._lm import solve_fresh
    from hdid._problems._problem import Problem
    from hdid._problems._base import AbstractProblem

    assert all(issubclass(c, AbstractProblem) for c in (Problem, DrivenProblem, JointProblem))

    class Decay(AbstractProblem):
        n_unknowns: int = eqx.field(static=True, default=3)

        def residuals(self, u):
            return residual(u)

        def residuals_and_jacobian(self, u):
            return residual(u), jax.jacfwd(residual)(u)

    starts = np.array([[1.0, 0.5, 0.0], [3.0, 3.0, 1.0]])
    U, cost, done, _ = solve_fresh(Decay(), jnp.asarray(starts), jnp.ones(2, dtype=bool), 200)
    best = np.asarray(U)[int(np.argmin(np.asarray(cost)))]
    # the optimum of the test above (same data), to the same statistical tolerance: the
    # optimum's own 0.1-σ stop, here ≪ 1e-3 relative on these well-determined unknowns
    np.testing.assert_allclose(best, TRUE, rtol=0.05)
    # the inherited cost is the engine's χ² (to summation order: 40 rows, rel 1e-12)
    assert float(Decay().cost(jnp.asarray(best))) == pytest.approx(float(np.min(np.asarray(cost))),
                                                                   rel=1e-12)


def test_residual_rows_are_evaluated_once_per_problem_structure(monkeypatch):
    """``solve_fresh`` sizes its state with ``residual_rows``: ``jax.eval_shape`` of the
    residuals (which traces a simulation: 0.24–0.30 s on the shipped paper log) once per
    structure. A problem with other data values or prior rows reuses the count; one with
    another data length or another static field (which may add rows) gets its own."""
    import equinox as eqx

    from hdid._fitting import _lm
    from hdid._problems._base import AbstractProblem

    class Decay(AbstractProblem):
        t: jax.Array
        y: jax.Array
        extra: int = eqx.field(static=True, default=0)  # prior-like rows: u[:extra]
        n_unknowns: int = eqx.field(static=True, default=3)

        def residuals(self, u):
            r = (u[0] * jnp.exp(-u[1] * self.t) + u[2] - self.y) / 0.01
            return jnp.concatenate([r, u[: self.extra]])

        def residuals_and_jacobian(self, u):
            return self.residuals(u), jax.jacfwd(self.residuals)(u)

    calls = []
    real = jax.eval_shape
    monkeypatch.setattr(_lm.jax, "eval_shape", lambda *a, **k: calls.append(1) or real(*a, **k))
    monkeypatch.setattr(_lm, "_ROWS", {})
    u = jnp.asarray(TRUE)
    a = Decay(jnp.asarray(T), jnp.asarray(Y))
    assert _lm.residual_rows(a, u) == 40 and len(calls) == 1
    assert _lm.residual_rows(Decay(jnp.asarray(T), jnp.asarray(Y) + 1.0), u) == 40
    assert len(calls) == 1  # other values, same structure: no new trace
    assert _lm.residual_rows(Decay(jnp.asarray(T[:30]), jnp.asarray(Y[:30])), u) == 30
    assert _lm.residual_rows(Decay(jnp.asarray(T), jnp.asarray(Y), extra=2), u) == 42
    assert len(calls) == 3
    # and the engine sized by it gives what a state sized by eval_shape gives, bit for bit
    starts = jnp.asarray(np.array([[1.0, 0.5, 0.0], [3.0, 3.0, 1.0]]))
    on = jnp.ones(2, dtype=bool)
    got = _lm.solve_fresh(a, starts, on, 50)
    ref = _lm._solve_lanes(a, starts, on, jnp.asarray(50),
                           LMState.empty(2, real(a.residuals, u).shape[0], 3))[:4]
    for x, y in zip(got, ref):
        assert np.array_equal(np.asarray(x), np.asarray(y))
