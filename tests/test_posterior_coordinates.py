"""Friction in data coordinates (``_posterior/coordinates.py``): the walkers' coordinates
change, the posterior does not.

The map replaces ``(tau_c, c_v)`` by the friction torque at two of the log's sliding
speeds. Its correctness is three identities, each checked to rounding at points spread
over the posterior's width (not only at the fit): the conversions are inverse, the
log-Jacobian the density adds equals ``log|det|`` of ``jax.jacfwd`` of the map, and so the
density of ``u`` is unchanged; and a point whose inversion gives ``tau_c ≤ 0`` has zero
density.
"""

from __future__ import annotations

from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

import hdid
from hdid._posterior.coordinates import friction_coordinates, sliding_speeds
from hdid._posterior.density import posterior_density

EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"


@pytest.fixture(scope="module")
def fit():
    return hdid.fit(EXAMPLE)


@pytest.fixture(scope="module")
def dens(fit):
    plain = posterior_density(fit).lp
    fric = posterior_density(fit, coordinates="friction").lp
    return plain, fric


def _points(fit, n=6, seed=3):
    """Unknowns (+ log σ_n) drawn from the fit's covariance in ``u`` (its standard
    errors, so the points span the posterior's width where the map has to hold)."""
    rng = np.random.default_rng(seed)
    u = np.asarray(fit.u, dtype=float)
    cov = np.asarray(fit.covariance, dtype=float)
    assert cov.shape == (u.size, u.size) and np.all(np.isfinite(cov))
    L = np.linalg.cholesky(0.5 * (cov + cov.T) + 1e-12 * np.eye(u.size))
    U = u + rng.standard_normal((n, u.size)) @ L.T
    return np.column_stack([U, np.full(n, np.log(0.3 * fit.resolution_rad))])


def test_speeds_come_from_the_log(fit, dens):
    """The two speeds are the fit's own sliding-speed quartiles (nothing fixed), and the
    scale makes the fit's point 1 in both data coordinates."""
    _, fric = dens
    fc = fric.friction
    assert fc is not None
    sp = sliding_speeds(fit)
    np.testing.assert_allclose(np.asarray(fc.speeds), np.quantile(sp, (0.25, 0.75)), rtol=1e-12)
    x = fric.to_sampled_np(np.concatenate([fit.u, [0.0]]))
    np.testing.assert_allclose(x[list(fc.idx[:2])], 1.0, rtol=1e-12)


def test_round_trip_and_jacobian_against_autodiff(fit, dens):
    """``from_sampled(to_sampled(U)) = U``; ``to_u`` returns ``log|det ∂u/∂s|`` equal to
    jax.jacfwd's of the same map (an independent computation: autodiff of the
    placeholder-and-solve code against the closed-form Cramer determinant)."""
    _, fric = dens
    U = _points(fit)
    S = fric.to_sampled_np(U)
    np.testing.assert_allclose(fric.from_sampled_np(S), U, rtol=0, atol=1e-10)
    for s in S:
        u, log_jac, inside = fric.to_u(jnp.asarray(s))
        assert bool(inside)
        np.testing.assert_allclose(np.asarray(u), fric.from_sampled_np(s[None])[0, :-1],
                                   rtol=0, atol=1e-10)
        J = jax.jacfwd(lambda x: fric.to_u(x)[0])(jnp.asarray(s))[:, :-1]
        sign, logdet = np.linalg.slogdet(np.asarray(J))
        assert sign != 0
        # float64 determinant of a ~20 × 20 matrix with entries of order 1e-2–1e3
        np.testing.assert_allclose(float(log_jac), logdet, rtol=0, atol=1e-8)


