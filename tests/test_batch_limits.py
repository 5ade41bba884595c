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
