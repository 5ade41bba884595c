"""The built-in check: simulate logs of a design at the current fit, fit them, compare.

Each simulated log is the design's releases at the fit's parameters, released at a random
instant inside the sample interval after the hold (the fit estimates it), the encoder's
zero at a random sub-count phase (the set-up offset moved by up to half a step), plus the noise
beyond quantization that the fit's residual showed (Gaussian, usually 0), rounded to the
design's encoder step — the log a test engineer would record if the fit were the truth.
Every log is fitted as :func:`hdid.fit` fits (the same model structure and fixed values;
the inertia freed for runs of different added inertia, as its default does). The spread
(sample std) of the fitted values is set beside the predicted std. A sample std of ``N``
Gaussian values has a relative standard error ``≈ 1/√(2(N−1))`` (13 % for N = 30): a
prediction within about twice that of the spread agrees.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from .._errors import HdidError
from . import _stack
from ._candidates import Experiment
from ._fisher import as_log, extra_noise, max_substep, parameter_names, readings


@dataclass
class CheckResult:
    """Empirical spread of ``n_fitted`` fits of simulated logs of ``experiment``."""

    experiment: str
    n_logs: int
    n_fitted: int
    mean: dict[str, float] = field(default_factory=dict)
    spread: dict[str, float] = field(default_factory=dict)
    predicted: dict[str, float] = field(default_factory=dict)
    truth: dict[str, float] = field(default_factory=dict)
    failures: list[str] = field(default_factory=list)
    above_floor: int = 0
    seconds: float = math.nan

    def ratio(self, name: str) -> float:
        """Predicted std over the fits' spread (1: agreement)."""
        s, p = self.spread.get(name, math.nan), self.predicted.get(name, math.nan)
        return p / s if s > 0 and math.isfinite(p) else math.nan

    @property
    def relative_se(self) -> float:
        """Relative standard error of a sample std of ``n_fitted`` Gaussian values."""
        return 1.0 / math.sqrt(2.0 * (self.n_fitted - 1)) if self.n_fitted > 1 else math.inf

    def to_dict(self) -> dict:
        names = list(self.predicted)
        return {
            "experiment": self.experiment, "n_logs": self.n_logs, "n_fitted": self.n_fitted,
            "relative_se_of_spread": self.relative_se, "fits_above_floor": self.above_floor,
            "seconds": self.seconds, "failures": list(self.failures),
            "quantities": {n: {"truth": self.truth.get(n), "mean": self.mean.get(n),
                               "spread": self.spread.get(n), "predicted": self.predicted[n],
                               "predicted_over_spread": self.ratio(n)} for n in names},
        }


def simulate_logs(fit, e: Experiment, n: int, seed: int = 0) -> list:
    """``n`` logs of ``e`` at the fit (random release phase, the fit's extra noise)."""
    rng = np.random.default_rng(seed)
    _, every = parameter_names(fit)
    quantized = bool(fit.resolution_known)
    sigma_x = extra_noise(fit)
    big = Experiment(
        name=e.name, amplitudes=e.amplitudes * n, rate=e.rate, duration=e.duration,
        hold=e.hold, resolution=e.resolution, added_inertia=e.added_inertia * n,
        setups=e.setups * n, offsets=e.offsets,
        releases=tuple(e.hold + rng.uniform(0.0, 1.0, e.n_runs * n) / e.rate))
    st = _stack.stack([(0, big)], fit, every, max_substep(fit))
    theta = _stack.trajectories(st, st.local[None])[0]
    R, m = e.n_runs, e.n_samples
    logs = []
    for k in range(n):
        th = theta[k * R:(k + 1) * R, :m]
        th = th + sigma_x * rng.standard_normal(th.shape) if sigma_x > 0 else th
        # the encoder's sub-count phase at the spring zero differs from test to test: with
        # a fixed one, noise-free readings would round the same way in every log and the
        # spread would miss the quantization error the prediction counts
        shift = {s: e.offsets[s] + e.resolution * rng.uniform(-0.5, 0.5) for s in e.setup_names}
        off = np.array([shift[s] for s in e.setups])
        logs.append(as_log(e, readings(e, th, quantized, off), f"{e.name} #{k + 1}", quantized))
    return logs


def run(fit, e: Experiment, predicted: dict[str, float], n: int, *, seed: int = 0,
        names: tuple[str, ...] = (), progress=None) -> CheckResult:
    """Fit ``n`` simulated logs of ``e``; spread of ``names`` (parameters or derived)."""
    import time

    from .._fitting._fit import fit as fit_log

    if n < 2:
        raise HdidError(f"--check {n}: give at least 2 simulated logs (30 for a 13 % spread estimate)")
    t0 = time.perf_counter()
    logs = simulate_logs(fit, e, n, seed)
    fixed = {k: p.value for k, p in fit.parameters.items() if p.fixed and k != "inertia"}
    inertia = fit.model.float_values().get("inertia")
    opts = dict(model=fit.model, fix=fixed or None)
    if e.free_inertia:
        opts["free_inertia"] = True
    elif inertia is not None:
        opts["inertia"] = inertia
    values: dict[str, list[float]] = {k: [] for k in names}
    out = CheckResult(experiment=e.name, n_logs=n, n_fitted=0)
    floor = e.resolution / math.sqrt(12.0)
    for k, log in enumerate(logs):
        try:
            r = fit_log(log, **opts)
        except (HdidError, ValueError) as exc:
            out.failures.append(f"{log.source}: {exc}".replace("\n", " "))
            continue
        out.n_fitted += 1
        if r.rms_residual_rad > 3.0 * floor:
            out.above_floor += 1
        for name in names:
            if name in r.parameters:
                values[name].append(r.parameters[name].value)
            else:
                values[name].append(r.derived.get(name, (math.nan, 0.0))[0])
        if progress is not None:
            progress(k + 1, n)
    truth = fit.model.float_values()
    for name in names:
        x = np.asarray(values[name], dtype=float)
        x = x[np.isfinite(x)]
        out.mean[name] = float(np.mean(x)) if x.size else math.nan
        out.spread[name] = float(np.std(x, ddof=1)) if x.size > 1 else math.nan
        out.predicted[name] = float(predicted.get(name, math.nan))
        out.truth[name] = truth.get(name, fit.derived.get(name, (math.nan, 0.0))[0])
    out.seconds = time.perf_counter() - t0
    return out
