"""The age of a sample-and-hold reading: a device that samples its encoder every ``P``
seconds and a host that reads the last sample whenever it polls (bus servos)."""

from __future__ import annotations

import math
from typing import Any, ClassVar

import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ._age_scan import expected_floor
from ._candidate import Candidate
from ._reading import AbstractReading


#: ``diagnose`` scans for a clock only where the residual's sample-to-sample part (RMS of
#: residual minus its 5-sample running mean, ×√(5/4)) exceeds this multiple of the rounding
#: floor ``step/√12``: a model that describes the log leaves at most the floor (0.4–1.0×
#: measured on exact models), and the age of a sampled reading lives in that part.
FAST_ABOVE_FLOOR = 2.0


def fast_part(frame) -> float:
    """The residual's sample-to-sample RMS [rad]: each run's residual minus its centred
    5-sample running mean, scaled by √(5/4) (white noise keeps its RMS), weighted."""
    total = weight = 0.0
    for _, d in frame.groupby("run", sort=False):
        r, w = d["residual_rad"].to_numpy(), d["weight"].to_numpy()
        f = r - np.convolve(r, np.ones(5) / 5, "same")
        total, weight = total + float(np.sum(w * f**2)), weight + float(np.sum(w))
    return math.sqrt(1.25 * total / weight) if weight > 0 else 0.0


def _floor_of(frame) -> float:
    """The rounding floor ``step/√12`` [rad] from the frame's residuals in rad and in steps."""
    c = frame["residual_counts"].to_numpy()
    r = frame["residual_rad"].to_numpy()
    ok = np.abs(c) > 0.5
    return float(np.median(r[ok] / c[ok])) / math.sqrt(12.0) if ok.any() else math.nan


class _WithReadings(Candidate):
    """Tried by ``hdid diagnose`` only where a sampling clock can be found: a free-motion
    fit whose residual frame (``hints["frame"]``) the scan of :mod:`._age_scan` explains
    better than the scan's own cost (the variant then holds the scan's period and phases).
    The scan chooses a period and one phase per run: the BIC charges ``ln n`` for each
    (:meth:`penalty`), as for fitted parameters."""

    #: runs whose phase the last scan chose (set by :meth:`variants` on diagnose's own copy
    #: of the candidate, :func:`~hdid.effects._candidate.candidates`)
    runs: int = 0

    def applies(self, model) -> bool:
        return getattr(model, "reading", None) is None and super().applies(model)

    def variants(self, model, values: dict[str, float], hints: dict[str, Any]):
        from ._age_scan import scan

        frame = hints.get("frame")
        if frame is None or "omega" not in frame:
            return []
        floor = _floor_of(frame)
        if not fast_part(frame) > FAST_ABOVE_FLOOR * floor:
            return []  # nothing sample-to-sample for an age to explain
        found = scan(frame, floor=floor)
        if found is None or not found.significant:
            return []
        object.__setattr__(self, "runs", len(found.runs))
        return [(self.key, model.with_effect(ReadingAge.of_scan(found)))]

    def penalty(self, n: float) -> float:
        return (1 + self.runs) * math.log(max(n, 2.0))


