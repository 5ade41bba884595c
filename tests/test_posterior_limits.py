"""The vanishing ends of value-flat parameters (``_posterior/limits.py``): the limit fits,
their place among the optima, and the warning when a chain stops short of an end the
data allow (docs/decisions/tau-c-flat-in-value.md)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

import hdid
from hdid._posterior.limits import LIMIT_DCHI2, LIMIT_FRACTION, LimitFit, limit_fits, limit_warnings

EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"


@pytest.fixture(scope="module")
def fit():
    return hdid.fit(EXAMPLE)


def _limit(name, dchi2, lsq=2.5e-3, mid=None):
    """A limit fit of ``name`` at e⁻⁶ of ``lsq`` with Δ ``dchi2``, and a path point at
    0.4 × ``lsq`` with Δ ``mid`` (default: the same)."""
    end = LIMIT_FRACTION * lsq
    mid = dchi2 if mid is None else mid
    return LimitFit(name=name, u=np.zeros(3), value=end, lsq_value=lsq, dchi2_lsq=dchi2,
                    dchi2=dchi2, profile=[(0.4 * lsq, mid), (end, dchi2)])


def test_warning_fires_where_the_data_allow_values_the_chain_never_reached():
    """Synthetic draws, no sampling. tau_c's limit path within reach (Δ 0.4) and draws in
    [2.3, 2.8] mN m (the plain chain on the shipped log) → "LOWER END NOT MEASURED" naming
    tau_c, the lowest allowed value, its Δ and what to do — also when only the path's
    point is allowed (Δ 2 at 1 mN m, 9 at the end). Draws spread down to zero → "BOUNDED
    ABOVE ONLY" instead. Limits the data exclude (Δ above 3.84 all along) → nothing,
    whatever the draws."""
    rng = np.random.default_rng(0)
    narrow = {"tau_c": rng.uniform(2.3e-3, 2.8e-3, 4000)}
    spread = {"tau_c": rng.uniform(0.0, 2.8e-3, 4000)}
    lsq = {"tau_c": 2.5e-3}
    w = limit_warnings([_limit("tau_c", 0.4)], narrow, lsq)
    assert len(w) == 1 and w[0].startswith("LOWER END NOT MEASURED: tau_c")
    assert "0.40" in w[0] and "prior={'tau_c'" in w[0] and "run longer" in w[0]
    assert f"{LIMIT_FRACTION * 2.5e-3:.3g}" in w[0]
    w = limit_warnings([_limit("tau_c", 9.0, mid=2.0)], narrow, lsq)
    assert len(w) == 1 and w[0].startswith("LOWER END NOT MEASURED: tau_c") and "0.001 " in w[0]
    assert "Δ = 9.00" in w[0]
    w = limit_warnings([_limit("tau_c", 0.4)], spread, lsq)
    assert len(w) == 1 and w[0].startswith("BOUNDED ABOVE ONLY") and "NOT MEASURED" not in w[0]
    assert limit_warnings([_limit("tau_c", 25.0)], narrow, lsq) == []
    assert limit_warnings([_limit("tau_c", LIMIT_DCHI2 + 0.01)], narrow, lsq) == []
    w = limit_warnings([_limit("tau_c", 0.4)], narrow, lsq, {"tau_c": (0.2, 0.0)})
    assert len(w) == 1 and "20.0% of the Laplace mass and 0.0% of the draws" in w[0]
    # a limit fit whose Δ is unknown, or of a parameter not sampled: nothing
    assert limit_warnings([_limit("tau_c", math.nan)], narrow, lsq) == []
    assert limit_warnings([_limit("k2", 0.1)], narrow, lsq) == []


def test_limit_fits_on_the_shipped_log(fit):
    """tau_c held at e⁻⁶ of its least-squares value, the rest refitted: the shipped log's
    Coulomb limit is within the data's reach (least-squares Δχ² below 3.84; the profile of docs/decisions/friction-coordinates.md:
    0.32 at 1 mN m); the viscous term's vanishing end is not (c_v → 0)."""
    import jax.numpy as jnp

    from hdid._posterior.modes import MODE_LANES

    best = float(fit.problem.cost(jnp.asarray(fit.u)))
    lims = {lim.name: lim for lim in limit_fits(fit, ["tau_c", "c_v"], best, MODE_LANES)}
    tc = lims["tau_c"]
    assert tc.value == pytest.approx(LIMIT_FRACTION * fit.values["tau_c"], rel=0.01)
    assert tc.lsq_value == pytest.approx(fit.values["tau_c"], rel=1e-12)
    assert tc.dchi2_lsq < LIMIT_DCHI2
    assert lims["c_v"].dchi2_lsq > 2 * LIMIT_DCHI2


