"""Pendulum drops as a bench logs them (issue 33, "Pendulum drops"): the gravity spring's
starts come from the log — the swing frequency gives m·g·l/I, the rest angle the zero.

The physics is simulated by ``tests/independent.py`` (event-driven scipy ``solve_ivp``,
no hdid code): a pendulum on a servo's output, ``I·θ̈ = −mgl·sin θ − τ_c·s − c_v·θ̇``,
stuck for good at a zero of the speed where ``|mgl·sin θ| ≤ τ_c``. What this file adds is
the log as a bench writes it, none of which hdid's own simulator assumes:

- the servo lifts the arm to the release angle and holds it there, its reading flickering
  by a count, before the torque is cut at an instant inside a sample interval;
- a 4096-count encoder on the output with its zero anywhere (not at the hanging angle);
- readings printed with fixed decimals;
- raw timestamps that jitter by ±30 % of the period, or BAM's resampling of them onto a
  uniform grid by linear interpolation (readings then lie on no encoder grid).

Swings of 0.3, 1 and 3 Hz. The cheap tests check the log-derived starts on every variant
(the release, the zero, m·g·l/I); the fits (one per scenario, few) check that the fit
then recovers m·g·l and releases every run.
"""

from __future__ import annotations

import io
import math

import numpy as np
import pandas as pd
import pytest

import hdid
import independent as ind
from hdid._fitting._pendulum import read_swings
from hdid.effects import library

COUNTS = 4096
STEP = 2 * math.pi / COUNTS
INERTIA = 0.01  # kg m² at the output
#: Friction: Coulomb 4 % of m·g·l (a stick band of ±0.04 rad), viscous 3 % of critical.
COULOMB_FRACTION, ZETA = 0.04, 0.03
RELEASES = (-0.9, -0.55, 0.7)  # rad from the hanging position


def plant(frequency_hz: float) -> ind.Plant:
    mgl = INERTIA * (2 * math.pi * frequency_hz) ** 2
    return ind.Plant(inertia=INERTIA, ratio=1.0, mgl=mgl, tau_c=COULOMB_FRACTION * mgl,
                     c_v=ZETA * 2 * math.sqrt(mgl * INERTIA))


def bench_log(frequency_hz: float, *, rate: float, jitter: float = 0.0,
              resample: bool = False, decimals: int = 6, seed: int = 0):
    """``(csv text, truth)``: one run per release in ``RELEASES``.

    Each run: 0.2 s of the servo lifting the arm from 0.3 rad short of the release angle,
    0.3 s of hold with ±1-count flicker, the release at a random instant, the free swing
    until it sticks and 1 s more. ``jitter``: raw time steps ``dt·(1 ± jitter)``;
    ``resample``: those readings linearly interpolated onto the uniform grid (as BAM does).
    """
    rng = np.random.default_rng(seed)
    p = plant(frequency_hz)
    zero = rng.uniform(-math.pi, math.pi)  # the encoder's zero is anywhere
    dt = 1.0 / rate
    rows, runs = [], []
    for r, theta0 in enumerate(RELEASES):
        traj = ind.trajectory(p, theta0, 200.0 / frequency_hz)
        assert traj.stuck_at is not None
        t_rel = 0.5 + rng.uniform(0.0, dt)
        t_end = t_rel + traj.stuck_at[0] + 1.0
        n = int(t_end / dt) + 1
        steps = dt * (1.0 + jitter * rng.uniform(-1.0, 1.0, n - 1))
        t = np.concatenate([[0.0], np.cumsum(steps)])
        theta, _ = traj(t - t_rel)
        lift = t < 0.2
        theta[lift] = theta0 - 0.3 * np.sign(theta0) * (0.5 + 0.5 * np.cos(np.pi * t[lift] / 0.2))
        held = (t >= 0.2) & (t < t_rel)
        reading = np.round((theta + zero) / STEP) * STEP
        flicker = rng.integers(-1, 2, held.sum()) * (rng.uniform(size=held.sum()) < 0.2)
        reading[held] += STEP * flicker
        if resample:
            grid = np.arange(0.0, t[-1], dt)
            reading, t = np.interp(grid, t, reading), grid
        rows.append(pd.DataFrame({"time": t, "theta": reading, "run": f"r{r}"}))
        runs.append({"theta0": theta0, "t_release": t_rel, "rest": traj.rest + zero,
                     "periods": traj.stuck_at[0] * frequency_hz})
    buf = io.StringIO()
    pd.concat(rows).to_csv(buf, index=False, float_format=f"%.{decimals}f")
    truth = {"mgl": p.mgl, "zero": zero, "runs": runs, "plant": p}
    return buf.getvalue(), truth


def _runs(text: str):
    df = pd.read_csv(io.StringIO(text))
    return [(g.time.to_numpy(), g.theta.to_numpy()) for _, g in df.groupby("run", sort=False)]


#: (frequency [Hz], rate [Hz]): a 0.3 Hz swing logged at 50 Hz (~170 samples per period),
#: 1 Hz at 100 Hz, 3 Hz at 200 Hz (~67 samples per period).
CASES = [(0.3, 50.0), (1.0, 100.0), (3.0, 200.0)]
VARIANTS = {"uniform": {}, "jittered": {"jitter": 0.3},
            "resampled": {"jitter": 0.3, "resample": True}}


