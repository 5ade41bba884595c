"""Real pendulum drops measured by others (issue 33, "Real logs by others" and "Pendulum
drops"): a servo lifts an arm, cuts the torque, and the arm swings under gravity until it
sticks. Only options a user knows from the experiment: ``--ratio 1 --remove stiffness
--add gravity --inertia I``.

- **BAM XL330** (Rhoban/bam, ``../shared/data/real/bam_xl330``): a 0.49 kg pendulum at
  0.10 m, BAM's 5 ms resampling (readings on no encoder grid). The issue's criteria:
  every run released and resting within 0.01 rad of its logged rest, m·g·l within 15 %
  of 0.48 N m, stick band half-width within [0.018, 0.040] rad (BAM's M2: 0.026).
- **Feetech STS3215** (K-Scale, ``../shared/data/real/sts3215_drop``): raw jittered
  timestamps (10–17 ms steps), a servo that is still lifting the arm when the torque is
  cut. Two of the eight set-ups (the two whose runs swing at least three half-periods,
  where the log times the frequency best). What the physics fixes is checked, not the
  lab's friction numbers (their README's caveats): m·g·l against the point mass's
  ``m·g·l`` within 15 %, every run released when the servo cut the torque, and the
  model's rests within its stick band of the logged ones.

The logs stay outside the repository; the tests skip, naming the folder, when it is absent.
"""

from __future__ import annotations

import json

import pytest

import hdid
from hdid.effects import library

from synthetic import ROOT, cli_fit_json

REAL = ROOT.parent / "shared" / "data" / "real"
BAM = REAL / "bam_xl330" / "bam_xl330_drop_processed.csv"
STS = REAL / "sts3215_drop"


def _need(path):
    if not path.exists():
        pytest.skip(f"{path.name} not in {path.parent} (real logs stay outside the "
                    "repository: ../shared/data/real/README.md says where they come from)")


def _released(runs, warnings):
    assert not [w for w in warnings if "never releases" in w], warnings
    for run in runs:
        assert run["peak_speed"] > 0, run


@pytest.fixture(scope="module")
def bam_fit(tmp_path_factory):
    _need(BAM)
    out = tmp_path_factory.mktemp("bam") / "fit.json"
    return cli_fit_json(BAM, out, "--ratio", "1", "--remove", "stiffness", "--add", "gravity",
                        "--inertia", "0.006714")[0]


def test_bam_xl330_every_run_released(bam_fit):
    _released(bam_fit["runs"], bam_fit["warnings"])


# What was tried on this log (one `hdid fit` each, the options plus --add ...;
# |rest_model - rest_logged| per run kp100/kp200/kp400/kp800 in rad):
# - base (Stribeck + viscous): RMS 1.048e-2 rad (65x the log's own noise 1.6e-4), rests
#   0.0046/0.0018/0.0139/0.0105, mgl 0.4705 (re-measured at 36628c1; the 9.50e-3 and rests
#   0.0015/0.0001/0.0096/0.0115 quoted before came from before 8047178, which weights a
#   still stretch repeating one printed level as one reading: the optimum moved with the
#   likelihood, a fit restarted at the old parameters slides to the new one). base +
#   back_emf / + hysteresis end at the base's optimum (the effect at its neutral value).
# - hdid diagnose (--selection-steps 2): "unexplained"; candidates by dBIC: ripple (order 6)
#   -1837, gravity_friction -436, load_friction -346, asymmetric_friction -43; back_emf,
#   hysteresis, reading_age no gain. Ladder: + ripple:6 (42.8x the noise), + hysteresis (34.7x).
# - + gravity_friction: c_g 0.080 N m, RMS 9.48e-3, rests 0.0063/0.0034/0.0160/0.0100.
#   (A model-free energy balance per half-swing prefers F0 + c_g|sin| to F0 + c_v, with
#   c_g 0.098-0.117 N m per run, near BAM's M6 0.26*mgl = 0.12 N m; the trajectory fit
#   does not follow it: the misfit is dominated by something else.)
# - + ripple:6: RMS 6.89e-3, rests 0.0070/0.0034/0.0147/0.0073.
# - + ripple:6 + hysteresis (diagnose's ladder): RMS 5.59e-3, rests 0.0044/0.0021/0.0005/
#   0.0017, mgl 0.487, but the band reported is 0.0067 rad (outside [0.018, 0.040]; the Dahl
#   element holds the rest, (tau_s + f_h)/mgl = 0.026) and an output ripple of 6 per rev has
#   no known source in a spur gear. f_h/sigma_h = 0.011 rad matches the tails' reversals
#   inside the base band (kp400 turns at -0.016 rad and creeps back 0.013 rad): free play
#   or presliding compliance in the gear train.
# - + gravity_friction + hysteresis: rests within 0.0073 but mgl 0.384 (-20 %), f_h/sigma_h
#   2.4 rad (an extra spring, not friction), band 0.
# No library model meets all three criteria (rests, mgl, band) on this log.
@pytest.mark.xfail(strict=True, reason=(
    "kp400 rests 0.0139 rad and kp800 0.0105 rad from their logged rests in the best optimum "
    "hdid knows for the Stribeck + viscous law (RMS 1.048e-2 rad); gravity_friction, "
    "back_emf, hysteresis, reading_age, ripple and diagnose's ladder (ripple:6 + "
    "hysteresis) each miss a criterion (see the comment above)"))