def test_density_of_u_is_unchanged(fit, dens):
    """``log p_s(s) − log|det ∂u/∂s| = log p_x(x) − log|det ∂u/∂x|`` at the same ``u`` (the
    determinants by jax.jacfwd of the maps): the
    target in the fit's parameters (likelihood × priors) is the one the plain coordinates
    sample — the map changes coordinates, not the distribution."""
    plain, fric = dens
    U = _points(fit, n=8, seed=4)
    X, S = plain.to_sampled_np(U), fric.to_sampled_np(U)
    lx = np.asarray(plain.batch(jnp.asarray(X)))
    ls = np.asarray(fric.batch(jnp.asarray(S)))
    # log|det ∂u/∂·| by autodiff of each map (independent of the log-Jacobian the
    # density itself adds: a density that left it out would fail here)
    jx, js = (np.array([np.linalg.slogdet(np.asarray(
        jax.jacfwd(lambda y: lp.to_u(y)[0])(jnp.asarray(y))[:, :-1]))[1] for y in Y])
        for lp, Y in ((plain, X), (fric, S)))
    # points of zero density (the order tau_s ≥ tau_c, the start-angle box) are the same
    fin = np.isfinite(lx)
    assert fin.sum() >= 4 and np.array_equal(fin, np.isfinite(ls))
    # same log-density of u to rounding (|log p| ~ 1e2–1e4: 1e-9 relative)
    np.testing.assert_allclose((ls - js)[fin], (lx - jx)[fin], rtol=1e-9, atol=1e-8)
    # and the Jacobian is not zero: without it the two densities would differ
    assert np.max(np.abs(js - jx)) > 1e-3


def test_outside_the_law_has_zero_density(dens, fit):
    """Torques no (tau_c > 0, c_v > 0) law with these (tau_s, v_s, delta) reaches —
    here the low-speed torque far above the high-speed one with tau_c forced negative —
    have zero density; the NumPy inverse marks them NaN."""
    _, fric = dens
    fc = fric.friction
    s = fric.to_sampled_np(np.concatenate([fit.u, [np.log(0.3 * fit.resolution_rad)]]))
    bad = s.copy()
    bad[fc.idx[0]] = 1e-3  # the low-speed torque ~0: tau_c < 0 needed
    assert np.asarray(fric.batch(jnp.asarray(bad[None])))[0] == -np.inf
    assert np.isnan(fric.from_sampled_np(bad[None])[0, fc.idx[0]])


def test_no_friction_law_means_plain(fit):
    """A model without the free Stribeck + viscous law gets no map (and a warning)."""
    from hdid._posterior.coordinates import NAMES

    assert set(NAMES) <= set(fit.problem.free)
    fixed = hdid.fit(EXAMPLE, fix={"c_v": 1.8e-5})
    assert "c_v" not in fixed.problem.free
    assert friction_coordinates(fixed) is None
    d = posterior_density(fixed, coordinates="friction")
    assert d.lp.friction is None and any("coordinates='friction'" in w for w in d.warnings)


def test_default_samples_in_friction_coordinates(fit):
    """``sample_posterior``'s default (``coordinates="auto"``) moves the walkers in the
    friction coordinates when the law is free, and reports it; a short chain's draws are
    the fit's parameters (tau_c, c_v positive and finite), not the torques."""
    from hdid._posterior import sample_posterior

    post = sample_posterior(fit, n_steps=20, burn_in=0, seed=0, modes="fit")
    assert post.coordinates == "friction"
    assert post.to_dict()["posterior_diagnostics"]["coordinates"] == "friction"
    for n in ("tau_c", "c_v"):
        v = np.asarray(post.samples[n])
        assert np.all(np.isfinite(v) & (v > 0))
    # the draws sit near the fit's values (≤ 2 of its standard errors at the median),
    # which torques of order 1 (the data coordinates) would not
    for n in ("tau_c", "c_v"):
        p = fit.parameters[n]
        assert abs(np.median(post.samples[n]) - p.value) < 2 * p.std
    with pytest.raises(ValueError, match="coordinates"):
        sample_posterior(fit, n_steps=5, burn_in=0, modes="fit", coordinates="torque")
