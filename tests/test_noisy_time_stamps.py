"""Logs as test stations write them, fit side: stamps rounded to the time column's print
unit, and fine encoders that measure the swing's frequency to parts per million.

- A reading whose instant is printed to ``u`` (whole milliseconds from ``millis()``) is
  compared with the model at an instant up to ``u`` off: ``ω·u/√12`` rad of error at speed
  ``ω``, far above a fine encoder's ``step/√12`` while the gear moves
  (:mod:`hdid._simulation._timing`). World log 21 (2^20 counts, 200 Hz with jitter,
  stamps to 1 µs): 2.54× the floor, k1 21.9 of its standard errors off, no warning.
- RK4 at the fit's substep runs the swing slow by ``(h·ω)⁴/120``, which the fit takes up in
  k1 (:mod:`hdid._simulation._phase_error`): world logs 04/05/11/14, k1 +9 … +48 ppm at
  4–10 sd on 2^18–2^20 counts, the RMS at the floor.

The logs are written here by the reference (event-driven) simulator at the true instants.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

import hdid
from hdid._fitting._limits import above_floor
from hdid._simulation._phase_error import frequency_bias
from hdid._simulation._prepare import prepare
from hdid.reference._events import reference_trajectory
from hdid.reference._logs import _sim_kwargs, encoder_step
from hdid.reference.logs import TRUTH_CSF8, make_log

#: a 19.4 Hz gear, light Coulomb friction: ~4 swings a run before it sticks
TRUTH = dict(TRUTH_CSF8, k1=104.0, k2=7.2e6, tau_c=1e-4, tau_s=1e-4, v_s=5.0, delta=1.0,
             c_v=2e-6)


def _stamped_log(path, seed=1, fs=200.0, cpr=2**16, duration=0.6, stamps="%d", jitter=0.02):
    """Two runs (±0.157 rad) at instants ``k/fs`` jittered by ``jitter`` of a period, read
    on ``cpr`` counts; the stamps written in ms as ``stamps`` prints them (``%d``: whole
    milliseconds, cut as ``millis()`` cuts them)."""
    rng = np.random.default_rng(seed)
    kw, step, rows = _sim_kwargs(TRUTH), encoder_step(cpr), []
    n = int(duration * fs)
    for i, a in enumerate((0.157, -0.157), start=1):
        t = np.sort(np.arange(n) / fs + rng.normal(0.0, jitter / fs, n))
        t -= t[0]
        t_rel = 0.05 + rng.uniform(0.0, 1.0) / fs
        th, _ = reference_trajectory(float(t[-1]), theta0=a, t_release=t_rel, **kw).evaluate(t)
        ms = np.floor(t * 1e3 + 1e-9) if stamps == "%d" else t * 1e3
        rows.append(np.column_stack((np.full(n, i), ms, np.round((th - 0.3) / step) * step)))
    np.savetxt(path, np.vstack(rows), fmt=["%d", stamps, "%.9f"], delimiter=",",
               header="run,time [ms],theta [rad]", comments="")
    return path


def test_stamps_on_the_print_grid_add_nothing_rounded_ones_weigh_by_speed(tmp_path):
    # A uniform 200 Hz clock in whole ms: every stamp is its instant (5 ms steps), nothing
    # to add: the prepared log is what it was. The same log with 2 % jitter cut to whole
    # ms: each reading's error is √(step²/12 + ω²u²/12), its weight divided by
    # √(1 + (ω·u/step)²) — 1 at rest, ~200 at the 18 rad/s peak on 2^16 counts.
    exact = prepare(hdid.read_log(_stamped_log(tmp_path / "a.csv", jitter=0.0)))
    assert exact.time_scale is None
    assert exact.floor == pytest.approx(exact.resolution / math.sqrt(12.0), rel=1e-12)
    prep = prepare(hdid.read_log(_stamped_log(tmp_path / "b.csv")))
    assert prep.time_print_unit == pytest.approx(1e-3)
    s = prep.time_scale
    held = s[0, : int(prep.first_moved[0]) - 1]
    assert held.size and np.all(held == 1.0)  # at rest: the step's rounding alone
    # peak speed of a 0.157 rad, 19.4 Hz swing: ≈ 19 rad/s (the central differences of
    # 5 ms steps read sin(ωh)/(ωh) = 0.94 of it, Coulomb friction takes some): 120-220
    peak = float(np.max(s)) * prep.resolution / 1e-3
    assert 12.0 < peak < 22.0, peak
    # the effective readings stay the readings (one each, a still stretch one in all); the
    # floor is the RMS the weighted residual reaches, χ² = n_effective·(RMS/floor)²
    assert prep.n_effective == pytest.approx(exact.n_effective, rel=0.05)
    sigma = prep.resolution / math.sqrt(12.0)
    w2 = float(np.sum(prep.weight**2))
    assert prep.floor == pytest.approx(sigma * math.sqrt(prep.n_effective / w2), rel=1e-12)
    assert prep.floor > 2.0 * sigma


@pytest.fixture(scope="module")
def ms_fit(tmp_path_factory):
    path = _stamped_log(tmp_path_factory.mktemp("ms") / "ms.csv")
    return hdid.fit(hdid.read_log(path), ratio=TRUTH["ratio"], inertia=TRUTH["inertia"])


def test_millisecond_stamps_fit_to_their_floor_with_honest_errors(ms_fit):
    # Before: the floor was the step's rounding alone: 62.7x it, "the model does not
    # describe this log", delta 176 sd from its truth. The stamps' rounding in the budget:
    # at the floor (the chi2 tail test for the log's effective readings and unknowns) and
    # the stiffness within 4 of its standard errors of the truth (|z| > 4: 6e-5 by chance).
    r = ms_fit
    assert r.time_print_unit == pytest.approx(1e-3)
    assert r.timing_floor_rad > 2.0 * r.resolution_rad / math.sqrt(12.0)  # (3.0x here)
    ratio = r.rms_residual_rad / r.quantization_floor_rad
    assert ratio <= above_floor(r.n_effective, r.n_unknowns), ratio
    assert not [w for w in r.warnings if "floor" in w and "RMS" in w], r.warnings
    for name in ("k1", "tau_c"):
        p = r.parameters[name]
        assert abs(p.value - TRUTH[name]) < 4.0 * p.std, (name, p.value, p.std)
    assert "time stamps" in r.report()
    d = r.to_dict()
    assert d["time_print_unit"] == pytest.approx(1e-3)
    assert d["quantization_floor_rad"] == pytest.approx(r.timing_floor_rad)


def test_the_rk4_phase_error_is_the_one_the_warning_predicts():
    # A frictionless linear swing simulated at two substeps: the frequency a cosine fit
    # reads off it against (h·ω)⁴/120. The series' next term (θ⁶) and the fit of 100
    # samples leave ~10 % at h·ω = 0.2.
    from scipy.optimize import least_squares

    k1, inertia, ratio = TRUTH["k1"], TRUTH["inertia"], TRUTH["ratio"]
    f = math.sqrt(k1 / (inertia * ratio**2)) / (2 * math.pi)
    model = hdid.Model(effects=(hdid.CubicStiffness(k1=k1, k2=0.0),), inertia=inertia,
                       ratio=ratio)
    t = np.arange(0.0, 0.5, 0.005)
    for h in (2.5e-3, 1.25e-3):  # two and four substeps a sample
        theta = np.asarray(hdid.simulate(model, t, 0.1, 0.0, max_substep=h))
        fit = least_squares(lambda p: p[0] * np.cos(2 * math.pi * p[1] * t) - theta,
                            [0.1, f], xtol=1e-15, ftol=1e-15, gtol=1e-15)
        slow = 1.0 - fit.x[1] / f
        assert slow == pytest.approx(frequency_bias(h, f), rel=0.1), (h, slow)


@pytest.fixture(scope="module")
def fine_fit():
    df = make_log(TRUTH, [0.157, -0.157], 250.0, 0.6, 0.05, {"A": 0.3}, 3,
                  counts_per_rev=2**20)
    return hdid.fit(df, ratio=TRUTH["ratio"], inertia=TRUTH["inertia"])


def test_a_fine_encoder_fit_says_when_the_substep_biases_k1(fine_fit):
    # 2^20 counts at 250 Hz measure this swing's frequency to 2.5 ppm; the fit's substep
    # (4 ms in two, h·ω 0.24) runs it slow by 2.9e-5. Before: k1 +45 ppm at 9.0 of its
    # standard errors (k2 5.3), RMS 0.93x the floor, no word of it. Either the stiffness is
    # within 3 of its standard errors of the truth (a substep fine enough: |z| > 3 by
    # chance 0.3 %) or the warnings name the substep's bias.
    p = fine_fit.parameters["k1"]
    z = (p.value - TRUTH["k1"]) / p.std
    said = [w for w in fine_fit.warnings if "RK4 substep" in w]
    assert abs(z) < 3.0 or said, (z, fine_fit.warnings)
