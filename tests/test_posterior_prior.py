"""The user's Gaussian prior (``sample_posterior(prior=...)``), the chunked batch and the
SMC's independence moves: exact identities, no statistics beyond what is written beside."""

from __future__ import annotations

import math
from pathlib import Path
from typing import ClassVar

import jax.numpy as jnp
import numpy as np
import pytest

import hdid
from hdid._posterior import PRIOR_HALF_WIDTH, density
from hdid._posterior.density import posterior_density

EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"


@pytest.fixture(scope="module")
def fit():
    return hdid.fit(EXAMPLE)


def _x(fit, du=None):
    x = np.concatenate([np.asarray(fit.u, dtype=float), [np.log(0.3 * fit.resolution_rad)]])
    if du is not None:
        for i, d in du.items():
            x[i] += d
    return x


def test_gaussian_prior_replaces_the_default_and_orders_the_friction(fit):
    """With ``prior={"v_s": (c, s)}`` the log-density differs from the default one by
    exactly (normalised Gaussian in log v_s) − (the law's declared Gaussian of v_s), at two
    points; v_s may leave the ±7 box (both are proper; tau_s keeps the box); with or
    without priors on tau_c and tau_s, tau_s < tau_c has zero density (the Stribeck law's
    declared order)."""
    prob = fit.problem
    free = list(prob.free)
    i = free.index("v_s")
    c, s = 5.0, 0.3
    base = posterior_density(fit, sample_linear=()).lp
    user = posterior_density(fit, sample_linear=(), prior={"v_s": (c, s)}).lp
    G0, _ = density.gaussian_prior(prob, None)
    for d in (0.0, 0.4):
        x = _x(fit, {i: d})
        u = x[i]
        gauss = -0.5 * ((u - math.log(c)) / s) ** 2 - math.log(s) - 0.5 * math.log(2 * math.pi)
        # the default: the Stribeck law's declared posterior prior on v_s (log-normal,
        # normalised like the user's), not the least-squares weak row
        m0, s0 = float(G0[0, i]), float(G0[1, i])
        weak = -0.5 * ((u - m0) / s0) ** 2 - math.log(s0) - 0.5 * math.log(2 * math.pi)
        diff = float(user.log_prob(jnp.asarray(x)) - base.log_prob(jnp.asarray(x)))
        assert diff == pytest.approx(gauss - weak, abs=1e-9)
    far = _x(fit, {i: PRIOR_HALF_WIDTH + 1.0})
    # v_s's Gaussians (the declared one and the user's) are proper: no box for v_s
    assert np.isfinite(float(base.log_prob(jnp.asarray(far))))
    assert np.isfinite(float(user.log_prob(jnp.asarray(far))))
    # tau_s: its default log-normal (issue 34, decision (a)) is proper, no box; under the
    # flat option (default_prior="flat") it keeps the box (flat in its log, ±7)
    far = _x(fit, {free.index("tau_s"): PRIOR_HALF_WIDTH + 1.0})
    assert np.isfinite(float(base.log_prob(jnp.asarray(far))))
    flat = posterior_density(fit, sample_linear=(), default_prior="flat").lp
    assert float(flat.log_prob(jnp.asarray(far))) == -np.inf
    vals = fit.values
    ordered = posterior_density(fit, sample_linear=(), prior={
        "tau_c": (vals["tau_c"], 1.0), "tau_s": (vals["tau_s"], 1.0)}).lp
    jc, js = free.index("tau_c"), free.index("tau_s")
    x = _x(fit)
    assert np.isfinite(float(ordered.log_prob(jnp.asarray(x))))
    x[jc] = x[js] + 0.01  # tau_c just above tau_s
    assert float(ordered.log_prob(jnp.asarray(x))) == -np.inf
    assert float(base.log_prob(jnp.asarray(x))) == -np.inf
    x[jc] = x[js] - 0.01  # just below: allowed
    assert np.isfinite(float(base.log_prob(jnp.asarray(x))))
    with pytest.raises(ValueError, match="not free"):
        posterior_density(fit, prior={"inertia": (1e-6, 0.1)})


