"""The validated log: :class:`Run` (one release) and :class:`Log` (all of them)."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


# --------------------------------------------------------------------------- data


def _frozen_float_array(values, name: str) -> np.ndarray:
    arr = np.array(values, dtype=np.float64, copy=True)
    if arr.ndim != 1:
        raise ValueError(f"Run.{name} must be one-dimensional, got shape {arr.shape}")
    arr.setflags(write=False)
    return arr


@dataclass(frozen=True, eq=False)
class Run:
    """One release of the drive: a contiguous block of samples of a log.

    Parameters
    ----------
    name : str
        Run label (the ``run`` column value as text; ``"1"`` if the log has no
        ``run`` column).
    time : numpy.ndarray
        Sample times [s], float64, strictly increasing, as in the file.
    theta : numpy.ndarray
        Wave-generator (motor) angle [rad], float64, converted from encoder
        counts if the log held counts.
    setup : str, default "1"
        Set-up label (the ``setup`` column; ``"1"`` if absent).
    added_inertia : float, default 0.0
        Inertia added for this run [kg m^2] (the ``added_inertia`` column).
    first_row : int, default 0
        CSV line number of the run's first sample (header is line 1); 0 when the
        run was not read from a file.
    motor_torque : numpy.ndarray or None, default None
        Driven runs: motor torque at the wave generator [N m] per sample, held
        from each sample to the next (zero-order hold). ``None`` for a
        free-motion run.
    theta_out : numpy.ndarray or None, default None
        Driven runs: output angle [rad, output encoder's frame], or ``None``.
    load_torque : numpy.ndarray or None, default None
        Driven runs: external torque on the output [N m, output side], linear
        between samples; ``None`` means zero load.

    Notes
    -----
    The arrays are copied to read-only float64 arrays. ``theta_out`` and
    ``load_torque`` need ``motor_torque`` (``ValueError`` otherwise). Runs compare by
    identity (``eq=False``) because element-wise array equality has no single
    truth value.
    """

    name: str
    time: np.ndarray
    theta: np.ndarray
    setup: str = "1"
    added_inertia: float = 0.0
    first_row: int = 0
    motor_torque: np.ndarray | None = None
    theta_out: np.ndarray | None = None
    load_torque: np.ndarray | None = None

    def __post_init__(self) -> None:
        time = _frozen_float_array(self.time, "time")
        theta = _frozen_float_array(self.theta, "theta")
        if time.shape != theta.shape:
            raise ValueError(
                f"Run {self.name!r}: time has {time.size} samples but theta has {theta.size}"
            )
        for key in ("motor_torque", "theta_out", "load_torque"):
            value = getattr(self, key)
            if value is None:
                continue
            arr = _frozen_float_array(value, key)
            if arr.shape != time.shape:
                raise ValueError(
                    f"Run {self.name!r}: time has {time.size} samples but {key} has {arr.size}"
                )
            if key != "motor_torque" and self.motor_torque is None:
                raise ValueError(
                    f"Run {self.name!r}: {key} is given without motor_torque — a driven run "
                    "needs the motor torque"
                )
            object.__setattr__(self, key, arr)
        object.__setattr__(self, "name", str(self.name))
        object.__setattr__(self, "setup", str(self.setup))
        object.__setattr__(self, "added_inertia", float(self.added_inertia))
        object.__setattr__(self, "first_row", int(self.first_row))
        object.__setattr__(self, "time", time)
        object.__setattr__(self, "theta", theta)

    @property
    def n_samples(self) -> int:
        """Number of samples in the run."""
        return int(self.time.size)

    @property
    def is_driven(self) -> bool:
        """Whether the run has a motor torque (a driven run, paper eqs. 8–9)."""
        return self.motor_torque is not None


@dataclass(frozen=True)
class Log:
    """A validated log: one or more runs, sampled at the logged times.

    Parameters
    ----------
    source : str
        The path as given to :func:`read_log`, or ``"<DataFrame>"``.
    runs : tuple of Run
        The runs, in order of first appearance in the file.
    sample_period : float
        The log's sample period [s]: median of the time steps over all runs (a scale;
        the steps themselves may vary, and the model is evaluated at the logged times).
    resolution : float or None
        Encoder step [rad]: ``2*pi/counts_per_rev`` when that was given, else
        estimated from the data by :func:`estimate_resolution`; ``None`` if the
        data do not look quantized.
    counts_per_rev : float or None
        Encoder counts per revolution if the log held raw counts.
    output_resolution : float or None
        Output encoder step [rad]: ``2*pi/output_counts_per_rev`` when that was
        given, else estimated from ``theta_out`` like ``resolution``; ``None``
        without ``theta_out`` or when it does not look quantized.
    output_counts_per_rev : float or None
        Output encoder counts per revolution if the log held raw output counts.
    torque_constant : float or None
        Motor torque constant [N m/A] if the log held ``motor_current``.
    resolution_source : str or None
        ``"given"`` (``resolution=`` or ``counts_per_rev``), ``"estimated"`` (from the
        readings' grid) or ``None`` (no resolution: readings on no grid).
    notes : tuple of str
        What reading did to the log that the report must say, one line each: runs split
        at a break in their time column, one-sample read dropouts dropped (a bus servo's
        −π; :mod:`hdid._log._dropouts`), readings off the encoder grid that all others lie
        on (kept; :mod:`hdid._log._grid_outliers`), runs that never move (kept as rest
        points).
    print_unit : float or None
        Printing precision of ``theta`` [rad]: the largest rounding unit of its cells as the
        file prints them (``1e-4`` for four decimals); ``None`` for numbers never printed.
    resolution_note : str or None
        Why no encoder step was found in the readings (``resolution`` is ``None``), or
        ``None``.
    time_print_unit : float or None
        Printing precision of the time column [s]: the largest rounding unit of its cells as
        the file prints them (``1e-6`` for whole microseconds or seconds to 6 decimals);
        ``None`` for numbers never printed, date-times, or times rebuilt as uniform steps
        (a note says so). A stamp is the sample's instant cut to this unit, an error of up
        to one unit: ``ω·u/√12`` rad on a reading where the angle moves at ``ω`` rad/s
        (rounded to the unit; truncated, a bias of ``u/2`` besides).
    first_reading_held : tuple of str
        Runs whose readings move from their second sample on but whose first reading is
        the hold (a logger that starts at the servo-off, the release falling in the first
        interval): set by :func:`hdid.fit` when that fits the log better than a run
        already moving at its first sample (:mod:`hdid._fitting._first_reading`).

    Raises
    ------
    ValueError
        If some runs are driven and others not.
    """

    source: str
    runs: tuple[Run, ...]
    sample_period: float
    resolution: float | None
    counts_per_rev: float | None = None
    output_resolution: float | None = None
    output_counts_per_rev: float | None = None
    torque_constant: float | None = None
    resolution_source: str | None = None
    notes: tuple[str, ...] = ()
    print_unit: float | None = None
    resolution_note: str | None = None
    first_reading_held: tuple[str, ...] = ()
    time_print_unit: float | None = None

    def __post_init__(self) -> None:
        object.__setattr__(self, "runs", tuple(self.runs))
        object.__setattr__(self, "notes", tuple(str(n) for n in self.notes))
        object.__setattr__(self, "first_reading_held", tuple(self.first_reading_held))
        kinds = {run.is_driven for run in self.runs}
        if len(kinds) > 1:
            free = next(run.name for run in self.runs if not run.is_driven)
            driven = next(run.name for run in self.runs if run.is_driven)
            raise ValueError(
                f"run {free!r} is free-motion but run {driven!r} is driven — a log must be "
                "all driven or all free-motion"
            )

    @property
    def is_driven(self) -> bool:
        """Whether every run has a motor torque (a driven log); False for no runs."""
        return bool(self.runs) and all(run.is_driven for run in self.runs)

    @property
    def setups(self) -> tuple[str, ...]:
        """Unique set-up labels, in order of appearance."""
        return tuple(dict.fromkeys(run.setup for run in self.runs))

    @property
    def n_samples(self) -> int:
        """Total number of samples over all runs."""
        return sum(run.n_samples for run in self.runs)