def test_bam_xl330_rests_within_a_hundredth_of_a_radian(bam_fit):
    for run in bam_fit["runs"]:
        # the criterion: the model rests within 0.01 rad of the logged rest
        assert abs(run["rest_model"] - run["rest_logged"]) <= 0.01, run


def test_bam_xl330_gravity_and_stick_band(bam_fit):
    mgl = bam_fit["parameters"]["mgl"]["value"]
    # the criteria: m·g·l within 15 % of 0.49 kg · 9.81 · 0.10 m ≈ 0.48 N m (the
    # arm's own mass and the inertia BAM fitted are not known better), and a stick band
    # of the size BAM's M2 friction gives (0.026 rad) within [0.018, 0.040]
    assert abs(mgl / 0.48 - 1) <= 0.15, mgl
    band = bam_fit["stick_band_halfwidth_rad"]
    assert 0.018 <= band <= 0.040, band


def _sts_reference():
    return json.loads((STS / "reference.json").read_text())


@pytest.mark.parametrize("setup", ["m1.168_l0.15", "m0.969_l0.15"])
def test_sts3215_drop(setup):
    _need(STS / "reference.json")
    ref = _sts_reference()["setups"][setup]
    path = STS / ref["csv"]
    _need(path)
    # `hdid fit sts3215_….csv --ratio 1 --remove stiffness --add gravity --inertia I`,
    # I = the lab's armature + m·l² (reference.json)
    model = (hdid.Model.default(inertia=ref["bam_m6_total_inertia_kgm2"], ratio=1.0)
             .without("stiffness").with_effect(library({})["gravity"]))
    result = hdid.fit(path, model)
    out = result.to_dict()
    _released(out["runs"], result.warnings)
    # m·g·l of the point mass; the arm (not weighed) adds ~2.6 %, the inertia is the
    # lab's fit: 15 %
    mgl = result.parameters["mgl"].value
    assert abs(mgl / ref["mgl_point_mass_Nm"] - 1) <= 0.15, (mgl, ref["mgl_point_mass_Nm"])
    # released where the log's servo cut the torque (reference.json, per run): the arm is
    # at its turning point then and stays within a count of it for ~2·sqrt(2·step/α)
    # ≈ 20 ms (α ≈ 30 rad/s² there), plus a sample of jitter either side: 40 ms
    for run in out["runs"]:
        logged = ref["runs"][run["name"]]["release_time_in_csv_s"]
        assert abs(run["release_time"] - logged) <= 0.04, (run["name"], run["release_time"], logged)
    # rests: a rest anywhere inside the stick band is one the law allows (the rest point
    # depends discontinuously on the parameters), so the model rests within the fitted
    # band's half-width of the logged rest; a run left at its hold, or swinging on, would
    # be ~1 rad off
    band = out["stick_band_halfwidth_rad"]
    for run in out["runs"]:
        assert abs(run["rest_model"] - run["rest_logged"]) <= band, (run, band)