def test_width_ratio_uses_the_user_prior_sd(fit):
    from hdid._posterior.diagnostics import width_ratios

    prob = fit.problem
    dens = posterior_density(fit, prior={"v_s": (5.0, 0.3)})
    i = list(prob.free).index("v_s")
    rng = np.random.default_rng(0)
    u = np.asarray(fit.u, dtype=float)
    draws = np.tile(u, (4000, 1))
    draws[:, i] += 0.3 * rng.standard_normal(4000)
    w = width_ratios(prob, draws, u, PRIOR_HALF_WIDTH, dens.lin, dens.lp.gauss_prior)
    # sd of 4000 normal draws: relative se 1/√8000 ≈ 0.011; 0.05 is > 4 se
    assert w["v_s"]["posterior_over_prior_width"] == pytest.approx(1.0, abs=0.05)
    assert w["v_s"]["verdict"] == "set by the prior (assumed)" and w["v_s"]["set_by_prior"]


def test_chunked_batch_equals_one_loop(fit, monkeypatch):
    """Chunks of rows each end their own simulation loop: same densities to rounding, for a
    row count that is not a multiple of the chunk (padding)."""
    lp = posterior_density(fit).lp
    rng = np.random.default_rng(0)
    x0 = lp.to_sampled_np(_x(fit))
    X = x0 + 0.02 * np.abs(x0) * rng.standard_normal((37, x0.size))
    one = np.asarray(density._batch_rows(lp, jnp.asarray(X)))
    monkeypatch.setattr(density, "BATCH_CHUNK", 8)
    import jax

    chunked = np.asarray(jax.jit(density._batch)(lp, jnp.asarray(X)))
    assert np.isfinite(one).sum() >= 30
    np.testing.assert_allclose(chunked, one, rtol=1e-11)


def test_mode_search_under_a_user_prior_minimises_the_posterior(fit):
    """With a user prior the optima are sought on the posterior's cost: the view's prior
    rows are the user's (its cost at the fit rises by exactly z² for v_s put 3 sd off),
    its starts are the prior's centre and draws from it, and the fit is not changed."""
    from hdid._posterior.density import gaussian_prior
    from hdid._posterior.modes import N_PRIOR_STARTS, with_user_prior

    prob = fit.problem
    i = list(prob.free).index("v_s")
    v = fit.values["v_s"]
    G, _ = gaussian_prior(prob, {"v_s": (v * math.exp(0.9), 0.3)})
    view, starts = with_user_prior(fit, G, seed=1)
    u = np.asarray(fit.u, dtype=float)
    base_rows = float(np.sum(np.asarray(prob.prior_residuals(u)) ** 2))
    own_vs = float(((u[i] - prob.prior_mean[i]) / prob.prior_sd[i]) ** 2)
    # the other rows G replaces: the default posterior priors (issue 34: every free
    # parameter's), each in place of its least-squares weak row where it has one
    on = [k for k in np.flatnonzero(G[2] > 0) if k != i]
    lsq = np.asarray(prob.prior_on, dtype=bool)
    others = sum(float(((u[k] - G[0, k]) / G[1, k]) ** 2
                       - (((u[k] - prob.prior_mean[k]) / prob.prior_sd[k]) ** 2 if lsq[k] else 0.0))
                 for k in on)
    got = float(view.problem.cost(jnp.asarray(u)) - prob.cost(jnp.asarray(u)))
    assert got == pytest.approx(9.0 - own_vs + others, abs=1e-9)
    assert base_rows >= own_vs
    assert starts.shape == (1 + N_PRIOR_STARTS, u.size)
    assert starts[0, i] == pytest.approx(u[i] + 0.9)
    kept = [k for k in range(u.size) if k >= G.shape[1] or G[2, k] < 2]
    assert np.all(starts[:, kept] == u[kept])  # only the user's priors' parameters are drawn
    assert np.array_equal(np.asarray(view.u), u) and fit.problem is prob
    assert with_user_prior(fit, None) == (fit, None)