class ReadingAge(AbstractReading):
    r"""Sample-and-hold readings: reading ``k`` of run ``r`` is the angle at the device's
    last sample before the host's timestamp ``t_k``,

    ``θ_read,k = θ(t_k − a_k)``, ``a_k = (t_k − φ_r) mod P``  (``0 ≤ a_k < P``),

    ``P`` [s] the device's sampling period (one clock for every run), ``φ_r`` [s, the log's
    time axis] the instant of one of its samples in run ``r`` (each run is a separate
    recording on its own clock origin; ``φ_r`` is kept within a period of the run's moving
    middle). The age is a sawtooth: it grows with the time since the device's last sample
    and drops by ``P`` at each new one. ``P`` and the phases are found by a scan of a fitted
    model's residuals (:meth:`from_fit`, :mod:`hdid.effects._age_scan`) or given, and held
    while the physics is fitted. In Python::

        base = hdid.fit(log, model)
        aged = hdid.fit(log, model.with_effect(ReadingAge.from_fit(base)))

    (``hdid fit LOG --add reading_age`` runs the same two fits.)

    Residual mark when missing: residual/ω (an apparent timing error) is a sawtooth of
    ``P``, or its alias against the host's rate, with a spread of ``P/√12``; it lives in the
    sample-to-sample part of the residual, which no torque (a smooth trajectory) can follow,
    and grows with the speed: a residual of ``ω·P/√12`` rad at speed ω.

    *Request jitter* ``j`` [s] (default 0: the sawtooth above). The host's request reaches
    the device at ``t_k + d_k``, ``d_k`` uniform over a window of width ``j`` (centred: a
    mean delay is a shift of ``φ_r``), so a reading polled within ``j/2`` of a device
    sample shows the newer or the older sample by chance. The model predicts the mean
    instant ``s̄_k = φ_r + P·E⌊(t_k + d_k − φ_r)/P⌋`` in closed form (:func:`hdid.effects._age_scan.expected_floor`):
    the staircase with ramps of width ``j`` at its steps (never after ``t_k`` on average,
    non-decreasing). Residual mark when ``j`` is missing: readings whose age is within
    ``j/2`` of ``0`` or ``P`` jump by ``±ω·P`` (residual/ω off the sawtooth by one period,
    towards the other side), uncorrelated with the host's own interval jitter.
    """

    #: ``P`` [s]: the device's sampling period (each reading is its last sample).
    sample_period: Float[ArrayLike, ""] = float("nan")
    #: ``φ_r`` per run [s, the log's time axis], in the log's run order; ``None``: not yet
    #: found (:meth:`from_fit`).
    phases: Float[ArrayLike, " R"] | None = None
    #: ``j`` [s]: width of the uniform spread of the request's arrival about the timestamp
    #: (0: each reading is exactly the last sample before ``t_k``); chosen by the scan
    #: (:func:`hdid.effects._age_scan.scan` with ``jitters``) and held, as ``P`` is.
    jitter: Float[ArrayLike, ""] = 0.0

    #: No least-squares unknowns: a change of ``P`` or ``φ`` re-sorts which device sample
    #: each reading shows (a jump of ``ω·P`` in that reading), which a local linearisation
    #: sees only as a stretch of the time axis (measured: fitted by Levenberg–Marquardt, P
    #: ran from the scan's value to a poorer one, |r(P, mgl)| = 1.000). Both are chosen by
    #: the scan, a discrete search, and held; ``hdid diagnose`` charges its settings.
    parameters: ClassVar[tuple] = ()
    name: ClassVar[str] = "reading"
    key: ClassVar[str] = "reading_age"
    candidate: ClassVar[Candidate] = _WithReadings(
        trial=5,
        reset_shape=False,
        mark="residual/velocity is a sawtooth in time (the device's sampling period, or its "
             "alias against the host's rate); the residual's sample-to-sample part grows "
             "with the speed",
        experiment="log the device's own sample counter or timestamp with each reading, or "
                   "poll it at a multiple of its sampling period",
    )

    @classmethod
    def start_from(cls, values: dict[str, float]) -> ReadingAge:
        """``--add reading_age``: the period and phases are found from a fit without it
        (``hdid fit --add reading_age`` does both); ``values["sample_period"]`` where given."""
        return cls(sample_period=values.get("sample_period", np.nan), phases=None)

    @classmethod
    def from_fit(cls, result, **scan_options) -> ReadingAge:
        """The component with ``P`` and the per-run phases that best explain ``result``'s
        residuals (a fit of the same log, with or without this component); raises
        ``ValueError`` when the log shows no moving samples to scan."""
        from ._age_scan import scan

        found = scan(result.residuals(), floor=result.quantization_floor_rad,
                     current=result.model.reading, **scan_options)
        if found is None:
            raise ValueError("reading_age: no moving samples with a model velocity to find "
                             "the sampling clock from")
        return cls.of_scan(found)

    @classmethod
    def of_scan(cls, found) -> ReadingAge:
        """The component holding a scan's clock (:class:`~hdid.effects._age_scan.AgeScan`)."""
        return cls(sample_period=float(found.period), phases=np.asarray(found.phases, dtype=float),
                   jitter=float(getattr(found, "jitter", 0.0)))

    def sample_times(self, times: Float[Array, "R T"]) -> Float[Array, "R T"]:
        """``t − a = φ + P·⌊(t − φ)/P⌋``, the device's last sample before ``t``."""
        if self.phases is None:
            from .._errors import HdidError

            raise HdidError("reading_age: its per-run phases are not known; add "
                            "ReadingAge.from_fit(result) of a fit without it, or use "
                            "`hdid fit ... --add reading_age` (which does)")
        times = jnp.asarray(times, dtype=float)
        n = times.shape[0]
        period = jnp.asarray(self.sample_period, dtype=float)
        phases = jnp.asarray(self.phases, dtype=float)
        runs = phases.shape[-1]
        if n % runs:
            raise ValueError(f"reading_age: {runs} phases for a log of {n} runs; find them "
                             "again on this log (ReadingAge.from_fit)")
        rows = jnp.arange(n)
        # a per-run copy of the model (one row per run) holds every run's phases in each row
        phases = phases[rows, rows % runs] if phases.ndim == 2 else phases[rows % runs]
        period = jnp.broadcast_to(period, (n,)) if period.ndim < 2 else period[:, 0]
        jitter = jnp.asarray(self.jitter, dtype=float)
        jitter = jnp.broadcast_to(jitter, (n,)) if jitter.ndim < 2 else jitter[:, 0]
        p, phi = period[:, None], phases[:, None]
        return phi + p * expected_floor((times - phi) / p, jitter[:, None] / p)