@pytest.mark.parametrize("variant", list(VARIANTS))
@pytest.mark.parametrize("frequency_hz, rate", CASES)
def test_swings_give_release_zero_and_mgl(frequency_hz, rate, variant):
    text, truth = bench_log(frequency_hz, rate=rate, seed=int(10 * frequency_hz),
                            **VARIANTS[variant])
    runs = _runs(text)
    # the flicker of a still reading: one count plus 3 σ of quantization (as hdid has it)
    still = STEP * (1 + 3 / math.sqrt(12))
    sw = read_swings(runs, np.zeros(len(runs), int), 1.0, still)
    assert sw is not None
    p = truth["plant"]
    for (t, _), r, tr in zip(runs, sw.runs, truth["runs"]):
        # the release reading is the hold's (within the flicker), and its last sample lies
        # before the true release by at most one interval (+30 % jitter; a second one
        # when resampled: the interpolation starts the first move one raw interval
        # early), or after it by the time the arm takes to leave the flicker from rest,
        # ½·α·τ² = flicker, α the angular acceleration at release (gravity less friction)
        assert abs(r.hold - (tr["theta0"] + truth["zero"])) <= 2 * STEP
        alpha = (p.mgl * math.sin(abs(tr["theta0"])) - p.tau_c) / p.inertia
        late = math.sqrt(2 * still / alpha)
        early = (2.6 if VARIANTS[variant].get("resample") else 1.3) / rate
        assert -early <= t[r.release] - tr["t_release"] <= late + 1.3 / rate
    # the zero: the energy balance of the half-swings of both directions; its error is set
    # by the turning points' reading (one count) relative to the friction's decrement per
    # half-swing, 2·r = 0.08 rad: a few counts
    assert abs(sw.zero[0] - truth["zero"]) <= 4 * STEP
    # r = τ/mgl of the half-swings: Coulomb's 0.04 plus the viscous loss (ζ = 0.03 takes
    # ~π·ζ·A/2 ≈ 0.02–0.04 of amplitude per half-swing at A = 0.3–0.9 rad): 0.04–0.07
    assert COULOMB_FRACTION <= sw.friction_ratio <= COULOMB_FRACTION + 2 * math.pi * ZETA * 0.9 / 2
    # m·g·l = I·ω₀²: each half-swing's duration between turning points, corrected for its
    # amplitude; the viscous term lengthens it by 1/sqrt(1 − ζ²) (0.05 %), a turning
    # point's time is known to a fraction of a sample (a parabola through the top tenth
    # of the swing): 2 % on m·g·l is 1 % on ω₀, one sample in 100 per period
    mgl = INERTIA * sw.omega0**2
    assert abs(mgl / truth["mgl"] - 1) <= 0.02, (mgl, truth["mgl"])


# -- the fits: one per scenario, three in all ----------------------------------------------

#: (frequency [Hz], rate [Hz], variant): the slowest swing on raw jittered timestamps, the
#: middle one resampled as BAM does (readings on no grid), the fastest on a uniform clock.
FITS = [(0.3, 50.0, "jittered"), (1.0, 100.0, "resampled"), (3.0, 200.0, "uniform")]


def pendulum_model() -> hdid.Model:
    """``--ratio 1 --remove stiffness --add gravity --add coulomb --inertia I``: the
    simulated friction is Coulomb + viscous, so the fit's model can be exact."""
    effects = library({})
    return (hdid.Model.default(inertia=INERTIA, ratio=1.0).without("stiffness")
            .with_effect(effects["gravity"]).with_effect(effects["coulomb"]))


@pytest.mark.parametrize("frequency_hz, rate, variant", FITS)
def test_fit_recovers_mgl_and_releases_every_run(tmp_path, frequency_hz, rate, variant):
    text, truth = bench_log(frequency_hz, rate=rate, seed=7, **VARIANTS[variant])
    path = tmp_path / f"drop_{variant}.csv"
    path.write_text(text)
    result = hdid.fit(path, pendulum_model())
    out = result.to_dict()
    # every run released: the model moves, and rests where the log does — within two
    # encoder steps (the reading's own rounding, plus one of the zero's)
    for run in out["runs"]:
        assert run["peak_speed"] > 0, (run["name"], result.warnings)
        assert abs(run["rest_model"] - run["rest_logged"]) <= 2 * STEP, run
    assert not [w for w in result.warnings if "never releases" in w]
    # m·g·l: a relative error ε shifts the phase by π·ε·k after k periods; with the
    # amplitude decaying about linearly from A₀ to 0 over K periods, the largest position
    # error is π·ε·A₀·K/4. A fit that tracks the swings to the readings' floor cannot hide
    # more than a few floors of it; the tolerance allows four (the release instants, the
    # friction and the zero absorb part of a phase error): ε ≤ 16·floor/(π·A₀·K), 0.2–0.4 %
    # here. The floor is one encoder step, plus, for readings resampled by linear
    # interpolation, the chord's error at a peak, A₀·(ω·h)²/8 over a raw interval h ≤ 1.3·dt
    K = max(r["periods"] for r in truth["runs"])
    A0 = max(abs(r["theta0"]) for r in truth["runs"])
    floor = STEP
    if VARIANTS[variant].get("resample"):
        floor += A0 * (2 * math.pi * frequency_hz * 1.3 / rate) ** 2 / 8
    est = result.parameters["mgl"]
    tol = max(16 * floor / (math.pi * A0 * K), 4 * est.std / truth["mgl"])
    print(f"{variant} {frequency_hz} Hz: mgl {est.value:.6g} truth {truth['mgl']:.6g} "
          f"error {est.value / truth['mgl'] - 1:+.2e} tolerance {tol:.2e}")
    assert abs(est.value / truth["mgl"] - 1) <= tol, (est, truth["mgl"], tol)
