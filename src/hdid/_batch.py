"""Batch identification of many logs: one row per log, bad files reported in their row."""

from __future__ import annotations

import os
from collections.abc import Iterable
from typing import Any

from ._errors import HdidError


def fit_many(logs: Iterable[Any], *, progress: bool = False, **options):
    """Fit every log and tabulate the results.

    Parameters
    ----------
    logs:
        CSV paths, pandas DataFrames or :class:`~hdid.Log` objects.
    progress:
        Show a progress bar (tqdm).
    **options:
        Passed to :func:`hdid.fit` (``inertia``, ``fix``, ``counts_per_rev``, …).

    Returns
    -------
    pandas.DataFrame
        One row per log, in input order: ``log``, ``error`` (``None`` when the fit worked),
        every parameter and its ``<name>_std``, ``stick_band_halfwidth_rad`` (± std and the
        data bracket), ``rms_residual_rad``, ``n_warnings``, ``warnings`` and ``result``
        (the :class:`~hdid.FitResult`, for everything else).

    Notes
    -----
    Logs of the same shape (runs × samples) reuse one compiled fit, so a production
    line's logs cost one compile. The fits run one after another (see the issue notes on
    vectorising across logs).
    """
    import pandas as pd

    from ._fit import fit

    items = list(logs)
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(items), unit="log")
    rows = []
    for i, item in enumerate(items):
        name = os.fspath(item) if isinstance(item, (str, os.PathLike)) else f"<log {i}>"
        row: dict[str, Any] = {"log": name, "error": None}
        try:
            res = fit(item, **options)
        except (HdidError, ValueError, KeyError) as exc:
            msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
            row["error"] = str(msg).replace("\n", " ")
            row["result"] = None
        else:
            for n, p in res.parameters.items():
                row[n] = p.value
                row[f"{n}_std"] = None if p.fixed else p.std
            hw, hw_std = res.derived["stick_band_halfwidth_rad"]
            row["stick_band_halfwidth_rad"] = hw
            row["stick_band_halfwidth_std_rad"] = hw_std
            lo, hi = res.band_bracket if res.band_bracket else (None, None)
            row["stick_band_bracket_lo_rad"], row["stick_band_bracket_hi_rad"] = lo, hi
            row["k1/inertia"] = res.derived["k1/inertia"][0] if "k1/inertia" in res.derived else None
            row["rms_residual_rad"] = res.rms_residual_rad
            row["rms_residual_counts"] = res.rms_residual_rad / res.resolution_rad
            row["n_runs"] = len(res.runs)
            row["n_warnings"] = len(res.warnings)
            row["warnings"] = " | ".join(res.warnings)
            row["result"] = res
        rows.append(row)
        if bar is not None:
            bar.update(1)
    if bar is not None:
        bar.close()
    return pd.DataFrame(rows)