def test_stribeck_priors_are_relative_to_the_log_and_physical(fit):
    """The Stribeck law's priors (effects/stribeck.py). In the posterior (declared as
    ``posterior_prior``): v_s log-normal with median 5 % of the log's own peak speed and
    sd 1 in log; delta logit-normal with median 1 and 95 % within [0.47, 2.3]; the order
    tau_c ≤ tau_s. In the least-squares fit: the weak rows, sd 2, centred on the same v_s
    start and on delta's interval middle."""
    from hdid._posterior.density import gaussian_prior, ordered_pairs
    from hdid._models._transforms import from_unconstrained

    prob = fit.problem
    free = list(prob.free)
    specs = prob.base.parameter_specs()
    i, j = free.index("v_s"), free.index("delta")
    from hdid._fitting._fit import _setup
    from hdid._simulation._prepare import offset_guess
    from hdid._fitting._starts import log_scales

    s0 = _setup(EXAMPLE)
    scales = log_scales(s0.prep, hdid.Model.default(), offset_guess(s0.prep))
    assert float(prob.prior_mean[i]) == pytest.approx(math.log(0.05 * scales.speed), rel=1e-9)
    # the peak speed of the log (the swing's ω·amplitude), not its sampled chord speed
    assert scales.speed >= s0.prep.speed
    assert float(prob.prior_sd[i]) == 2.0 and float(prob.prior_sd[j]) == 2.0
    G, pairs = gaussian_prior(prob, None)
    assert G[2, i] == 1.0 and G[2, j] == 1.0
    # with the flat option v_s and delta are the only Gaussian priors (as before issue 34)
    assert gaussian_prior(prob, None, "flat")[0][2].sum() == 2.0
    assert G[0, i] == pytest.approx(float(prob.prior_mean[i]), rel=1e-12) and G[1, i] == 1.0
    m, s = G[0, j], G[1, j]
    lo, med, hi = (float(from_unconstrained(specs["delta"], m + z * s, np)) for z in (-1.96, 0, 1.96))
    assert med == pytest.approx(1.0, abs=1e-12)
    assert 0.45 < lo < 0.5 and 2.2 < hi < 2.3
    assert pairs.tolist() == [[free.index("tau_c"), free.index("tau_s")]]
    assert ordered_pairs(prob).tolist() == pairs.tolist()


def test_sampling_coordinates_and_orders_are_declared_by_the_effects(fit):
    """The posterior reads its coordinates from the parameters' declarations (issue 20:
    no list of names in the posterior): the library's ``k1, k2, tau_c, c_v`` are sampled
    in value and ``k2, tau_c, c_v`` get a value-flat prior (coefficients of terms that may
    vanish; tau_c since it became flat in value, issue 17), and a user's effect that declares
    ``sample_in_value`` / ``flat_in_value`` and an order is treated the same way."""
    from hdid._posterior.density import declared, ordered_pairs
    from hdid.effects import parameter

    specs = hdid.Model.default().parameter_specs()
    assert declared(specs, "sample_in_value") == ("k1", "k2", "tau_c", "c_v")
    assert declared(specs, "flat_in_value") == ("k2", "tau_c", "c_v")

    class Drag(hdid.AbstractEffect):
        c_d: float = parameter("N m s^2/rad^2", "quadratic drag", start=lambda s: 1e-9,
                               flat_in_value=True, sample_in_value=True)
        c_e: float = parameter("N m s^2/rad^2", "a second drag", start=lambda s: 2e-9)
        name: ClassVar[str] = "drag"
        ordered: ClassVar = (("c_d", "c_e"),)

        def torque(self, motion, state):
            return -(self.c_d + self.c_e) * motion.omega * jnp.abs(motion.omega)

    model = hdid.Model.default().with_effect(Drag(c_d=1e-9, c_e=2e-9))
    specs = model.parameter_specs()
    assert declared(specs, "sample_in_value")[-1] == "c_d"
    assert declared(specs, "flat_in_value")[-1] == "c_d"
    problem = fit.problem
    problem = type(problem)(**{**{f: getattr(problem, f) for f in problem.__dataclass_fields__},
                               "base": model, "free": problem.free + ("c_d", "c_e")})
    pairs = ordered_pairs(problem)
    free = list(problem.free)
    assert [free.index("c_d"), free.index("c_e")] in pairs.tolist()
    assert [free.index("tau_c"), free.index("tau_s")] in pairs.tolist()


