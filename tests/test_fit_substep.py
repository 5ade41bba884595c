"""hdid.fit picks its RK4 substep from the log's turning points; a log sampled below twice
its swing shows the swing's slow alias there, so the substep is picked for the alias. The
fit asks its fitted swing again (hdid._fitting._substep) and refits at the substep that
swing wants, keeping the lower χ² and saying so."""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

import hdid
from hdid._fitting import _limits
from hdid._fitting._substep import MAX_REFITS, refined, substep_for, substep_wanted

#: A stiff gear on the paper design (4 releases of ±0.157 rad read at 250 Hz): k1 13 600
#: N m/rad on 7e-7 kg m² through 100:1 swings at 222 Hz, above the log's 125 Hz Nyquist
#: frequency (its turning points show a ~29 Hz alias); light friction rings it down over
#: ~10 periods. The truth of the posterior SBC's paper seed 36016, rounded (drawn from the
#: default priors, not tuned), as in tests/test_posterior_basin.py.
STIFF = dict(k1=13600.0, k2=6.9e8, tau_c=3.8e-3, tau_s=1.13e-2, v_s=0.99, delta=0.49,
             c_v=2.3e-5, inertia=7e-7)


@pytest.fixture(scope="module")
def stiff_log(tmp_path_factory):
    """The stiff gear's encoder log written as a logger does (times and angles printed to 6
    decimals): its path."""
    from hdid.reference import logs

    df = logs.make_log(STIFF, **dict(logs.PAPER_DESIGN, seed=5))
    path = tmp_path_factory.mktemp("substep") / "stiff_250hz.csv"
    df.to_csv(path, index=False, float_format="%.6f")
    return path


@pytest.fixture(scope="module")
def stiff_fit(stiff_log):
    """``hdid.fit`` of the stiff gear's log, read back from the file (the inertia given:
    free motion fixes torques relative to it)."""
    return hdid.fit(stiff_log, inertia=STIFF["inertia"])


def test_an_aliased_swing_is_refitted_at_the_substep_it_wants(stiff_fit):
    """The fit's substep resolves its fitted swing (the rule's h·ω ≲ 0.27, the edge of its
    octave: 2π·60 Hz·0.5 ms·√2), the fit reaches the quantization floor (its own χ² tail
    test) and k1 is within 3 standard errors of the truth (99.7 % for a Gaussian error; the
    errors are scaled by max(χ²/ν, 1)); the warnings say it was refitted and why. At the 1 ms
    substep the log's turning points give, the fit ended at 16.5× the floor."""
    fit = stiff_fit
    f = 2 * math.pi * fit.derived["natural_frequency_hz"][0]
    assert fit.problem.max_substep * f <= 0.27, fit.problem.max_substep
    assert substep_wanted(fit, at_floor=True) is None
    assert _limits.reached_floor(fit), fit.rms_residual_rad / fit.quantization_floor_rad
    k1 = fit.parameters["k1"]
    assert abs(k1.value - STIFF["k1"]) <= 3 * k1.std, (k1.value, k1.std)
    note = [w for w in fit.warnings if w.startswith("refitted at the")]
    assert len(note) == 1 and "Nyquist" in note[0], fit.warnings


def _stand_in(f_hz: float, h: float, chi2: float):
    """A fit's stand-in: a swing at ``f_hz`` (4 runs released at 0.15 rad) fitted at the
    substep ``h`` [s] with the data χ² ``chi2`` (floor units), read at 250 Hz."""
    k1 = (2 * math.pi * f_hz) ** 2 * 7e-3
    th = np.tile(0.15 * np.cos(np.linspace(0, 20, 50)) * np.exp(-np.linspace(0, 5, 50)), (4, 1))
    prob = SimpleNamespace(theta=th, weight=np.ones_like(th), hold=th[:, 0], max_substep=h)
    return SimpleNamespace(problem=prob, derived={"natural_frequency_hz": (f_hz, 0.0)},
                           parameters={"k1": SimpleNamespace(value=k1)},
                           model=SimpleNamespace(ratio=100.0), sample_period=4e-3,
                           rms_residual_rad=math.sqrt(chi2 / 200), n_effective=200.0,
                           quantization_floor_rad=1.0, warnings=[], first_reading_held=())


