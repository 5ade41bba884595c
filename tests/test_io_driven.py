"""Tests for the driven-log columns of hdid._log (motor torque/current, output angle, load)."""

from __future__ import annotations

import hashlib
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from hdid._errors import LogError
from hdid._log import Log, Run, read_log, write_log

ROOT = Path(__file__).resolve().parents[1]
DRIVEN = ROOT / "data" / "synthetic" / "driven_csf8.csv"
FREE = ROOT / "data" / "synthetic" / "csf8_paper.csv"
CPR = 4000
Q = 2 * math.pi / CPR
OUT_CPR = 2**19
QO = 2 * math.pi / OUT_CPR
DT = 0.004
KT = 0.0143  # N m/A, a small BLDC motor


def digest(path: Path) -> str:
    return hashlib.sha256(path.read_bytes()).hexdigest()


def driven_frame(n: int = 30, runs=("a", "b"), *, current: bool = False) -> pd.DataFrame:
    """A small valid driven log: the WG turns, the output follows (-theta/N), a load."""
    rows = []
    for j, name in enumerate(runs):
        t = np.arange(n) * DT
        counts = np.rint((3.0 + j) * t**2 / Q)
        out_counts = np.rint(-(counts * Q) / 100.0 / QO) + 17
        torque = 4e-3 + 1e-4 * np.sin(t * 50 + j)
        load = 0.5 * np.cos(3 * t + j)
        for k in range(n):
            rows.append({
                "run": name,
                "time": t[k],
                "theta": counts[k] * Q,
                "theta_out": out_counts[k] * QO,
                ("motor_current" if current else "motor_torque"):
                    torque[k] / KT if current else torque[k],
                "load_torque": load[k],
            })
    return pd.DataFrame(rows)


def write_csv(df: pd.DataFrame, path: Path) -> Path:
    df.to_csv(path, index=False, float_format="%.17g", lineterminator="\n")
    return path


def raises_log_error(path: Path, **kwargs) -> LogError:
    before = digest(path)
    with pytest.raises(LogError) as info:
        read_log(path, **kwargs)
    assert digest(path) == before  # the input file is never modified
    text = str(info.value)
    assert "\n" not in text and text.startswith(str(path))
    return info.value


# ------------------------------------------------------------------ the shipped log


def test_reads_shipped_driven_log():
    before = digest(DRIVEN)
    log = read_log(DRIVEN)
    assert digest(DRIVEN) == before
    assert log.is_driven
    assert [r.name for r in log.runs] == ["1", "2", "3", "4"]
    assert log.sample_period == pytest.approx(DT, rel=1e-9)
    # encoder steps estimated from the data; 1e-9 relative: values written with 15 digits
    assert log.resolution == pytest.approx(Q, rel=1e-9)
    assert log.output_resolution == pytest.approx(QO, rel=1e-9)
    # round_trip: the reference read must be exact too (pandas 3.0.6's default parser read
    # -0.008014558756458316 as -0.0080145587564583, 3.5e-13 off)
    raw = pd.read_csv(DRIVEN, float_precision="round_trip")
    for run in log.runs:
        sel = raw[raw["run"].astype(str) == run.name]
        for key in ("motor_torque", "theta_out", "load_torque"):
            arr = getattr(run, key)
            assert arr.dtype == np.float64 and not arr.flags.writeable
            np.testing.assert_array_equal(arr, sel[key].to_numpy())
        assert run.is_driven


def test_free_motion_log_is_not_driven():
    log = read_log(FREE)
    assert not log.is_driven
    assert log.output_resolution is None and log.torque_constant is None
    assert all(r.motor_torque is None and r.theta_out is None and r.load_torque is None
               for r in log.runs)
    # the driven-only arguments are ignored for a free-motion log (joint fits read both
    # logs with one set of arguments)
    same = read_log(FREE, torque_constant=KT, output_counts_per_rev=OUT_CPR)
    assert not same.is_driven and same.torque_constant is None
    for a, b in zip(log.runs, same.runs):
        np.testing.assert_array_equal(a.theta, b.theta)


# --------------------------------------------------------------- conversions


def test_motor_current_times_torque_constant(tmp_path):
    torque = driven_frame()
    path = write_csv(driven_frame(current=True), tmp_path / "current.csv")
    log = read_log(path, torque_constant=KT)
    assert log.torque_constant == KT and log.is_driven
    got = np.concatenate([r.motor_torque for r in log.runs])
    # (torque/KT)*KT in float64: a few ulps
    np.testing.assert_allclose(got, torque["motor_torque"].to_numpy(), rtol=1e-14)