def test_tau_c_flat_option_is_flat_in_value_and_a_user_prior_replaces_it(fit):
    """Under the flat option (``default_prior="flat"``; the default before issue 34's
    decision (a)) the prior of tau_c is flat in its value (the Coulomb limit is a law of
    its own, effects/stribeck.py): moving tau_c by Δ in log changes the log-density by
    exactly Δ more than a log-flat prior does (density ∝ e^u in u), at two points; the box
    stays (±7 in log). A Gaussian of the user's on tau_c (and the calibration's ``--prior
    physical``, which gives one) replaces it: no value-flat term."""
    prob = fit.problem
    free = list(prob.free)
    j = free.index("tau_c")
    dflt = posterior_density(fit, sample_linear=(), default_prior="flat")
    logflat = posterior_density(fit, sample_linear=(), linear_prior=("k2", "c_v"),
                                default_prior="flat")
    assert dflt.lin[j] == 1.0 and logflat.lin[j] == 0.0
    assert [free[i] for i in np.flatnonzero(dflt.lin)] == ["k2", "tau_c", "c_v"]
    x0 = _x(fit)
    for d in (-0.7, -2.5):  # tau_c lowered (stays below tau_s: the order holds)
        x = _x(fit, {j: d})
        a = float(dflt.lp.log_prob(jnp.asarray(x)) - dflt.lp.log_prob(jnp.asarray(x0)))
        b = float(logflat.lp.log_prob(jnp.asarray(x)) - logflat.lp.log_prob(jnp.asarray(x0)))
        assert a - b == pytest.approx(d, abs=1e-9)
    assert float(dflt.lp.log_prob(jnp.asarray(_x(fit, {j: -PRIOR_HALF_WIDTH - 0.1})))) == -np.inf
    vals = fit.values
    user = posterior_density(fit, sample_linear=(), prior={"tau_c": (vals["tau_c"], 0.3)},
                             default_prior="flat")
    assert user.lin[j] == 0.0 and user.lin[free.index("c_v")] == 1.0
    x = _x(fit, {j: -0.7})
    a = float(user.lp.log_prob(jnp.asarray(x)) - user.lp.log_prob(jnp.asarray(x0)))
    b = float(logflat.lp.log_prob(jnp.asarray(x)) - logflat.lp.log_prob(jnp.asarray(x0)))
    assert a - b == pytest.approx(-0.5 * (0.7 / 0.3) ** 2, abs=1e-9)


def test_every_optimum_out_of_order_falls_back_to_the_fits_own_inside_the_order(fit):
    """When every optimum given (or found) breaks tau_s >= tau_c, the walkers start from the
    fit's own optimum with each such pair put just inside the allowed side. Paper log 9506
    of the calibration (benchmarks/posterior_sbc.py --seed0 9500) reached this path and
    failed writing into the fit's read-only unknowns; the start must now be in order and
    the fit untouched."""
    from dataclasses import replace

    from hdid._posterior.density import ordered_pairs
    from hdid._posterior.modes import _fit_mode, sampled_modes

    prob = fit.problem
    free = list(prob.free)
    jc, js = free.index("tau_c"), free.index("tau_s")
    before = np.array(fit.u, dtype=float)
    bad = _fit_mode(fit)
    bad = replace(bad, u=bad.u.copy())
    bad.u[jc] = bad.u[js] + 0.5  # tau_c above tau_s: outside the order
    dens = posterior_density(fit)
    found = sampled_modes(fit, [bad], 0, dens.u_fit, dens.lin, dens.lp.gauss_prior)
    assert len(found) == 1 and found[0].weight == pytest.approx(1.0)
    for i, j in ordered_pairs(prob):
        assert found[0].u[j] >= found[0].u[i]
    np.testing.assert_array_equal(np.asarray(fit.u, dtype=float), before)


def test_the_box_filters_only_optima_beyond_a_flat_prior(fit):
    """An optimum far from the fit (k2 at e⁸ × the fit's: a better basin, as on SBC log
    36001 where k2 was 10⁶ × the fit's) is sampled under the default log-normal prior of k2,
    which has no box; under the flat option (a box of ±PRIOR_HALF_WIDTH in log around the
    fit) it is outside the prior and dropped."""
    from dataclasses import replace

    from hdid._posterior.density import PRIOR_HALF_WIDTH
    from hdid._posterior.modes import _fit_mode, sampled_modes

    j = list(fit.problem.free).index("k2")
    far = _fit_mode(fit)
    far = replace(far, u=far.u.copy())
    far.u[j] += PRIOR_HALF_WIDTH + 1.0
    near = _fit_mode(fit)
    for default, kept in (("weak", 2), ("flat", 1)):
        dens = posterior_density(fit, default_prior=default)
        found = sampled_modes(fit, [near, far], 0, dens.u_fit, dens.lin, dens.lp.gauss_prior)
        assert len(found) == kept, default


