"""Batch identification of many logs: one row per log, bad files reported in their row."""

from __future__ import annotations

import contextlib
import math
import os
from collections.abc import Iterable
from typing import Any

from .._config import float64
from ._fit import fit
from ._vfit import LOG_ERRORS, error_text, fit_batch

#: Logs per dask task (each worker runs the batch fit on its chunk).
DASK_CHUNK = 64
#: ``workers=N``: the logs are cut into about this many chunks per worker process.
CHUNKS_PER_WORKER = 8


def fit_many(
    logs: Iterable[Any],
    *,
    progress: bool = False,
    vectorize: bool = True,
    band_bracket: bool | None = None,
    lanes: int | None = None,
    threads: int | None = None,
    workers: int | None = None,
    client=None,
    executor=None,
    chunk_size: int | None = None,
    **options,
):
    """Fit every log and tabulate the results.

    Parameters
    ----------
    logs:
        CSV paths, pandas DataFrames or :class:`~hdid.Log` objects.
    progress:
        Show a progress bar (tqdm).
    vectorize:
        Fit the logs as a batch (default): each log through :func:`hdid.fit`'s own
        multi-start driver, the logs of one model structure and length bucket (runs
        padded to a multiple of 16 samples) sharing its compiled programs
        (:mod:`hdid._fitting._vfit`), the limit checks only above the floor and no band
        bracket by default (below).
        ``False``: one :func:`hdid.fit` after another (the reference).
    band_bracket:
        Compute each log's model-free stick-band bracket (``stick_band_bracket_*``
        columns) with the event-driven reference simulator. Default: ``False`` for the
        batch (per-log SciPy work: ≈ 90 ms of CPU per log measured, about as much as
        the fit itself),
        ``True`` for ``vectorize=False`` (as :func:`hdid.fit`). Without it the bracket
        columns are empty and ``band_bracket`` says so.
    lanes, threads:
        Batch path: starts per call of the Levenberg–Marquardt program (default 1, as
        :func:`hdid.fit`: wider calls are vmapped, and a vmapped simulator runs its
        event branch as a select) and threads fitting logs (default 1: JAX runs one CPU
        program at a time per process, so more threads do not add cores; use ``workers``
        for that). ``lanes="logs"``: the logs of a length bucket fitted together, every
        call ``lane_width`` (log, start) lanes (:mod:`hdid._fitting._log_lanes`; the same
        fits up to rounding): for a GPU, where a call costs about the same for one lane
        as for thousands; not the default anywhere until measured on one.
    workers:
        Local worker processes, one thread each (a ``dask.distributed.LocalCluster``
        started and closed by this call; needs ``pip install "hdid[dask]"``): the way to
        use several cores. Each worker traces and compiles once (or reads the persistent
        cache, ``HDID_CACHE_DIR``) before its first chunk — seconds to tens of seconds — so
        it pays off from a few hundred logs. Default 1 (in this process). Ignored with ``client``.
    client:
        A ``dask.distributed.Client``: the logs are split into chunks of ``chunk_size``
        (default 64) and each worker runs the batch fit on its chunks. Paths must be
        readable on the workers (or pass DataFrames). The same as
        ``executor=client.get_executor()``.
    executor:
        Any :class:`concurrent.futures.Executor` (parallelism passed in, like emcee's
        ``pool=``): a ``ProcessPoolExecutor``, a dask or MPI executor. The logs are cut
        into chunks of ``chunk_size`` (default 64) and each chunk's batch fit is one
        task. The caller owns the executor (this call neither starts nor shuts it down).
    **options:
        Passed to :func:`hdid.fit` (``inertia``, ``fix``, ``counts_per_rev``, ``n_starts``,
        …). In the batch, ``nested`` defaults to ``None``: :func:`hdid.fit`'s checks against
        the model's limits (the nested Coulomb case, no friction, the linear spring, one
        log at a time) run where a log's fit has not reached the floor, as ``"auto"`` does
        there; a fit at the floor is left as it is (``nested="auto"``: its verdicts on a
        vanishing term too).

    Returns
    -------
    pandas.DataFrame
        One row per log, in input order: ``log``, ``error`` (``None`` when the fit worked),
        every parameter and its ``<name>_std``, ``stick_band_halfwidth_rad`` (± std and the
        data bracket), ``rms_residual_rad``, ``n_warnings``, ``warnings`` and ``result``
        (the :class:`~hdid.FitResult`, for everything else). ``table.attrs["timing"]``:
        wall seconds in total, compiling (``compile_s``: JAX tracing, lowering and XLA
        compilation or persistent-cache reads) and running (``run_s``), and per phase.

    Notes
    -----
    In the batch every log runs :func:`hdid.fit`'s own driver (grid, all starts a few
    iterations, the best ones to convergence, the restart of an optimum that holds moving
    runs, the restarts of a cubic gone to 0, a stuck release or an aliased swing, the refit
    at the RK4 substep a swing above the log's Nyquist frequency wants), so its numbers are
    :func:`hdid.fit`'s up to rounding (the padding reorders sums) and, at the floor, the
    limit checks; logs whose problems have the same structure and padded shape share one compiled
    program per step. A log whose fit diverges gets an error in its row. A log with runs
    that move from their first samples is fitted by :func:`hdid.fit` itself, which weighs
    both stories of their first readings (:mod:`hdid._fitting._first_reading`).
    """
    import pandas as pd

    items = list(logs)
    names = [os.fspath(x) if isinstance(x, (str, os.PathLike)) else f"<log {i}>"
             for i, x in enumerate(items)]
    if band_bracket is None:
        band_bracket = not vectorize
    bar = None
    if progress:
        from tqdm.auto import tqdm

        bar = tqdm(total=len(items), unit="log")

    workers = 1 if workers is None else int(workers)
    if workers < 1:
        raise ValueError(f"workers = {workers}: must be >= 1 (local worker processes)")
    task_options = dict(band_bracket=band_bracket, lanes=lanes, threads=threads, **options)
    if client is not None and executor is not None:
        raise ValueError("give client= or executor=, not both (a dask client is "
                         "executor=client.get_executor())")
    if client is not None:
        rows, timing = _fit_executor(client.get_executor(pure=False), items, names,
                                     chunk_size or DASK_CHUNK, bar, task_options)
        timing["mode"] = "dask"
    elif executor is not None:
        rows, timing = _fit_executor(executor, items, names, chunk_size or DASK_CHUNK, bar,
                                     task_options)
    elif workers > 1 and vectorize:
        with _local_client(workers) as local:
            # about 8 chunks per worker: the last chunks finish close together (the idle
            # tail is at most one chunk), and a chunk is still wide enough for the grid
            chunk = chunk_size or max(1, -(-len(items) // (CHUNKS_PER_WORKER * workers)))
            rows, timing = _fit_executor(local.get_executor(pure=False), items, names, chunk,
                                         bar, task_options)
            timing.update(mode="dask", workers=workers)
    elif vectorize:
        rows, timing = _fit_vectorized(items, names, bar, band_bracket, lanes, threads, options)
    else:
        rows, timing = _fit_loop(items, names, bar, band_bracket, options)
    if bar is not None:
        bar.close()
    table = pd.DataFrame(rows)
    table.attrs["timing"] = timing
    return table


def _fit_loop(items, names, bar, band_bracket, options):
    import time

    t0 = time.perf_counter()
    rows = []
    for name, item in zip(names, items):
        try:
            res = fit(item, **options)
            if not band_bracket:
                res.band_bracket = None
        except LOG_ERRORS as exc:
            res = exc
        rows.append(_row(name, res, band_bracket))
        if bar is not None:
            bar.update(1)
    n_failed = sum(r["error"] is not None for r in rows)
    return rows, {"total_s": time.perf_counter() - t0, "n_logs": len(rows),
                  "n_failed": n_failed, "mode": "loop"}


def _fit_vectorized(items, names, bar, band_bracket, lanes, threads, options):
    def done(i, outcome):
        if bar is not None:
            bar.update(1)

    outcomes, timing = fit_batch(
        items, lanes=lanes, threads=threads, bracket=band_bracket,
        on_done=done, **options,
    )
    rows = [_row(name, res, band_bracket) for name, res in zip(names, outcomes)]
    return rows, {**timing.to_dict(), "mode": "vectorized"}


@contextlib.contextmanager
def _local_client(workers: int):
    """A dask client on ``workers`` local single-threaded worker processes."""
    try:
        from distributed import Client, LocalCluster
    except ImportError as exc:
        raise ImportError(
            f"workers={workers} needs dask.distributed: pip install \"hdid[dask]\" "
            "(or run with workers=1)"
        ) from exc
    with LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        yield client


@float64  # a worker process: hdid's arithmetic, whatever its JAX settings
def _fit_chunk(items, names, options):
    """One task: the batch fit of a chunk of logs (runs on a worker)."""
    opts = dict(options)
    band_bracket = opts.pop("band_bracket")
    lanes, threads = opts.pop("lanes"), opts.pop("threads")
    if threads is None:  # as many lane threads as the worker has task threads
        try:
            from distributed import get_worker

            threads = get_worker().state.nthreads
        except (ImportError, ValueError, AttributeError):
            threads = None
    rows, timing = _fit_vectorized(items, names, None, band_bracket, lanes, threads, opts)
    # Results travel back pickled: a problem of NumPy arrays unpickles ≈ 7× faster than
    # one of JAX arrays (0.4 vs 2.7 ms per log, measured) — CPU the client's process would
    # take from the workers' cores — and works the same in every later call.
    import jax
    import numpy as np

    for row in rows:
        res = row.get("result")
        if res is not None:
            res.problem = jax.tree_util.tree_map(np.asarray, res.problem)
    return rows, timing


def _fit_executor(executor, items, names, chunk, bar, options):
    """Chunks of ``chunk`` logs as tasks of ``executor`` (``concurrent.futures`` API)."""
    import time
    from concurrent.futures import as_completed

    t0 = time.perf_counter()
    chunk = max(int(chunk), 1)
    starts = list(range(0, len(items), chunk))
    futures = {
        executor.submit(_fit_chunk, items[s : s + chunk], names[s : s + chunk], options): s
        for s in starts
    }
    rows: list = [None] * len(items)
    timings = []
    for fut in as_completed(futures):
        s = futures[fut]
        part, timing = fut.result()
        rows[s : s + len(part)] = part
        timings.append(timing)
        if bar is not None:
            bar.update(len(part))
    summed = {k: sum(t.get(k, 0) for t in timings)
              for k in ("compile_s", "run_s", "setup_s", "grid_s", "solve_s", "analyse_s",
                        "lane_steps", "n_failed")}
    return rows, {"total_s": time.perf_counter() - t0, "n_logs": len(items), "mode": "executor",
                  "n_tasks": len(starts), "workers_sum": summed}


def _row(name: str, res, band_bracket: bool) -> dict[str, Any]:
    row: dict[str, Any] = {"log": name, "error": None}
    if isinstance(res, BaseException):
        row["error"] = error_text(res)
        row["result"] = None
        return row
    for n, p in res.parameters.items():
        row[n] = p.value
        row[f"{n}_std"] = None if p.fixed else p.std
    hw, hw_std = res.derived["stick_band_halfwidth_rad"]
    row["stick_band_halfwidth_rad"] = hw
    row["stick_band_halfwidth_std_rad"] = hw_std
    lo, hi = res.band_bracket if res.band_bracket else (None, None)
    row["stick_band_bracket_lo_rad"], row["stick_band_bracket_hi_rad"] = lo, hi
    row["band_bracket"] = ("computed" if res.band_bracket else
                           "not available" if band_bracket else "skipped (band_bracket=False)")
    row["k1/inertia"] = res.derived["k1/inertia"][0] if "k1/inertia" in res.derived else None
    row["rms_residual_rad"] = res.rms_residual_rad
    row["rms_residual_counts"] = res.rms_residual_rad / res.resolution_rad
    row["n_runs"] = len(res.runs)
    row["units_problem"] = res.units_problem  # a wrong unit: the one line that matters
    row["n_warnings"] = len(res.warnings)
    row["warnings"] = " | ".join(res.warnings)
    row["result"] = res
    if not all(math.isfinite(v) for v in (hw, res.rms_residual_rad)):
        row["error"] = "non-finite fit result"
    return row