def test_short_chain_from_the_fit_warns_that_the_coulomb_limit_was_not_sampled(fit):
    """End to end on the shipped log, under the flat option (``default_prior="flat"``: the
    default before issue 34's decision (a), whose value-flat priors have vanishing ends):
    100 steps from the fit's optimum alone cannot go down
    the Coulomb-limit ridge the data allow, so the result says so for tau_c; the viscous
    term's vanishing end is excluded by the data (not within reach); the limit fits are in
    the JSON with their profiles."""
    post = hdid.sample_posterior(fit, n_steps=100, burn_in=40, seed=3, modes="fit",
                                 progress=False, default_prior="flat")
    w = [x for x in post.warnings if x.startswith("LOWER END NOT MEASURED")]
    assert any(x.startswith("LOWER END NOT MEASURED: tau_c") for x in w)
    d = post.to_dict()["posterior_diagnostics"]["limits"]
    by = {x["name"]: x for x in d}
    assert set(by) == {"k2", "tau_c", "c_v"}
    assert min(p["dchi2"] for p in by["tau_c"]["profile"]) <= LIMIT_DCHI2
    assert not by["c_v"]["within_reach"]
    assert len(by["tau_c"]["profile"]) == 5


def test_limit_fits_skip_parameters_the_fit_measures_well(fit):
    """No limit fit for a value-flat parameter measured to better than 20 % (its end ≥ 5
    linearised sd away); an unknown (NaN) standard error does not skip it."""
    from hdid._posterior.density import posterior_density
    from hdid._posterior.limits import LIMIT_SCREEN_REL_SD, limit_names

    prob = fit.problem
    free = list(prob.free)
    lin = posterior_density(fit, default_prior="flat").lin  # value-flat: the flat option
    assert limit_names(prob, lin) == ["k2", "tau_c", "c_v"]
    assert limit_names(prob, posterior_density(fit).lin) == []  # weak default: no flat end
    assert limit_names(prob, lin, fit.covariance) == ["k2", "tau_c", "c_v"]  # 34, 106, 236 %
    C = np.array(fit.covariance, dtype=float)
    C[free.index("tau_c"), free.index("tau_c")] = (0.9 * LIMIT_SCREEN_REL_SD) ** 2
    C[free.index("k2"), free.index("k2")] = np.nan
    assert limit_names(prob, lin, C) == ["k2", "c_v"]


def test_mode_search_solver_is_the_fits_program_without_its_trace(fit, monkeypatch):
    """The mode search's and limit fits' ``solve_fresh`` runs its rows through the fit's
    stored one-lane program (:mod:`hdid._fitting._one_lane`), so a ``--posterior``
    process traces no vmapped program of its own (27–32 s per lane count in a fresh
    process; docs/decisions/mode-search-programs.md): the vmapped program is never
    called, and each active row ends where the vmapped program takes it — also for the
    limit fits' problems, whose prior rows differ. Tolerance: one lane against a vmapped
    lane differ only by the order of floating-point operations (~1e-13 relative per
    step); 1e-9 relative on the cost leaves that room over 12 steps and fails on any
    different accept/reject path or a wrong row."""
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    from hdid._fitting import _lm
    from hdid._fitting._lm import LMState, _solve_lanes
    from hdid._posterior.lanes import MODE_LANES, solve_fresh

    rng = np.random.default_rng(0)
    U = jnp.asarray(np.asarray(fit.u) + 0.05 * rng.standard_normal((MODE_LANES, len(fit.u))))
    active = jnp.asarray(np.arange(MODE_LANES) < 4)
    prob = fit.problem
    pinned = eqx.tree_at(lambda p: p.prior_on, prob, jnp.ones_like(prob.prior_on))
    for p in (prob, pinned):
        m = jax.eval_shape(p.residuals, U[0]).shape[0]
        ref = _solve_lanes(p, U, active, jnp.asarray(12), LMState.empty(MODE_LANES, m, len(fit.u)))
        with monkeypatch.context() as mp:
            mp.setattr(_lm, "_solve_lanes", lambda *a, **k: pytest.fail("vmapped program called"))
            U2, cost, done, _ = solve_fresh(p, U, active, 12)
        on = np.asarray(active)
        np.testing.assert_allclose(cost[on], np.asarray(ref[1])[on], rtol=1e-9)
        np.testing.assert_allclose(U2[on], np.asarray(ref[0])[on], rtol=1e-6, atol=1e-9)
        assert np.array_equal(done[on], np.asarray(ref[2])[on])
        assert np.all(np.isinf(cost[~on])) and np.array_equal(U2[~on], np.asarray(U)[~on])