class _Inverted:
    """``fit`` with its unknowns ``u`` replaced (a fit that ended outside the prior's order)."""

    def __init__(self, fit, u):
        self._fit, self.u = fit, u

    def __getattr__(self, name):
        return getattr(self._fit, name)


def test_an_optimum_outside_the_order_is_refitted_inside_and_said(fit):
    """A fit that ends on an inverted Stribeck law (tau_s < tau_c: zero posterior density;
    SBC paper log 36009 did, tau_s 1.11 < tau_c 3.67 mN m) — here the shipped paper fit with
    its two friction levels swapped. The walkers must start from an optimum inside the order,
    not from that point merely moved inside (which stranded every walker 8770 in log p
    away), and the result must say so in one line. The shipped fit itself is an optimum
    inside the order on this very log, so the refit must reach its cost within 9.21 (the 99 %
    point of χ²₂: the tolerance the mode search keeps its ridge starts by), and the start's
    log density must be finite."""
    from hdid._posterior.density import ordered_pairs
    from hdid._posterior.ensemble import _Ensemble
    from hdid._posterior.modes import _laplace, sampled_modes

    prob = fit.problem
    free = list(prob.free)
    jc, js = free.index("tau_c"), free.index("tau_s")
    u = np.array(fit.u, dtype=float)
    assert u[js] > u[jc]  # the shipped fit keeps the order
    u[jc], u[js] = u[js], u[jc]
    bad = _Inverted(fit, u)
    dens = posterior_density(bad)
    found = sampled_modes(bad, "fit", 0, dens.u_fit, dens.lin, dens.lp.gauss_prior)
    pairs = ordered_pairs(prob)
    best = min(found, key=lambda m: m.cost)
    assert np.all(best.u[pairs[:, 1]] >= best.u[pairs[:, 0]])
    from hdid._posterior.modes import with_user_prior

    view = with_user_prior(fit, dens.lp.gauss_prior)[0]
    ref = _laplace(view.problem, np.asarray(fit.u, dtype=float))[0]
    assert best.cost <= ref + 9.21  # 99 % point of χ²₂
    x = np.concatenate([best.u, [np.log(0.3 * fit.resolution_rad)]])
    assert np.isfinite(float(dens.lp.log_prob(jnp.asarray(dens.lp.to_sampled_np(x)))))
    notes = [m.note for m in found if m.note]
    assert len(notes) == 1 and "\n" not in notes[0]
    assert notes[0].startswith("CONSTRAINED OPTIMUM") and "tau_s ≥ tau_c" in notes[0]
    run = _Ensemble.start(bad, None, 0, None, None, None, None, "weak", "fit", None)
    assert notes[0] in run.warnings
    assert np.all(np.isfinite(run.state.log_prob))


def test_no_optimum_inside_the_order_is_said_before_sampling(fit, monkeypatch, capsys):
    """When no refit inside the order reaches a finite density (forced here: every cost
    infinite), one line says so on standard error at once — before any sampling — and the
    sampled start carries it for the result's warnings."""
    from hdid._posterior import inside
    from hdid._posterior.modes import sampled_modes

    free = list(fit.problem.free)
    jc, js = free.index("tau_c"), free.index("tau_s")
    u = np.array(fit.u, dtype=float)
    u[jc], u[js] = u[js], u[jc]
    bad = _Inverted(fit, u)
    dens = posterior_density(bad)
    monkeypatch.setattr(inside, "_costs", lambda problem, U: np.full(len(np.atleast_2d(U)), np.inf))
    found = sampled_modes(bad, "fit", 0, dens.u_fit, dens.lin, dens.lp.gauss_prior)
    err = capsys.readouterr().err
    assert err.count("NO OPTIMUM INSIDE THE PRIOR") == 1 and "tau_s ≥ tau_c" in err
    assert found[0].note is not None and found[0].note.startswith("NO OPTIMUM INSIDE")
