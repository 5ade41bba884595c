"""Synthetic free-motion logs from hdid's own simulator (``hdid simulate``)."""

from __future__ import annotations

import math

import numpy as np

from .._log import Run, write_log
from .._models._model import Model
from ._simulate import simulate


def synthesize(
    path,
    *,
    amplitudes,
    rate: float = 250.0,
    duration: float = 0.5,
    hold: float = 0.04,
    offset: float = 0.0,
    counts_per_rev: int | None = 4000,
    noise: float = 0.0,
    seed: int = 0,
    values: dict | None = None,
    model: Model | None = None,
    as_counts: bool = False,
    overwrite: bool = False,
):
    """Simulate one run per release amplitude and write them as a log.

    Each run holds still for ``hold`` seconds, is released at a random instant inside
    the next sample interval, and is read by an encoder of ``counts_per_rev`` counts per
    revolution (``None``: no quantization) after adding Gaussian ``noise`` [rad].
    """
    if not amplitudes:
        raise ValueError("amplitudes: give at least one release angle, e.g. 0.157,-0.157")
    model = Model.default() if model is None else model
    if values:
        model = model.replace(**values)
    rng = np.random.default_rng(seed)
    n = int(round(duration * rate))
    t = np.arange(n) / rate
    step = 2 * math.pi / counts_per_rev if counts_per_rev else None
    runs = []
    # a reading component (e.g. reading_age): each run read at the instants its device sampled
    t_read = (np.asarray(model.reading.sample_times(np.tile(t, (len(amplitudes), 1))))
              if model.reading is not None else np.tile(t, (len(amplitudes), 1)))
    for i, a in enumerate(amplitudes):
        t_r = hold + rng.uniform(0.0, 1.0) / rate
        theta = np.asarray(simulate(model, t_read[i], a, t_r, max_substep=min(2.5e-4, 0.25 / rate)))
        enc = theta + offset + rng.normal(0.0, noise, size=n) * (noise > 0)
        if step:
            enc = np.round(enc / step) * step
        runs.append(Run(name=str(i + 1), time=t, theta=enc, setup="1"))
    write_log(path, runs, counts_per_rev=counts_per_rev if as_counts else None, overwrite=overwrite)
    return runs
