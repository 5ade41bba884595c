"""The batch with logs as lanes (``fit_many(lanes="logs")``, the GPU path): each log gets the
fit the one-start-a-call batch gives it, whatever lanes it shares a call with."""

from __future__ import annotations

import numpy as np
import pytest

import hdid
from hdid._fitting import _log_lanes

PARAMS = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v")


@pytest.fixture(scope="module")
def fits(tmp_path_factory):
    """Three paper-design logs of one length bucket with truths far apart (k1 and tau_c
    0.8x, 1x, 1.25x: a log fitted on another's problem would be off by tens of percent),
    fitted by the default batch and as lanes four to a call (a log's six starts span
    two calls, and calls hold starts of different logs)."""
    from hdid.reference import logs

    out = tmp_path_factory.mktemp("lanes")
    paths = []
    for seed, scale in ((21, 0.8), (22, 1.0), (23, 1.25)):
        truth = dict(logs.TRUTH_CSF8, k1=940.0 * scale, tau_c=2.5e-3 * scale)
        path = out / f"log{seed}.csv"
        logs.make_log(truth, **dict(logs.PAPER_DESIGN, seed=seed)).to_csv(path, index=False)
        paths.append(path)
    return hdid.fit_many(paths), hdid.fit_many(paths, lanes="logs", lane_width=4)


def test_logs_as_lanes_give_each_log_its_own_fit(fits):
    one, lanes = fits
    assert lanes.attrs["timing"]["lanes"] == "logs" and lanes.attrs["timing"]["n_buckets"] == 1
    assert one.error.isna().all() and lanes.error.isna().all()
    for a, b in zip(one.result, lanes.result):
        ca, cb = a.starts.costs[a.starts.best], b.starts.costs[b.starts.best]
        # The same LM iterations on the same log; the lanes' vmapped simulator selects
        # where the one-lane one branches, so sums round differently (measured 1e-14 to
        # 1e-9 relative); 1e-6 is the project's same-numbers rule. A log fitted on another
        # log's problem is off by far more (its truth differs by 20-25 %).
        assert cb == pytest.approx(ca, rel=1e-6)
        for k in PARAMS:
            assert b.values[k] == pytest.approx(a.values[k], rel=1e-6), k
        assert b.warnings == a.warnings
    k1 = lanes["k1"].to_numpy()
    assert np.all(np.diff(k1) > 0)  # the logs' own order (0.8x < 1x < 1.25x)


def test_the_default_stays_one_start_a_call(fits):
    one, _ = fits
    assert one.attrs["timing"]["lanes"] == 1


def test_a_call_holds_at_most_a_gibibyte_of_jacobians(fits):
    _, lanes = fits
    p = lanes.result[0].problem  # a paper log: 4 runs of 125 samples
    assert _log_lanes.default_width(p) == _log_lanes.CPU_WIDTH  # far below the bound
    big = 8 * (p.times.size + p.n_physical) * p.n_unknowns
    # a bound of 3.5 paper problems' Jacobians: 3 lanes, rounded down to a power of two
    old = _log_lanes.LANE_JACOBIAN_BYTES
    try:
        _log_lanes.LANE_JACOBIAN_BYTES = int(3.5 * big)
        assert _log_lanes.default_width(p) == 2
    finally:
        _log_lanes.LANE_JACOBIAN_BYTES = old


def test_an_unknown_lanes_value_is_refused():
    with pytest.raises(ValueError, match="'logs'"):
        hdid.fit_many([], lanes="starts")