def test_the_refit_keeps_the_lower_chi2_and_stops_after_two():
    """The rule around the refit, with stand-ins for the fits (no simulation): a substep the
    caller gave stands; a clearly under-resolved swing (h·ω above AT_FLOOR_HW) is refitted
    at the rule's substep for it, warm from the fitted model, and kept where its χ² is
    lower, else the coarser fit stays and says so; a refit that settles on a faster swing
    asks again, at most MAX_REFITS times; a swing the substep resolves is left alone."""
    calls = []

    def fake_fit(swing_hz, chi2):
        def fit(log, **options):
            calls.append(options)
            return _stand_in(swing_hz, options["max_substep"], chi2 / len(calls))
        return fit

    coarse = _stand_in(222.0, 1e-3, 1.6e4)  # h·ω 1.4
    assert refined(coarse, None, {"max_substep": 1e-3}, fake_fit(222.0, 47.0)) is coarse
    assert not calls
    new = refined(coarse, None, {"max_substep": None}, fake_fit(222.0, 47.0))
    assert len(calls) == 1 and calls[0]["start_from_model"] and calls[0]["model"] is coarse.model
    assert new.problem.max_substep == substep_for(222.0) == 1.25e-4
    assert new.warnings and new.warnings[0].startswith("refitted at the 0.125 ms")
    calls.clear()
    kept = refined(_stand_in(222.0, 1e-3, 40.0), None, {"max_substep": None},
                   fake_fit(222.0, 47.0))
    assert kept.problem.max_substep == 1e-3 and "ended higher" in kept.warnings[0]
    calls.clear()
    faster = refined(_stand_in(150.0, 1e-3, 1e3), None, {"max_substep": None},
                     fake_fit(1500.0, 10.0))  # each refit lower, on a 10x faster alias
    assert len(calls) == MAX_REFITS and faster.problem.max_substep == substep_for(1500.0)
    calls.clear()
    assert refined(_stand_in(60.0, 5e-4, 1e3), None, {"max_substep": None},
                   fake_fit(60.0, 1.0)).problem.max_substep == 5e-4  # h·ω 0.19: resolved
    assert not calls


def _same_optimum(a, b):
    """Two fits of one log in the same basin: χ² within 1 % of each other (two searches'
    last iterations, far under the χ²'s own scatter of √(2ν) ≈ 6 % for ν ≈ 500 readings)
    and k1 within a tenth of its standard error (the same optimum up to the searches, not
    another draw of the data)."""
    ca, cb = (r.rms_residual_rad**2 * r.n_effective for r in (a, b))
    assert abs(ca - cb) <= 0.01 * max(ca, cb), (ca, cb)
    ka, kb = a.parameters["k1"], b.parameters["k1"]
    assert abs(ka.value - kb.value) <= 0.1 * ka.std, (ka.value, kb.value, ka.std)


def test_the_batch_reaches_the_fits_answer_on_an_aliased_swing(stiff_log, stiff_fit):
    """fit_many runs hdid.fit's restarts and its substep refit by the same functions
    (_cubic_restart.restarted, _substep.refined; _vfit._settled). With its limit checks on
    (nested="auto", as hdid.fit) the batch finds the 222 Hz swing at the 1 ms substep of the
    log's turning points, 16.5x the floor, and stopped there; now it is refitted at the
    substep that swing wants and ends at hdid.fit's optimum, at the floor. (Without the
    checks the batch ends on the slow 31.5 Hz alias at 91x and its warning says to refit
    with nested='auto'.)"""
    res = hdid.fit_many([stiff_log], inertia=STIFF["inertia"], nested="auto")["result"][0]
    assert res.problem.max_substep == stiff_fit.problem.max_substep
    assert _limits.reached_floor(res), res.rms_residual_rad / res.quantization_floor_rad
    _same_optimum(res, stiff_fit)
    assert any(w.startswith("refitted at the") for w in res.warnings), res.warnings

