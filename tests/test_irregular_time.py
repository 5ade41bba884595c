"""Irregular sample times are data (issue 33, "What to build" 6; "Must show": controller
timestamps).

A controller or servo log is not sampled on a grid: its steps jitter (10 ms ± 20 %), it
drops a sample now and then (12 ms steps at 10 ms), and a late cycle leaves one short step
(2 ms). The model is evaluated at the logged times (the simulator integrates each logged
interval in substeps of at most ``max_substep``); only a break (a step over five of the
run's median steps, ``hdid._log._validate.BREAK_PERIODS``) splits a run, and a note says
so (``tests/test_io.py``).

The twin logs come from the independent generator (``tests/independent.py``: solve_ivp
with an exact stick rule, evaluated at whatever times it is asked): the paper's design on
a gear slow enough for 100 Hz (``csf32_flywheel``, 7.0 Hz, 14 samples per swing), once at
the jittered times and once on the uniform 10 ms grid.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import hdid
import independent as ind
from hdid._problems._driven_problem import DrivenData, local_cubic

PLANT = ind.gear_plant("csf32_flywheel")
A = 0.157
RELEASES = [A, -A, A, -A]
SETUPS = ["A", "A", "B", "B"]
OFFSETS = {"A": 0.012, "B": -0.020}
PERIOD = 0.01
UR10E = Path(__file__).resolve().parents[2] / "shared" / "data" / "real" / "ur10e_hd"


def _times(kind: str, run: int, n: int, rng) -> np.ndarray:
    if kind == "uniform":
        steps = np.full(n, PERIOD)
    else:  # 10 ms ± 20 %, a tenth of the steps 12 ms (a dropped beat), one 2 ms step
        steps = PERIOD * rng.uniform(0.8, 1.2, n)
        steps[rng.choice(n, n // 10, replace=False)] = 1.2 * PERIOD
        if run == 1:
            steps[40] = 0.2 * PERIOD
    return np.concatenate([[0.0], np.cumsum(steps)])


def twin(kind: str, duration: float = 3.0, seed: int = 7) -> pd.DataFrame:
    """The paper's four releases, 4 samples of hold, readings with no noise and no
    rounding (analog and noise-free: see the test's reasoning)."""
    rng = np.random.default_rng(seed)
    frames = []
    for r, theta0 in enumerate(RELEASES):
        t = _times(kind, r, int(duration / PERIOD) + 5, rng)
        t_rel = t[4] + (0.19 + 0.2 * r) * (t[5] - t[4])  # each at its own phase
        theta, _ = ind.trajectory(PLANT, theta0, t[-1] - t_rel + PERIOD)(t - t_rel)
        frames.append(pd.DataFrame({"run": str(r + 1), "setup": SETUPS[r], "time": t,
                                    "theta": theta + OFFSETS[SETUPS[r]]}))
    return pd.concat(frames, ignore_index=True)


@pytest.fixture(scope="module")
def twin_fits():
    return {kind: hdid.fit(twin(kind), ratio=PLANT.ratio, inertia=PLANT.inertia)
            for kind in ("uniform", "jittered")}


def test_jittered_log_is_read_whole():
    df = twin("jittered")
    steps = np.diff(df[df.run == "2"]["time"])
    assert steps.min() == pytest.approx(0.002) and steps.max() == pytest.approx(0.012)
    log = hdid.read_log(df)
    assert [r.n_samples for r in log.runs] == [306] * 4 and log.notes == ()
    assert 0.0095 < log.sample_period < 0.0105  # the median step, a scale


def test_jittered_log_gives_the_physics_of_its_uniform_twin(twin_fits):
    """Same physics within 0.2 σ.

    Why noise-free analog readings: two logs of one plant at different sample times do
    not share their reading errors (an encoder's rounding error at other times is, for
    the fit, another noise realisation), so two rounded or noisy twins differ by about
    √2 σ, and no bound of 0.2 σ could hold. Without rounding or noise the two fits differ
    only by what sampling at other times does to the model's evaluation — exactly what is
    tested: a uniform-period assumption anywhere (integration, release bracket, weights,
    speeds) moves them by many σ. Their σ is then hdid's noise floor for readings on no
    grid (10⁻⁴ of the swing, the simulator's accuracy), a lower bound, so 0.2 σ is
    strict. Measured: at most 0.03 σ between the twins, 0.15 σ from the truth.
    """
    u, j = twin_fits["uniform"], twin_fits["jittered"]
    assert not any("split" in w or "break" in w for w in j.warnings), j.warnings
    for name, pu in u.parameters.items():
        if pu.std == 0.0:  # fixed (inertia)
            continue
        pj = j.parameters[name]
        assert abs(pj.value - pu.value) <= 0.2 * pu.std, (name, pj.value, pu.value, pu.std)
    # and both are the plant: within 1 σ of the truth (measured ≤ 0.15 σ; 1 σ because
    # the analog floor's σ is a lower bound, so this is not a statistical test)
    truth = PLANT.params()
    for name in ("k1", "tau_c", "c_v"):
        p = j.parameters[name]
        assert abs(p.value - truth[name]) <= p.std, (name, p.value, truth[name], p.std)


def test_local_cubic_differentiates_at_the_logged_times():
    """The starting speeds of driven windows and the noise scale: a cubic sampled at
    jittered times is differentiated exactly (a uniform-period formula is off by the
    jitter, ~20 % here)."""
    rng = np.random.default_rng(3)
    t = np.cumsum(PERIOD * rng.uniform(0.8, 1.2, 60))
    y = 0.3 - 2.0 * t + 5.0 * t**2 - 4.0 * t**3
    value, slope = local_cubic(t, y, 7)
    np.testing.assert_allclose(value, y, rtol=0, atol=1e-12)
    np.testing.assert_allclose(slope, -2.0 + 10.0 * t - 12.0 * t**2, rtol=0, atol=1e-9)


@pytest.mark.parametrize("joint", [1, 2, 3, 4])
def test_ur10e_controller_logs_are_read(joint):
    """UR10e controller logs (10 ms with 12 ms steps, one 2 ms step in joint 2) are read
    whole, not refused, and cut into windows at their logged times."""
    path = UR10E / f"ur10e_joint{joint}.csv"
    if not path.exists():
        pytest.skip(f"{path.name} not in {UR10E} (real logs stay outside the repository)")
    log = hdid.read_log(path)
    raw = pd.read_csv(path)
    assert len(log.runs) == 1 and log.runs[0].n_samples == len(raw) and log.notes == ()
    assert log.sample_period == pytest.approx(0.01, rel=1e-6)
    data = DrivenData.from_log(log)
    logged = np.concatenate([data.times[w, : int(np.sum(data.weight[w] > 0))]
                             for w in range(data.n_runs)])
    np.testing.assert_array_equal(logged, log.runs[0].time)
    assert np.all(np.isfinite(data.omega0)) and data.step > 0
