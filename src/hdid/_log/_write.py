""":func:`write_log`: runs to a CSV log that :func:`read_log` reads back."""

from __future__ import annotations

import math
import os
from collections.abc import Sequence

import numpy as np
import pandas as pd

from .._errors import LogError
from ._names import _INERTIA, _LOAD_TORQUE, _MOTOR_TORQUE, _RUN, _SETUP, _THETA, _THETA_OUT, _TIME
from ._types import Log, Run
from ._table import _show


# ----------------------------------------------------------------------- writing


def write_log(
    path: str | os.PathLike[str],
    runs: Sequence[Run] | Log,
    *,
    counts_per_rev: float | None = None,
    overwrite: bool = False,
    output_counts_per_rev: float | None = None,
) -> None:
    """Write runs as a CSV log readable by :func:`read_log`.

    The columns are ``run,setup,time,theta`` plus ``added_inertia`` when any
    run has a nonzero added inertia, and for driven runs ``motor_torque``,
    ``load_torque`` (when any run has one; a run without it gets zeros) and
    ``theta_out`` (when the runs have it). Floats are written with full
    (round-trip) precision.

    Parameters
    ----------
    path : str or os.PathLike
        Output CSV file.
    runs : sequence of Run, or Log
        The runs to write; their names must be distinct.
    counts_per_rev : float, optional
        When given, ``theta`` is written as integer encoder counts,
        ``round(theta / (2*pi/counts_per_rev))`` (this quantizes theta); read the
        file back with the same ``counts_per_rev``.
    overwrite : bool, default False
        Replace an existing file. Otherwise an existing file is an error.
    output_counts_per_rev : float, optional
        Likewise for ``theta_out``: written as integer output encoder counts;
        read back with the same ``output_counts_per_rev``.

    Raises
    ------
    LogError
        If the file exists (and `overwrite` is false), cannot be written, or the
        runs are not writable (no runs, empty or non-finite arrays, repeated or
        empty run names, labels with line breaks, bad `counts_per_rev`, driven
        and free-motion runs mixed, ``theta_out`` in some runs only).
    """
    if isinstance(runs, Log):
        runs = runs.runs
    runs = tuple(runs)
    err = lambda message, **kw: LogError(message, path=path, **kw)  # noqa: E731
    if not runs:
        raise err("no runs to write — pass at least one Run")
    for what, value in (("", counts_per_rev), ("output ", output_counts_per_rev)):
        if value is not None:
            cpr = float(value)
            if not (math.isfinite(cpr) and cpr > 0):
                raise err(f"{what}counts per revolution must be a positive number, got {value!r}")
    seen: set[str] = set()
    for run in runs:
        if not isinstance(run, Run):
            raise TypeError(f"write_log expects Run objects, got {type(run).__name__}")
        label = f"run {_show(run.name)}"
        for text in (run.name, run.setup):
            if text.strip() == "" or text != text.strip() or any(c in text for c in "\r\n"):
                raise err(
                    f"{label}: label {_show(text)} is empty, padded or has a line break — use a "
                    "plain label"
                )
        if run.name in seen:
            raise err(f"{label} is given twice — run names must be distinct")
        seen.add(run.name)
        if run.n_samples == 0:
            raise err(f"{label} has no samples")
        if not (np.all(np.isfinite(run.time)) and np.all(np.isfinite(run.theta))):
            raise err(f"{label} has non-finite time or theta values")
        if not (math.isfinite(run.added_inertia) and run.added_inertia >= 0):
            raise err(f"{label} has an invalid added inertia {run.added_inertia!r}")
        for key in ("motor_torque", "theta_out", "load_torque"):
            value = getattr(run, key)
            if value is not None and not np.all(np.isfinite(value)):
                raise err(f"{label} has non-finite {key} values")
    for key, what in (("motor_torque", "driven and free-motion runs"), ("theta_out", "theta_out")):
        have = [getattr(r, key) is not None for r in runs]
        if any(have) and not all(have):
            lacking = runs[have.index(False)].name
            raise err(
                f"run {_show(lacking)} has no {key} but other runs have — cannot write "
                f"{what} in one log; write them to separate files"
            )

    columns: dict[str, object] = {
        _RUN: np.concatenate([np.full(r.n_samples, r.name, dtype=object) for r in runs]),
        _SETUP: np.concatenate([np.full(r.n_samples, r.setup, dtype=object) for r in runs]),
        _TIME: np.concatenate([r.time for r in runs]),
    }
    theta = np.concatenate([r.theta for r in runs])
    if counts_per_rev is not None:
        columns[_THETA] = np.rint(theta / (2.0 * math.pi / float(counts_per_rev))).astype(np.int64)
    else:
        columns[_THETA] = theta
    if any(r.added_inertia != 0.0 for r in runs):
        columns[_INERTIA] = np.concatenate(
            [np.full(r.n_samples, r.added_inertia, dtype=np.float64) for r in runs]
        )
    if runs[0].motor_torque is not None:
        columns[_MOTOR_TORQUE] = np.concatenate([r.motor_torque for r in runs])
        if any(r.load_torque is not None for r in runs):
            columns[_LOAD_TORQUE] = np.concatenate(
                [np.zeros(r.n_samples) if r.load_torque is None else r.load_torque for r in runs]
            )
        if runs[0].theta_out is not None:
            out = np.concatenate([r.theta_out for r in runs])
            if output_counts_per_rev is not None:
                step = 2.0 * math.pi / float(output_counts_per_rev)
                columns[_THETA_OUT] = np.rint(out / step).astype(np.int64)
            else:
                columns[_THETA_OUT] = out
    text = pd.DataFrame(columns).to_csv(index=False, lineterminator="\n")
    try:
        with open(path, "w" if overwrite else "x", encoding="utf-8", newline="") as fh:
            fh.write(text)
    except FileExistsError:
        raise err("file already exists — choose another name or pass overwrite=True") from None
    except OSError as exc:
        raise err(f"cannot write the file ({exc.strerror or exc}) — check the path") from None
