"""A viscous ring-down's last readings under the noise are motion, a Coulomb stop's are one
rest reading (:func:`hdid._simulation._prepare.search_weight`, :mod:`hdid._simulation._tails`).

The search weights a stuck tail as one observation. A viscously damped ring-down never
sticks: when the log ends while its swing is a few noise σ, its trailing readings lie within
the still threshold (5 σ) of the last one but still trace the decaying oscillation. Weighted
as a stop, the Silverbox's analog ring-downs (4 of 10 runs, 6–30 such samples) let the search
explain the decay as dry friction. Tested here without a fit: on an analytic log (damped
sinusoids plus Gaussian noise printed at fixed decimals, runs of one set-up ending at 1.5 σ
of swing) and on the Silverbox log when ``../shared/data/real`` is present.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from hdid._log import read_log
from hdid._simulation._prepare import FULL_WEIGHT_TAIL, prepare, search_weight

from synthetic import ROOT

SILVERBOX = ROOT.parent / "shared" / "data" / "real" / "silverbox"

FN, ZETA, FS, SIGMA = 40.0, 0.05, 500.0, 1e-4  # Hz, 1, Hz, rad
AMPLITUDES = [0.02, -0.012, 0.016]


def _log(tmp_path, stop_after: float | None = None):
    """Ring-downs ending when the envelope reaches 1.5 σ; with ``stop_after`` [s] one more
    run that stops dead there (a Coulomb stop) and stays 0.4 s at its rest reading."""
    rng = np.random.default_rng(7)
    w = 2 * math.pi * FN
    wd = w * math.sqrt(1 - ZETA**2)
    rows = []
    for r, a in enumerate(AMPLITUDES, start=1):
        t_end = math.log(abs(a) / (1.5 * SIGMA)) / (ZETA * w)
        t = np.arange(0.0, t_end, 1 / FS)
        th = a * np.exp(-ZETA * w * t) * np.cos(wd * t)
        rows += [(r, ti, yi) for ti, yi in zip(t, th + rng.normal(0, SIGMA, t.size))]
    if stop_after is not None:
        t = np.arange(0.0, stop_after + 0.4, 1 / FS)
        th = 0.02 * np.exp(-ZETA * w * t) * np.cos(wd * t)
        k = int(np.argmin(np.abs(t - stop_after)))
        th[k:] = th[k]
        rows += [(len(AMPLITUDES) + 1, ti, yi)
                 for ti, yi in zip(t, th + rng.normal(0, SIGMA, t.size))]
    df = pd.DataFrame(rows, columns=["run", "time", "theta"])
    df["time"] = [f"{v:.6f}" for v in df["time"]]
    df["theta"] = [f"{v:.7f}" for v in df["theta"]]
    path = tmp_path / "ringdowns.csv"
    df.to_csv(path, index=False)
    return prepare(read_log(path))


def _downweighted(prep, w, i):
    n = int(prep.lengths[i])
    return bool(np.any(w[i, :n] < prep.weight[i, :n]))


def test_a_viscous_tail_under_the_noise_keeps_its_weight_a_stop_does_not(tmp_path):
    # (the stop at 0.1 s: a swing of 0.02·e^{-1.26} ≈ 28 σ, so it stops well above the noise)
    prep = _log(tmp_path, stop_after=0.1)
    assert prep.resolution_source == "noise"
    w = search_weight(prep)
    for i in range(len(AMPLITUDES)):
        n, ts = int(prep.lengths[i]), int(prep.tail_start[i])
        # the premise: a tail that the search would weight as a stop (read as at rest,
        # longer than the full-weight samples after the last motion)
        assert not prep.ends_moving[i] and n - ts > FULL_WEIGHT_TAIL + 3, (i, n, ts)
        assert not _downweighted(prep, w, i), i
    # the Coulomb stop: ~200 readings of one rest point, one observation in the search
    # (the oscillation test's false alarm is 1e-3 a run)
    assert _downweighted(prep, w, len(AMPLITUDES))


def test_the_silverbox_tails_are_not_stops():
    log = SILVERBOX / "silverbox_ringdown_moving.csv"
    if not log.exists():
        pytest.skip(f"{log.name} not in {SILVERBOX} (real logs stay outside the repository; "
                    "../shared/data/real/README.md says where they come from)")
    prep = prepare(read_log(log))
    w = search_weight(prep)
    read_as_stopped = [i for i in range(prep.n_runs) if not prep.ends_moving[i]
                       and prep.lengths[i] - prep.tail_start[i] > FULL_WEIGHT_TAIL + 3]
    assert read_as_stopped  # the premise: some runs end in a long still stretch
    assert not any(_downweighted(prep, w, i) for i in read_as_stopped), read_as_stopped
