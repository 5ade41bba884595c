"""fit_many on a dask.distributed cluster: chunks of logs to worker processes."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd
import pytest

import hdid

distributed = pytest.importorskip("distributed")

EXAMPLE = Path(__file__).resolve().parents[1] / "data" / "synthetic" / "csf8_paper.csv"


def _other_log(path: Path) -> Path:
    from hdid.reference import logs

    truth = dict(logs.TRUTH_CSF8, k1=800.0, tau_c=2.2e-3)
    logs.make_log(truth, **dict(logs.PAPER_DESIGN, seed=5)).to_csv(path, index=False)
    return path


#: The plumbing under test is the cluster's, not the fit's: two starts and no nested
#: check (one LM program per process instead of three; every worker process reads its
#: programs from the store, ~10 s each) — tests/test_batch.py checks that fit_many passes
#: ``nested`` and the other options through.
OPTIONS = dict(n_starts=2, nested=False)


@pytest.fixture(scope="module")
def logs_and_local(tmp_path_factory):
    """Three logs (one unreadable) and their fits in this process, shared by the tests."""
    tmp = tmp_path_factory.mktemp("dask")
    bad = tmp / "bad.csv"
    bad.write_text("time,theta\n0,abc\n")
    logs = [EXAMPLE, bad, _other_log(tmp / "other.csv")]
    return logs, hdid.fit_many(logs, **OPTIONS)


def test_fit_many_on_a_local_cluster(logs_and_local):
    logs, local = logs_and_local
    with distributed.LocalCluster(
        n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
    ) as cluster, distributed.Client(cluster) as client:
        # chunk_size=2: two tasks, i.e. both workers busy
        table = hdid.fit_many(logs, client=client, chunk_size=2, **OPTIONS)
        workers = {w["id"] for w in client.scheduler_info()["workers"].values()}
    assert len(workers) == 2
    assert table.attrs["timing"]["mode"] == "dask" and table.attrs["timing"]["n_tasks"] == 2
    assert list(table["log"]) == [str(p) for p in logs]
    assert "row 2" in table.loc[1, "error"] and table.loc[1, "result"] is None
    for i in (0, 2):
        assert pd.isna(table.loc[i, "error"])
        res = table.loc[i, "result"]
        assert res.parameters["k1"].value == table.loc[i, "k1"]
        # Same program, same inputs on a worker process: the same fit (tolerance as in
        # tests/test_batch.py: 1e-3 std is far below any change of schedule).
        ref = local.loc[i, "result"]
        for name in ref.problem.free:
            assert abs(res.parameters[name].value - ref.parameters[name].value) <= (
                1e-3 * ref.parameters[name].std
            )


def test_workers_fit_in_local_processes_like_in_this_one(logs_and_local):
    """``workers=2``: a LocalCluster of two single-threaded processes, started and closed
    by the call — the way to use several cores (threads in one process do not: JAX runs
    one CPU program at a time per process). Same fits as in-process, bad file in its row."""
    logs, local = logs_and_local
    table = hdid.fit_many(logs, workers=2, chunk_size=1, **OPTIONS)
    timing = table.attrs["timing"]
    assert timing["mode"] == "dask" and timing["workers"] == 2 and timing["n_tasks"] == 3
    assert list(table["log"]) == [str(p) for p in logs]
    assert "row 2" in table.loc[1, "error"]
    # a result that came back from a worker still works (its problem travels as NumPy)
    back = table.loc[0, "result"].residuals()
    np.testing.assert_allclose(back["residual_rad"], local.loc[0, "result"].residuals()["residual_rad"],
                               rtol=0, atol=1e-9 * float(table.loc[0, "result"].resolution_rad))
    for i in (0, 2):
        ref = local.loc[i, "result"]
        for name in ref.problem.free:
            # same program and inputs in another process (tolerance as above)
            assert abs(table.loc[i, name] - ref.parameters[name].value) <= (
                1e-3 * ref.parameters[name].std
            )


def test_workers_must_be_positive():
    with pytest.raises(ValueError, match="workers = 0"):
        hdid.fit_many([EXAMPLE], workers=0)
