"""A coasting servo's back-EMF brake on real drops: Feetech STS3215 pendulum drops
(``../shared/data/real/sts3215_drop``; K-Scale's BAM-protocol bench, torque off at release).

With its driver off, the motor's back-EMF passes the 12 V supply plus two freewheel-diode drops
above ``w_e = (12 + 2·0.7) V / k_e`` (k_e = the lab's own fitted k_t, 3.61 V s/rad at the output:
3.71 rad/s), and the bridge's diodes brake it (:class:`hdid.effects.BackEmfBraking`). The energy
lost per half-swing puts a brake's threshold at 3.0–4.75 rad/s in all eight set-ups without a fit
(``benchmarks/real_logs.py --energy``). Without the brake the fitted Stribeck law stands in for it
by rising with speed (on this set-up tau_c 0.33 N m over tau_s 0.17 N m at 75c7da4; the
benchmark's older base fit ran to tau_c = 3000 N m at v_s = 88 rad/s, an ω⁴ rise); with the
brake's threshold held at the clamp speed, the Stribeck law falls with speed as a physical one
does (tau_c 0.16 under tau_s 0.35; ``--sts back_emf@clamp``).
"""

from __future__ import annotations

import pytest

import hdid
from hdid.effects import library

from synthetic import ROOT, real_reference

STS = ROOT.parent / "shared" / "data" / "real" / "sts3215_drop"
SETUP = "m0.741_l0.15"   # swings to 6.7 rad/s, well past the clamp speed; ~30 s to fit


@pytest.fixture(scope="module")
def braked():
    ref = real_reference(STS.name)
    w_e = (12.0 + 2 * 0.7) / ref["bam_fits_published"]["m1"]["kt"]  # the clamp speed [rad/s]
    v = ref["setups"][SETUP]
    model = (hdid.Model.default(inertia=v["bam_m6_total_inertia_kgm2"], ratio=1.0).without("stiffness")
             .with_effect(library({})["gravity"])
             .with_effect(library({"mgl": v["mgl_point_mass_Nm"], "w_e": w_e})["back_emf"]))
    return hdid.fit(STS / v["csv"], model, fix={"w_e": w_e})


def test_the_stribeck_law_is_physical_again(braked):
    p = {n: e.value for n, e in braked.parameters.items()}
    # a Stribeck law's kinetic level lies below its static one (the friction falls as the
    # contact lifts off); the fit without the brake has tau_c/tau_s ≈ 1.9, with it ≈ 0.5
    assert p["tau_c"] <= p["tau_s"], p
