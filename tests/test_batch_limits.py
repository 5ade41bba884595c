"""The batch's default (``nested=None``) runs hdid.fit's limit checks where a log's fit ends
above the floor, and leaves a fit at the floor as it is."""

from __future__ import annotations

import pytest

import hdid
from hdid._fitting._limits import reached_floor
from hdid.reference import logs

#: A stiff gear on the paper design: its hardened swing (≈ 108 Hz) 0.87× the 250 Hz log's
#: Nyquist frequency, friction sized for a long ring-down (one of 20 random stiff-gear logs
#: on which the batch without the checks sat 10× above the floor while hdid.fit, with them,
#: reached it).
STIFF = dict(k1=3035.9, k2=1.1476e8, tau_c=9.2478e-4, tau_s=2.1871e-3, v_s=1.7888,
             delta=1.6466, c_v=4.1586e-6, inertia=7e-7)


@pytest.fixture(scope="module")
def stiff():
    log = logs.make_log(STIFF, **{**logs.PAPER_DESIGN, "seed": 9101})
    unchecked = hdid.fit_many([log], inertia=STIFF["inertia"], nested=False).result[0]
    default = hdid.fit_many([log], inertia=STIFF["inertia"]).result[0]
    return unchecked, default


def test_the_batch_checks_the_limits_of_a_fit_above_the_floor(stiff):
    unchecked, default = stiff
    # the case: the batch's own optimum has not reached the floor (the 99.9 % point of
    # the floor's χ²_ν, _limits.reached_floor), where hdid.fit checks every limit
    assert not reached_floor(unchecked)
    # the default batch ran those checks (every limit recorded) and kept the better optimum
    assert {lim["limit"] for lim in getattr(default, "limits", [])} >= {"coulomb", "no_cubic"}
    assert default.rms_residual_rad <= unchecked.rms_residual_rad
    # ... which reaches the floor here, with the stiffness of the gear that made the log:
    # at the floor the fitted k1's own std is well under 5 % on a paper log; 5 % tells
    # the right basin from the aliased ones (a fold of the swing moves k1 by ≥ 30 %)
    assert reached_floor(default)
    assert abs(default.parameters["k1"].value / STIFF["k1"] - 1) < 0.05
    assert not any("did not check it against its limits" in w for w in default.warnings)


def test_the_batch_schedules_its_limit_checks_as_hdid_fit(monkeypatch):
    """The limit checks' starts and schedule follow the fit's number of grid starts
    (``nested_check(lanes=…)``: each limit ``lanes − 1`` grid starts beside the fit's
    optimum, its rows scheduled ``lanes`` at a time). hdid.fit passes its starts' count;
    the batch passed none, so its checks above the floor had 2 grid starts a limit in one
    schedule — other optima than hdid.fit's on the same log. The checks are replaced by a
    recorder here (no limit fitted): the call's arguments are the claim."""
    from pathlib import Path

    from hdid._fitting import _fit, _vfit

    calls: dict = {}

    def recorder(tag):
        def check(result, log, setup, **kw):
            calls.setdefault(tag, []).append(kw)
            result.limits, result.restarted_from = [], None
            return result
        return check

    monkeypatch.setattr(_fit, "nested_check", recorder("fit"))
    monkeypatch.setattr(_vfit, "nested_check", recorder("batch"))
    example = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"
    hdid.fit(example, nested=True)
    hdid.fit_many([example], nested=True)
    fit_kw, batch_kw = calls["fit"][0], calls["batch"][0]
    assert fit_kw["lanes"] >= 2  # (hdid.fit: its grid starts)
    assert batch_kw.get("lanes") == fit_kw["lanes"]
    # the same local fits handed to the check (the batch's on the padded problem)
    assert len(batch_kw["solutions"][0]) == len(fit_kw["solutions"][0])
