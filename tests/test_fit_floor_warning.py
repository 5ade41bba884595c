"""A fit above its floor says so, by a χ² test that statistics can defend. On an encoder's
grid the floor is exact (the rounding, step/√12), so ``n·(RMS/floor)²`` over the ``n``
effective readings is χ² on ``n − unknowns`` degrees of freedom at the floor; a fit whose
upper tail is below FLOOR_TAIL has not reached it. The warning used to allow 1e-4 of the
swing for the simulator on top of the rounding: on a fine encoder that raised its bound
above the 3× of "does not describe" (HV7 world log07, 2^17 counts: 1.36× the floor, χ² 1260
on ν 660, silent), so a fit biased by its RK4 substep went unsaid."""

from __future__ import annotations

import math

import pytest
from scipy.stats import chi2

import hdid
from hdid._fitting._identifiability import RESIDUAL_FLOOR_FACTOR
from hdid._fitting._limits import FLOOR_TAIL
from hdid._fitting._plausibility import floor_test
from hdid.reference import logs
from hdid.reference._logs import TRUTH_CSF8

#: The paper gear with a hundredth of its friction (a ~58 Hz swing that rings through the
#: 0.5 s runs at 250 Hz, ~229 effective readings) read by a 2^17-count encoder: a floor of
#: 1.4e-5 rad under a 0.157 rad release.
TRUTH = dict(TRUTH_CSF8, tau_c=2.5e-5, tau_s=4.5e-5, c_v=1.8e-7)
DESIGN = dict(logs.PAPER_DESIGN, amplitudes=[0.157, -0.157], offsets_by_setup={"A": 0.012})
COUNTS = 2**17
#: A forced coarse RK4 substep (the 4 ms sample period in 3, h·ω 0.5 at the swing): the
#: fit takes up its phase error in k1 (+0.07 %, tens of standard errors) and what k1
#: cannot take up is left over the rounding, under the 3× of "does not describe".
COARSE = 0.0014
#: The substep rule's own (h·ω 0.18): the phase error far below the rounding.
FINE = 0.0005


@pytest.fixture(scope="module")
def fine_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("floor_warning") / "fine_encoder.csv"
    logs.make_log(TRUTH, **DESIGN, counts_per_rev=COUNTS).to_csv(
        path, index=False, float_format="%.9f")
    return hdid.read_log(path)


def _fit(log, h):
    # (a substep the caller gives stands: no precision refit replaces it)
    return hdid.fit(log, inertia=TRUTH["inertia"], max_substep=h, n_starts=2)


def _said(r):
    return [w for w in r.warnings if "RMS residual" in w and "floor" in w]


def test_the_floor_test_is_the_chi2_tail():
    # chi2 = n·ratio², nu = n − unknowns, p its upper tail; the bound is where p = FLOOR_TAIL
    c, nu, p, bound = floor_test(680.0, 1.36, 20)
    assert (c, nu) == (pytest.approx(680 * 1.36**2), 660.0)
    assert p == pytest.approx(chi2.sf(680 * 1.36**2, 660), rel=1e-9)
    assert bound == pytest.approx(math.sqrt(chi2.ppf(1 - FLOOR_TAIL, 660) / 680), rel=1e-9)
    assert floor_test(680.0, bound, 20)[2] == pytest.approx(FLOOR_TAIL, rel=1e-6)


def test_a_coarse_substep_above_the_floor_warns(fine_log):
    r = _fit(fine_log, COARSE)
    ratio = r.rms_residual_rad / r.quantization_floor_rad
    c, nu, p, bound = floor_test(r.n_effective, ratio, r.n_unknowns)
    # the case in between: the chi2 test rejects the floor (p < FLOOR_TAIL) and the
    # residual is under the 3x of "does not describe"
    assert p < FLOOR_TAIL and ratio < RESIDUAL_FLOOR_FACTOR, (ratio, c, nu, p)
    said = _said(r)
    assert len(said) == 1 and "has not reached the floor" in said[0], r.warnings
    assert f"χ² {c:.4g} on ν {nu:.0f}" in said[0] and "substep" in said[0], said[0]
    # and it is right to: k1 is off its truth by more than 4 standard errors (6e-5 by chance)
    k1 = r.parameters["k1"]
    assert abs(k1.value - TRUTH["k1"]) > 4.0 * k1.std, (k1.value, k1.std)


def test_the_same_log_at_the_rule_substep_does_not_warn(fine_log):
    r = _fit(fine_log, FINE)
    ratio = r.rms_residual_rad / r.quantization_floor_rad
    assert floor_test(r.n_effective, ratio, r.n_unknowns)[2] >= FLOOR_TAIL, ratio
    assert _said(r) == [], r.warnings
    k1 = r.parameters["k1"]  # at the floor, the stiffness within 4 standard errors
    assert abs(k1.value - TRUTH["k1"]) < 4.0 * k1.std, (k1.value, k1.std)
