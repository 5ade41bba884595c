"""The friction-shape warning names every determined parameter whose variance runs along an
undetermined Stribeck shape, not only the law's levels.

A world-test log with ``v_s`` far above the peak speed: the viscous ``c_v`` traded with the
Stribeck slope (multiple correlation 0.996 with ``tau_c, v_s, delta``), its standard error was
the shape's linearised spread and it sat 8.8 of them from the truth, unwarned. These tests
hand :func:`hdid._fitting._identifiability._shape_warnings` a stand-in covariance built from
independent unit factors, so each correlation is known by construction (no fit).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np

from hdid._fitting._identifiability import HIGH_CORRELATION, _shape_warnings
from hdid.effects import StribeckFriction

FREE = ("k1", "tau_c", "tau_s", "v_s", "delta", "c_v")
SHAPE_FLAGS = {"v_s": "not determined by the data: the weak prior sets it",
               "delta": "not determined by the data: the weak prior sets it"}


def _problem(free=FREE):
    law = StribeckFriction(tau_c=1e-5, tau_s=2e-5, v_s=0.05, delta=2.0)
    return SimpleNamespace(free=free, base=SimpleNamespace(effects=[law]))


def _covariance(loadings: dict[str, dict[str, float]], scale: dict[str, float]) -> np.ndarray:
    """``cov = D L Lᵀ D`` over ``FREE``: a parameter without loadings is its own unit factor;
    one with ``loadings[name] = {other: a}`` is ``Σ a·other + √(1 − Σa²)·(its own noise)``,
    so its correlation with ``other`` is ``a``; ``D`` gives the parameters different
    units (the warning must not depend on them)."""
    n = len(FREE)
    L = np.zeros((n, 2 * n))
    for i, name in enumerate(FREE):
        a = loadings.get(name)
        if a is None:
            L[i, i] = 1.0
            continue
        for other, x in a.items():
            L[i, FREE.index(other)] = x
        L[i, n + i] = math.sqrt(1.0 - sum(x * x for x in a.values()))
    d = np.array([scale.get(name, 1.0) for name in FREE])
    return (L * d[:, None]) @ (L * d[:, None]).T


def _warn(cov, flags=SHAPE_FLAGS, free=FREE):
    std = np.sqrt(np.diag(cov))
    return _shape_warnings(_problem(free), dict(flags), cov, std)


def _named(warnings, name):
    return [w for w in warnings if w.startswith(f"{name}:")]


def test_viscous_trading_with_an_undetermined_shape_is_named():
    """c_v = 0.99·v_s + noise: R = 0.99 > HIGH_CORRELATION; its error at a fixed shape is
    √(1 − 0.99²) = 0.141 of the stated one, so the warning says 7.09×. k1 (independent)
    and the levels' own warning are unchanged."""
    cov = _covariance({"c_v": {"v_s": 0.99}}, scale={"c_v": 7e-5, "k1": 350.0, "v_s": 16.0})
    out = _warn(cov)
    assert any(w.startswith("tau_c, tau_s: standard errors assume the Stribeck shape (v_s, delta)")
               for w in out)
    (cv,) = _named(out, "c_v")
    assert "v_s, delta" in cv and "multiple correlation 0.990" in cv
    assert f"{1 / math.sqrt(1 - 0.99**2):.3g}×" in cv  # 7.09×, by construction
    assert "--posterior" in cv
    assert not _named(out, "k1")


def test_multiple_not_pairwise_correlation_decides():
    """c_v loads 0.69 on each of v_s and delta: every pairwise |r| is 0.69 < 0.95, so the
    pairwise correlation warning stays silent, but together they explain R² = 2·0.69² = 0.952
    of its variance (R = 0.976 > 0.95): named. At loadings 0.6 (R² = 0.72, R = 0.85): not."""
    cov = _covariance({"c_v": {"v_s": 0.69, "delta": 0.69}}, scale={"c_v": 1e-4})
    (cv,) = _named(_warn(cov), "c_v")
    assert f"multiple correlation {math.sqrt(2 * 0.69**2):.3f}" in cv
    assert 0.69 < HIGH_CORRELATION < math.sqrt(2 * 0.69**2)
    cov = _covariance({"c_v": {"v_s": 0.6, "delta": 0.6}}, scale={"c_v": 1e-4})
    assert not _named(_warn(cov), "c_v")


def test_any_parameter_not_a_fixed_list():
    """k1 trading with the shape is named the same way; c_v independent of it is not."""
    cov = _covariance({"k1": {"v_s": -0.98}}, scale={"k1": 350.0})
    out = _warn(cov)
    assert _named(out, "k1") and not _named(out, "c_v")


def test_a_flagged_level_counts_as_part_of_the_undetermined_law():
    """tau_c flagged (it trades with v_s) joins the shape: c_v loading 0.8 on tau_c and 0.59
    on v_s has R² = 0.64 + 0.348 = 0.988 with both, 0.64 with tau_c alone; named, with the
    flagged tau_c listed among the undetermined."""
    flags = dict(SHAPE_FLAGS, tau_c="poorly determined by the data alone (±orders of magnitude from data)")
    cov = _covariance({"c_v": {"tau_c": 0.8, "v_s": 0.59}}, scale={"c_v": 7e-5})
    out = _warn(cov, flags)
    (cv,) = _named(out, "c_v")
    assert "tau_c, v_s, delta" in cv


def test_a_determined_shape_names_nothing():
    """The same c_v–v_s trade with v_s and delta determined: no shape doubt, no warning."""
    cov = _covariance({"c_v": {"v_s": 0.99}}, scale={"c_v": 7e-5})
    assert _warn(cov, flags={}) == []