def test_limit_fits_are_made_once_per_fit(fit, monkeypatch):
    """A second call on the same fit and names (the SMC after the emcee call, ``modes="fit"``)
    reuses the continuation — whatever its best cost or stop — and hands out copies (the
    caller sets their profile)."""
    import jax.numpy as jnp

    from hdid._posterior import limits
    from hdid._posterior.modes import MODE_LANES

    best = float(fit.problem.cost(jnp.asarray(fit.u)))
    first = limit_fits(fit, ["tau_c"], best, MODE_LANES)
    monkeypatch.setattr(limits, "_limit_paths", lambda *a: pytest.fail("limit fits redone"))
    again = limit_fits(fit, ["tau_c"], best, MODE_LANES)
    assert np.array_equal(first[0].u, again[0].u) and first[0].u is not again[0].u
    assert first[0].dchi2_lsq == again[0].dchi2_lsq
    # a stop below the path's first point's cost ends the path there, as before the cache
    short = limit_fits(fit, ["tau_c"], best, MODE_LANES, stop=-1.0)
    assert short[0].path == [] and np.array_equal(short[0].u, first[0].path[0][0])



def test_ridge_starts_under_the_default_prior(fit):
    """Under the weak default priors (nothing flat in value: no limit fits, no limit
    warning) the optima the samplers start from still include points down the ridges of
    the vanishing terms (``ridge:NAME``, the limit continuation under the sampled priors):
    on the shipped log the Coulomb ridge — tau_c below the fit's, c_v above it — within
    ``RIDGE_DCHI2`` (the default prior's cost of going down it is (s/1.2)² at exp(−s)).
    Before them, every start sat on the fit's side of that ridge and the calibration's
    tau_c ranks piled low (benchmarks/results/posterior_sbc.md)."""
    from hdid._posterior.density import posterior_density
    from hdid._posterior.modes import (RIDGE_DCHI2, RIDGE_SHARE, found_limits, ridge_names,
                                       sampled_modes)

    dens = posterior_density(fit)
    assert not np.any(dens.lin)
    assert ridge_names(fit.problem, dens.lin, fit.covariance) == ["k2", "tau_c", "c_v"]
    assert ridge_names(fit.problem, posterior_density(fit, default_prior="flat").lin) == []
    found = sampled_modes(fit, "auto", 0, dens.u_fit, dens.lin, dens.lp.gauss_prior)
    ridge = [m for m in found if m.kind == "ridge:tau_c"]
    assert len(ridge) >= 2
    assert all(m.values["tau_c"] < fit.values["tau_c"] for m in ridge)
    assert max(m.values["c_v"] for m in ridge) > fit.values["c_v"]
    assert all(m.limit is None for m in found if m.kind.startswith("ridge:"))
    assert all(m.cost - found[0].cost < RIDGE_DCHI2 for m in ridge)
    # starts, not masses: together at most RIDGE_SHARE of the walkers and the proposals
    assert sum(m.weight for m in found if m.kind.startswith("ridge:")) <= RIDGE_SHARE + 1e-12
    assert found_limits(fit, found, "auto", dens.lin, dens.lp.gauss_prior) == []