def test_output_counts(tmp_path):
    df = driven_frame()
    counts = np.rint(df["theta_out"].to_numpy() / QO).astype(np.int64)
    df_counts = df.drop(columns="theta_out").assign(output_counts=counts)
    path = write_csv(df_counts, tmp_path / "counts.csv")
    log = read_log(path, output_counts_per_rev=OUT_CPR)
    assert log.output_counts_per_rev == OUT_CPR
    assert log.output_resolution == pytest.approx(QO, rel=1e-15)
    np.testing.assert_allclose(np.concatenate([r.theta_out for r in log.runs]), counts * QO,
                               rtol=0, atol=0)
    # 'theta_out' holding counts, with the argument
    path2 = write_csv(df.assign(theta_out=counts), tmp_path / "counts2.csv")
    log2 = read_log(path2, output_counts_per_rev=OUT_CPR)
    np.testing.assert_array_equal(log2.runs[0].theta_out, log.runs[0].theta_out)


def test_driven_run_may_stay_stuck(tmp_path):
    df = driven_frame(runs=("a",))
    df["theta"] = 0.25  # no motion: a driven run below breakaway is still data
    log = read_log(write_csv(df, tmp_path / "stuck.csv"))
    assert log.is_driven and np.all(log.runs[0].theta == 0.25)


# --------------------------------------------------------------- bad input


def test_missing_motor_torque_value(tmp_path):
    df = driven_frame()
    df["motor_torque"] = df["motor_torque"].astype(object)
    df.loc[5, "motor_torque"] = ""
    err = raises_log_error(write_csv(df, tmp_path / "m.csv"))
    assert err.column == "motor_torque" and err.row == 7  # data row 5 is CSV line 7
    assert "empty" in err.message


@pytest.mark.parametrize("column", ["theta_out", "load_torque", "motor_torque"])
@pytest.mark.parametrize("cell, word", [("abc", "text"), ("inf", "infinite"), ("nan", "missing")])
def test_bad_driven_cells(tmp_path, column, cell, word):
    df = driven_frame().astype({column: object})
    df.loc[11, column] = cell
    err = raises_log_error(write_csv(df, tmp_path / "bad.csv"))
    assert err.column == column and err.row == 13
    assert word in err.message


def test_current_without_constant(tmp_path):
    err = raises_log_error(write_csv(driven_frame(current=True), tmp_path / "c.csv"))
    assert err.column == "motor_current" and "torque_constant" in err.message


def test_both_torque_columns(tmp_path):
    df = driven_frame()
    df["motor_current"] = df["motor_torque"] / KT
    err = raises_log_error(write_csv(df, tmp_path / "both.csv"), torque_constant=KT)
    assert err.column == "motor_current" and "both" in err.message


def test_constant_without_current_column(tmp_path):
    err = raises_log_error(write_csv(driven_frame(), tmp_path / "t.csv"), torque_constant=KT)
    assert err.column == "motor_torque" and "torque_constant" in err.message


@pytest.mark.parametrize("bad", [-1.0, 0.0, float("nan"), "x"])
def test_bad_torque_constant(tmp_path, bad):
    err = raises_log_error(write_csv(driven_frame(current=True), tmp_path / "c.csv"),
                           torque_constant=bad)
    assert "torque constant" in err.message


@pytest.mark.parametrize("column", ["theta_out", "load_torque"])
def test_driven_column_without_motor_torque(tmp_path, column):
    df = driven_frame().drop(columns=[c for c in ("motor_torque", "theta_out", "load_torque")
                                      if c != column])
    err = raises_log_error(write_csv(df, tmp_path / "nm.csv"))
    assert err.column == column
    assert "motor_torque" in err.message and "no motor torque" in err.message


def test_output_counts_need_counts_per_rev(tmp_path):
    df = driven_frame()
    df = df.drop(columns="theta_out").assign(output_counts=np.rint(df["theta_out"] / QO))
    err = raises_log_error(write_csv(df, tmp_path / "oc.csv"))
    assert err.column == "output_counts" and "output_counts_per_rev" in err.message


def test_output_counts_not_integer(tmp_path):
    err = raises_log_error(write_csv(driven_frame(), tmp_path / "r.csv"),
                           output_counts_per_rev=OUT_CPR)
    assert err.column == "theta_out" and err.row == 2 and "whole number" in err.message


