"""The stick-band bracket's reference simulations at the bracket's own tolerance
(``_derived.BRACKET_RTOL``, issue 37): the ends it reports agree with the reference
simulator's default tolerance far inside the precision the bracket needs, for fewer
right-hand-side evaluations."""

from __future__ import annotations

import functools
from types import SimpleNamespace

import pytest

from hdid import reference
from hdid._models._model import CATALOG_CSF8, Model
from hdid._problems import _derived

#: Runs released from rest at ±0.157 rad (wave generator), the paper design's amplitude;
#: their logged rest points only set the lower end.
RUNS = [SimpleNamespace(theta0=a, rest_logged=0.01) for a in (0.157, -0.157)]


def _bracket(monkeypatch, **tolerances):
    """``band_bracket`` of the catalog CSF-8 with the reference at ``tolerances``
    (default: the bracket's own), and the right-hand-side evaluations it took."""
    n = [0]
    real = reference.reference_trajectory

    def counted(*a, **k):
        k.update(tolerances)
        extra = k["extra_torque"]

        def count(th, w):
            n[0] += 1
            return extra(th, w)

        return real(*a, **{**k, "extra_torque": count})

    monkeypatch.setattr(reference, "reference_trajectory", counted)
    model = Model.default().with_ratio(100.0).replace(**CATALOG_CSF8)
    return _derived.band_bracket(model, RUNS, 0.5), n[0]


def test_the_bracket_matches_the_tight_reference_for_fewer_evaluations(monkeypatch):
    (lo, hi), n = _bracket(monkeypatch)
    (lo_ref, hi_ref), n_ref = _bracket(monkeypatch, rtol=1e-11, atol=1e-14)
    assert lo == lo_ref == 0.01
    # the bracket is printed to 1e-4 rad and compared with the band's standard error:
    # 1e-6 relative (1.6e-7 rad here) is three orders below what it is read to
    assert hi == pytest.approx(hi_ref, rel=1e-6)
    assert lo < hi < 0.157  # a reversal inside the swing, not the release
    # DOP853's steps scale as rtol^(-1/8) (2.4x fewer from 1e-11 to 1e-8) between the
    # events, whose location costs the same: 1.43x fewer here (2738 vs 3914); at least 1.25x
    assert n * 1.25 < n_ref, (n, n_ref)


def test_the_bracket_passes_its_tolerance_to_every_simulation(monkeypatch):
    seen = []
    real = reference.reference_trajectory
    monkeypatch.setattr(reference, "reference_trajectory", functools.partial(
        lambda *a, **k: seen.append((k.get("rtol"), k.get("atol"))) or real(*a, **k)))
    _derived.band_bracket(Model.default().with_ratio(100.0), RUNS, 0.5)
    assert seen == [(_derived.BRACKET_RTOL, _derived.BRACKET_ATOL)] * len(RUNS)
