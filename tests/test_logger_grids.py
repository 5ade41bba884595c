"""An encoder's grid and its held readings, as loggers print them.

Each log is drawn here by numpy (a Coulomb-damped ring-down, its exact piecewise
solution, on an encoder grid), never read from a shipped file:

- a fine encoder (2^19 or 2^18 counts a revolution) printed in degrees to 4 decimals,
  7-14 print units a step, sampled at 250-400 Hz: its levels lie tens to thousands of
  steps apart and the closest-gap search left every multiple ambiguous (no step found;
  the noise was estimated instead);
- 0.3 steps of sensor noise ahead of a 14-bit rounding: the held reading flickers one
  count either way before the release, and the reader took the first flicker as the
  direction the run moves off (two runs from one angle "moving both ways": an error).

Each test failed on the reader before this file, except those marked as guards.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hdid import LogError, read_log


def ring(t: np.ndarray, x0: float, w: float, a_c: float) -> np.ndarray:
    """Angle of a linear spring with Coulomb friction released from rest at ``x0`` at
    ``t = 0`` (``w`` its natural angular frequency, ``a_c`` the friction's acceleration):
    each half period a cosine about ``±a_c/w²``, the turn ``2a_c/w²`` closer to it, stuck
    once a turn lies inside that band."""
    x = np.full_like(t, np.nan)
    band, half = a_c / w**2, math.pi / w
    start, xk = 0.0, x0
    while abs(xk) > band:
        centre = math.copysign(band, xk)
        m = (t >= start) & (t < start + half)
        x[m] = centre + (xk - centre) * np.cos(w * (t[m] - start))
        start, xk = start + half, 2.0 * centre - xk
    x[t >= start] = xk
    return x


def world(rng, *, fs: float, cpr: int, f_n: float, amps, dur: float = 0.6,
          noise_steps: float = 0.0, offset: float = 0.0123, friction: float = 0.03):
    """Runs ``(time [s], counts)``: a hold of 3-11 samples, a release between samples,
    the ring-down on a ``cpr`` grid (Gaussian noise of ``noise_steps`` steps ahead of the
    rounding). Each half period loses ``2·friction`` of the release angle."""
    w, q = 2.0 * math.pi * f_n, 2.0 * math.pi / cpr
    runs = []
    for x0 in amps:
        t = np.arange(int(dur * fs)) / fs
        release = (int(rng.integers(3, 12)) + rng.uniform()) / fs
        a_c = friction * w**2 * abs(x0)
        angle = np.where(t < release, x0, ring(np.maximum(t - release, 0.0), x0, w, a_c))
        angle = angle + offset + rng.normal(0.0, noise_steps * q, t.size)
        runs.append((t, np.round(angle / q).astype(np.int64)))
    return runs


def _write(path, runs, cell) -> None:
    path.write_text("run;time [us];theta [deg]\n" + "".join(
        f"{k};{round(s * 1e6)};{cell(c)}\n" for k, (t, counts) in enumerate(runs, 1)
        for s, c in zip(t, counts)))


@pytest.mark.parametrize("cpr, fs, f_n", [(2**19, 250.0, 22.8), (2**18, 400.0, 86.3)])
def test_a_fine_encoder_printed_a_few_print_units_a_step(tmp_path, cpr, fs, f_n):
    """The step, 360/2^19 = 0.00069° (6.9 print units of 0.0001°) or 0.0014° (13.7), is
    found in each of 8 heavily damped logs (a few turns, then stuck: levels tens to
    thousands of steps apart): every level's multiple resolved by bisection, one offset
    per run. Before: about half gave no step ('do not tell it from chance')."""
    q = 2 * math.pi / cpr
    for seed in range(8):
        rng = np.random.default_rng(seed)
        runs = world(rng, fs=fs, cpr=cpr, f_n=f_n, amps=(0.145, -0.145, 0.12), friction=0.2)
        path = tmp_path / f"fine{seed}.csv"
        _write(path, runs, lambda c: f"{c * 360.0 / cpr:.4f}")
        log = read_log(path)
        # the levels span ~10^3-10^4 steps and each lies within half a print unit (q/14)
        # of the grid, so the step is pinned to ~1e-4 q or better
        assert log.resolution == pytest.approx(q, rel=1e-4), seed
        assert log.resolution_source == "estimated"


def test_guard_analog_readings_printed_the_same_way_get_no_grid(tmp_path):
    """Guard (passes on the old reader too): the same swings, analog (no grid), printed
    to 0.0001°: no step is told."""
    rng = np.random.default_rng(7)
    runs = world(rng, fs=250.0, cpr=2**40, f_n=22.8, amps=(0.145, -0.145, 0.12), friction=0.2)
    path = tmp_path / "analog.csv"
    _write(path, runs, lambda c: f"{c * 360.0 / 2**40:.4f}")
    assert read_log(path).resolution is None




def test_held_readings_flickering_with_noise_before_opposite_releases(tmp_path):
    """Four runs of one set-up, released from +0.157 and -0.157 rad alternately, 0.3
    steps of noise ahead of a 14-bit rounding: the held level flickers one count either
    way, so the first reading off it points either way. Runs 1 and 3 share their held
    count; they swing the same way (down). Before: 'move off it in opposite directions'."""
    rng = np.random.default_rng(23)
    runs = world(rng, fs=1000.0, cpr=16384, f_n=60.0, amps=(0.157, -0.157, 0.157, -0.157),
                 dur=0.5, noise_steps=0.32)
    # the same held count in runs 1 and 3, the first flicker up in one, down in the other
    held = int(np.median(runs[0][1][:3]))
    for k, flicker in ((0, 1), (2, -1)):
        c = runs[k][1]
        c[:2], c[2] = held, held + flicker
    path = tmp_path / "noisy_holds.csv"
    path.write_text("run,setup,time [ms],theta\n" + "".join(
        f"{k},A,{s * 1e3:.3f},{v}\n" for k, (t, c) in enumerate(runs, 1) for s, v in zip(t, c)))
    log = read_log(path, counts_per_rev=16384)
    assert [r.n_samples for r in log.runs] == [500] * 4


def test_a_counter_zeroed_at_each_release_is_refused_under_noise_too(tmp_path):
    """Each run's counter zeroed at its hold (every run starts at 0), one swinging up,
    one down, with the same noise: the first two readings of a run differ (a flicker),
    which hid the hold before; the reading 3 of the first 5 show is the hold. The
    one-line error naming both runs (before: read, one offset for two zeros)."""
    rng = np.random.default_rng(5)
    runs = world(rng, fs=1000.0, cpr=16384, f_n=60.0, amps=(0.157, -0.157), dur=0.5,
                 noise_steps=0.32, offset=0.0)
    for k, (t, c) in enumerate(runs):
        c -= int(np.median(c[:3]))  # zeroed at its hold
        c[:4] = (0, 1 - 2 * k, 0, 0)  # the first two readings differ: a flicker
    path = tmp_path / "zeroed.csv"
    path.write_text("run,time,theta\n" + "".join(
        f"{k},{s:.6f},{v}\n" for k, (t, c) in enumerate(runs, 1) for s, v in zip(t, c)))
    with pytest.raises(LogError, match="opposite directions"):
        read_log(path, counts_per_rev=16384)