def test_output_counts_per_rev_without_column(tmp_path):
    df = driven_frame().drop(columns="theta_out")
    err = raises_log_error(write_csv(df, tmp_path / "x.csv"), output_counts_per_rev=OUT_CPR)
    assert "output_counts_per_rev" in err.message


def test_mixed_driven_and_free_runs(tmp_path):
    df = driven_frame(runs=("a", "b", "c")).astype(
        {"motor_torque": object, "theta_out": object, "load_torque": object})
    free = df["run"] == "b"
    df.loc[free, ["motor_torque", "theta_out", "load_torque"]] = ""
    err = raises_log_error(write_csv(df, tmp_path / "mixed.csv"))
    first_b = int(np.flatnonzero(free.to_numpy())[0]) + 2
    assert err.column == "motor_torque" and err.row == first_b
    assert "'b'" in err.message and "all driven or all free-motion" in err.message


def test_dataframe_input_and_messages(tmp_path):
    df = driven_frame(current=True)
    with pytest.raises(LogError, match=r"^<DataFrame>: column 'motor_current'"):
        read_log(df)
    log = read_log(df, torque_constant=KT)
    assert log.is_driven and log.source == "<DataFrame>"


# --------------------------------------------------------------- writing and objects


def test_write_log_round_trip(tmp_path):
    log = read_log(DRIVEN)
    path = tmp_path / "rt.csv"
    write_log(path, log)
    back = read_log(path)
    assert back.is_driven and len(back.runs) == len(log.runs)
    for a, b in zip(log.runs, back.runs):
        for key in ("time", "theta", "motor_torque", "theta_out", "load_torque"):
            np.testing.assert_array_equal(getattr(a, key), getattr(b, key))
    # output angle as integer counts
    path2 = tmp_path / "rt_counts.csv"
    write_log(path2, log, output_counts_per_rev=OUT_CPR, counts_per_rev=CPR)
    raw = pd.read_csv(path2)
    assert raw["theta_out"].dtype.kind == "i" and raw["theta"].dtype.kind == "i"
    back2 = read_log(path2, output_counts_per_rev=OUT_CPR, counts_per_rev=CPR)
    for a, b in zip(log.runs, back2.runs):
        # quantized values written with 15 digits: back on the grid within 1e-12 rad
        np.testing.assert_allclose(b.theta_out, a.theta_out, rtol=0, atol=1e-12)


def test_write_log_without_load_and_output(tmp_path):
    t = np.arange(20) * DT
    runs = [Run("1", t, t**2, motor_torque=np.full(20, 4e-3)),
            Run("2", t, -(t**2), motor_torque=np.full(20, -4e-3),
                load_torque=np.linspace(0, 1, 20))]
    path = tmp_path / "w.csv"
    write_log(path, runs)
    raw = pd.read_csv(path)
    assert "theta_out" not in raw and list(raw["load_torque"][:20]) == [0.0] * 20
    back = read_log(path)
    assert back.is_driven and back.output_resolution is None


def test_write_log_refuses_mixed_runs(tmp_path):
    t = np.arange(20) * DT
    runs = [Run("1", t, t**2, motor_torque=np.ones(20)), Run("2", t, t**2)]
    with pytest.raises(LogError, match="no motor_torque"):
        write_log(tmp_path / "mixed.csv", runs)
    runs = [Run("1", t, t**2, motor_torque=np.ones(20), theta_out=t),
            Run("2", t, t**2, motor_torque=np.ones(20))]
    with pytest.raises(LogError, match="no theta_out"):
        write_log(tmp_path / "mixed2.csv", runs)
    bad = Run("1", t, t**2, motor_torque=np.r_[np.ones(19), np.inf])
    with pytest.raises(LogError, match="non-finite motor_torque"):
        write_log(tmp_path / "inf.csv", [bad])


def test_run_and_log_validation():
    t = np.arange(10) * DT
    with pytest.raises(ValueError, match="without motor_torque"):
        Run("1", t, t, theta_out=t)
    with pytest.raises(ValueError, match="load_torque has 9"):
        Run("1", t, t, motor_torque=t, load_torque=t[:9])
    driven = Run("1", t, t, motor_torque=t)
    free = Run("2", t, t)
    with pytest.raises(ValueError, match="all driven or all free-motion"):
        Log("x", (driven, free), DT, None)
    assert Log("x", (driven,), DT, None).is_driven
    assert not Log("x", (free,), DT, None).is_driven
