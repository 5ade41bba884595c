"""Tests for hdid._log: reading, validating and writing free-motion logs."""

from __future__ import annotations

import hashlib
import math
import pickle
import re
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from hdid._errors import HdidError, LogError
from hdid._log import Log, Run, estimate_resolution, read_log, write_log

CPR = 4000
Q = 2 * math.pi / CPR  # encoder step [rad]
DT = 0.004  # 250 Hz


# ----------------------------------------------------------------- helpers


def release(n: int, amp: float = 0.157, freq: float = 5.0) -> tuple[np.ndarray, np.ndarray]:
    """Times and integer encoder counts of a decaying spring-back."""
    t = np.arange(n) * DT
    counts = np.rint(amp * np.exp(-3.0 * t) * np.cos(2 * np.pi * freq * t) / Q).astype(np.int64)
    return t, counts


def log_lines(
    runs=(("a", "s1", 0.0), ("b", "s2", 1e-4)),
    n: int = 40,
    *,
    counts: bool = False,
    setup: bool = True,
    inertia: bool = True,
    run_col: bool = True,
    periods: dict[str, float] | None = None,
    offset: float = 0.0,
) -> list[str]:
    """CSV lines (header first) of a valid log; data line i is CSV row i + 2."""
    header = (["run"] if run_col else []) + (["setup"] if setup else []) + ["time", "theta"]
    header += ["added_inertia"] if inertia else []
    lines = [",".join(header)]
    for k, (name, setup_label, j) in enumerate(runs):
        t, c = release(n, amp=0.157 - 0.02 * k)
        if periods and name in periods:
            t = np.arange(n) * periods[name]
        for ti, ci in zip(t, c):
            theta = str(int(ci)) if counts else repr(offset + float(ci) * Q)
            cells = ([name] if run_col else []) + ([setup_label] if setup else [])
            cells += [repr(float(ti)), theta] + ([repr(j)] if inertia else [])
            lines.append(",".join(cells))
    return lines


def write_lines(path: Path, lines: list[str]) -> Path:
    path.write_text("\n".join(lines) + "\n", encoding="utf-8")
    return path


def set_cell(lines: list[str], row: int, column: str, value: str) -> list[str]:
    """Return a copy of `lines` with the cell at CSV `row` (1-based line) replaced."""
    out = list(lines)
    col = out[0].split(",").index(column)
    cells = out[row - 1].split(",")
    cells[col] = value
    out[row - 1] = ",".join(cells)
    return out


def error_of(source, **kwargs) -> LogError:
    with pytest.raises(LogError) as info:
        read_log(source, **kwargs)
    err = info.value
    assert "\n" not in str(err) and "\r" not in str(err)
    return err


def rows_in(message: str) -> list[int]:
    return [int(m) for m in re.findall(r"\brow (\d+)\b", message)]


def assert_error(err: LogError, path: Path, *, column: str | None = None, row: int | None = None):
    msg = str(err)
    assert path.name in msg
    if column is not None:
        assert f"column '{column}'" in msg
        assert err.column == column
    if row is not None:
        assert rows_in(msg) == [row], msg
        assert err.row == row


@pytest.fixture
def good(tmp_path) -> tuple[Path, list[str]]:
    lines = log_lines()
    return write_lines(tmp_path / "good.csv", lines), lines


# ----------------------------------------------------------------- LogError


def test_log_error_format_and_pickle():
    err = LogError("cell is empty — fill it\nor drop the row", path="x.csv", column="theta", row=17)
    assert str(err) == "x.csv: column 'theta', row 17: cell is empty — fill it or drop the row"
    assert isinstance(err, HdidError) and isinstance(err, ValueError)
    assert (err.path, err.column, err.row) == ("x.csv", "theta", 17)
    assert str(LogError("bad")) == "<DataFrame>: bad"
    assert str(LogError("bad", row=3)) == "<DataFrame>: row 3: bad"
    back = pickle.loads(pickle.dumps(err))
    assert str(back) == str(err) and back.row == 17 and back.column == "theta"


# ----------------------------------------------------------------- good logs


def test_read_good_multi_run_log(good):
    path, lines = good
    log = read_log(path)
    assert isinstance(log, Log)
    assert log.source == str(path)
    assert [r.name for r in log.runs] == ["a", "b"]
    assert [r.setup for r in log.runs] == ["s1", "s2"]
    assert log.setups == ("s1", "s2")
    assert [r.added_inertia for r in log.runs] == [0.0, 1e-4]
    assert [r.first_row for r in log.runs] == [2, 42]
    assert log.n_samples == 80
    assert log.sample_period == pytest.approx(DT, rel=1e-12)
    assert log.resolution == pytest.approx(Q, rel=1e-9)
    assert log.counts_per_rev is None
    _, c = release(40)
    np.testing.assert_array_equal(log.runs[0].theta, c * Q)
    np.testing.assert_array_equal(log.runs[0].time, np.arange(40) * DT)
    assert log.runs[0].time.dtype == np.float64
    assert not log.runs[0].theta.flags.writeable


def test_round_trip_write_read(tmp_path, good):
    log = read_log(good[0])
    out = tmp_path / "copy.csv"
    write_log(out, log)
    assert out.read_text().splitlines()[0] == "run,setup,time,theta,added_inertia"
    back = read_log(out)
    assert [(r.name, r.setup, r.added_inertia, r.first_row) for r in back.runs] == [
        (r.name, r.setup, r.added_inertia, r.first_row) for r in log.runs
    ]
    for a, b in zip(log.runs, back.runs):
        np.testing.assert_array_equal(a.time, b.time)
        np.testing.assert_array_equal(a.theta, b.theta)
    assert back.resolution == pytest.approx(log.resolution, rel=1e-12)
    assert back.sample_period == log.sample_period


def test_round_trip_counts_and_runs_sequence(tmp_path):
    t, c = release(30)
    runs = [
        Run("r1", t, c * Q, setup="A"),
        Run("r2", t + 10.0, -c * Q, setup="B"),
        Run("7", t, 0.5 * c * Q + 3 * Q, setup="A"),
    ]
    out = tmp_path / "sim.csv"
    write_log(out, runs, counts_per_rev=CPR)
    text = out.read_text().splitlines()
    assert text[0] == "run,setup,time,theta"  # all added inertias are zero
    assert text[1].split(",")[3] == str(int(c[0]))  # integer counts
    log = read_log(out, counts_per_rev=CPR)
    assert log.counts_per_rev == CPR
    assert log.resolution == pytest.approx(Q, rel=1e-15)
    assert log.setups == ("A", "B")
    assert [r.name for r in log.runs] == ["r1", "r2", "7"]
    for a, b in zip(runs, log.runs):
        np.testing.assert_allclose(b.theta, np.rint(a.theta / Q) * Q, rtol=0, atol=1e-15)
        np.testing.assert_array_equal(a.time, b.time)
        assert b.added_inertia == 0.0


def test_write_log_refuses_overwrite(tmp_path, good):
    path = good[0]
    before = path.read_bytes()
    log = read_log(path)
    err = pytest.raises(LogError, write_log, path, log).value
    assert path.name in str(err) and "overwrite=True" in str(err)
    assert path.read_bytes() == before
    write_log(path, log.runs[:1], overwrite=True)
    assert [r.name for r in read_log(path).runs] == ["a"]


def test_write_log_rejects_duplicate_run_names(tmp_path):
    t, c = release(20)
    with pytest.raises(LogError, match="twice"):
        write_log(tmp_path / "dup.csv", [Run("a", t, c * Q), Run("a", t, c * Q)])
    assert not (tmp_path / "dup.csv").exists()


def test_counts_conversion(tmp_path):
    path = write_lines(tmp_path / "counts.csv", log_lines(counts=True))
    log = read_log(path, counts_per_rev=CPR)
    _, c = release(40)
    np.testing.assert_array_equal(log.runs[0].theta, c * (2 * math.pi / CPR))
    assert log.resolution == 2 * math.pi / CPR
    # a `counts` column is an alias of theta when counts_per_rev is given
    lines = log_lines(counts=True)
    lines[0] = lines[0].replace("theta", "Counts")
    log2 = read_log(write_lines(tmp_path / "alias.csv", lines), counts_per_rev=CPR)
    np.testing.assert_array_equal(log2.runs[1].theta, log.runs[1].theta)


def test_flexible_header_extra_columns_and_defaults(tmp_path):
    lines = log_lines(setup=False, inertia=False, run_col=False, runs=(("x", "", 0.0),))
    lines = [" Time , THETA ,note"] + [line + ",hello" for line in lines[1:]]
    log = read_log(write_lines(tmp_path / "plain.csv", lines))
    (run,) = log.runs
    assert (run.name, run.setup, run.added_inertia, run.first_row) == ("1", "1", 0.0, 2)
    assert log.setups == ("1",)


def test_blank_lines_are_skipped_and_rows_stay_true_line_numbers(tmp_path):
    lines = log_lines()
    lines = lines[:5] + [""] + lines[5:]  # blank line is line 6
    log = read_log(write_lines(tmp_path / "blank.csv", lines))
    assert log.n_samples == 80 and log.runs[1].first_row == 43
    bad = set_cell(lines, 10, "theta", "oops")
    err = error_of(write_lines(tmp_path / "blank_bad.csv", bad))
    assert_error(err, tmp_path / "blank_bad.csv", column="theta", row=10)


def test_dataframe_input(good):
    df = pd.read_csv(good[0])
    log = read_log(df)
    assert log.source == "<DataFrame>"
    assert [r.name for r in log.runs] == ["a", "b"] and log.runs[1].first_row == 42
    df.loc[4, "theta"] = np.nan
    err = error_of(df)
    assert str(err).startswith("<DataFrame>: column 'theta', row 6:")
    df2 = pd.read_csv(good[0], dtype=str)
    df2.loc[7, "time"] = "abc"
    assert "'abc'" in str(error_of(df2))


def test_numbers_are_read_correctly_rounded_whatever_pandas_parses(good, monkeypatch):
    """Every number is the correctly rounded value of its text (Python's ``float``), even
    under a pandas whose text parser is one unit in the last place off — pandas 3.0.6 read
    ``repr(0.036)`` as 0.036000000000000004 (seen on the GPU machine's image). Here the
    parser is made off by one ulp on purpose; ``to_numeric`` still decides what is a number."""
    import hdid._log._table as io_mod

    real = pd.to_numeric

    def off_by_one_ulp(arg, *a, **kw):
        out = np.asarray(real(arg, *a, **kw), dtype=np.float64)
        return np.nextafter(out, np.inf)

    monkeypatch.setattr(io_mod.pd, "to_numeric", off_by_one_ulp)
    path, lines = good
    log = read_log(path)
    header = lines[0].split(",")
    rows = [line.split(",") for line in lines[1:41]]  # run "a"
    for col, arr in (("time", log.runs[0].time), ("theta", log.runs[0].theta)):
        text = [r[header.index(col)] for r in rows]
        np.testing.assert_array_equal(arr, [float(x) for x in text])


def test_file_is_not_modified(good):
    path = good[0]
    digest = hashlib.sha256(path.read_bytes()).hexdigest()
    mtime = path.stat().st_mtime_ns
    read_log(path)
    error_of(path, counts_per_rev=CPR)
    assert hashlib.sha256(path.read_bytes()).hexdigest() == digest
    assert path.stat().st_mtime_ns == mtime


# ----------------------------------------------------------------- estimate_resolution


def test_estimate_resolution_quantized_sine_with_offset():
    t = np.arange(2000) * DT
    theta = 0.7312 + Q * np.rint(0.157 * np.sin(2 * np.pi * 1.3 * t) / Q)
    assert estimate_resolution(theta) == pytest.approx(Q, rel=1e-9)
    assert estimate_resolution(-12.5 + theta[::7]) == pytest.approx(Q, rel=1e-9)


def test_estimate_resolution_not_quantized():
    rng = np.random.default_rng(1)
    assert estimate_resolution(0.157 * np.sin(np.linspace(0, 3, 500))) is None
    assert estimate_resolution(rng.normal(size=300)) is None
    assert estimate_resolution(np.full(10, 0.3)) is None
    assert estimate_resolution(np.array([])) is None


# ----------------------------------------------------------------- file-level errors


def test_missing_file(tmp_path):
    path = tmp_path / "nope.csv"
    err = error_of(path)
    assert_error(err, path)
    assert "not found" in str(err)


def test_directory(tmp_path):
    err = error_of(tmp_path)
    assert str(tmp_path) in str(err) and "directory" in str(err)


@pytest.mark.parametrize("content", [b"", b"\n\n  \n"])
def test_empty_file(tmp_path, content):
    path = tmp_path / "empty.csv"
    path.write_bytes(content)
    assert_error(error_of(path), path)


def test_header_only(tmp_path):
    path = write_lines(tmp_path / "hdr.csv", ["time,theta"])
    err = error_of(path)
    assert_error(err, path)
    assert "no data rows" in str(err)


def test_binary_file(tmp_path):
    path = tmp_path / "blob.csv"
    path.write_bytes(bytes(range(256)) * 4)
    assert_error(error_of(path), path)


def test_missing_column_lists_found_columns(tmp_path):
    lines = log_lines()
    lines[0] = lines[0].replace("theta", "winkel")
    path = write_lines(tmp_path / "cols.csv", lines)
    msg = str(error_of(path))
    assert path.name in msg and "'theta'" in msg and "'winkel'" in msg and "'run'" in msg


def test_semicolon_file_is_read_like_the_comma_file(tmp_path):
    # A ';'-separated export (issue 18) reads to the same log as the comma file.
    lines = log_lines()
    semi = read_log(write_lines(tmp_path / "semi.csv", [line.replace(",", ";") for line in lines]))
    comma = read_log(write_lines(tmp_path / "comma.csv", lines))
    assert [r.name for r in semi.runs] == [r.name for r in comma.runs]
    assert all(np.array_equal(a.theta, b.theta) for a, b in zip(semi.runs, comma.runs))


def test_mixed_delimiters_get_delimiter_hint(tmp_path):
    lines = log_lines()
    lines = [lines[0].replace(",", ";")] + lines[1:]  # ';' header, ',' rows
    path = write_lines(tmp_path / "mixed.csv", lines)
    msg = str(error_of(path))
    assert path.name in msg and "delimiter" in msg


def test_no_header_hint(tmp_path):
    path = write_lines(tmp_path / "nohdr.csv", log_lines(run_col=False, setup=False)[1:])
    assert "header" in str(error_of(path))


def test_duplicate_column(tmp_path):
    lines = log_lines(inertia=False)
    lines = [lines[0] + ",Time"] + [line + ",1" for line in lines[1:]]
    path = write_lines(tmp_path / "dup.csv", lines)
    assert_error(error_of(path), path, column="Time")


def test_row_with_extra_cells(tmp_path):
    lines = log_lines()
    lines[11] += ",99"  # line 12
    path = write_lines(tmp_path / "extra.csv", lines)
    assert_error(error_of(path), path, row=12)


def test_unclosed_quote(tmp_path):
    lines = set_cell(log_lines(), 9, "theta", '"0.1')
    path = write_lines(tmp_path / "quote.csv", lines)
    assert_error(error_of(path), path, row=9)


# ----------------------------------------------------------------- cell errors


@pytest.mark.parametrize("column", ["run", "setup", "time", "theta", "added_inertia"])
@pytest.mark.parametrize("value", ["", "   "])
def test_empty_cell(tmp_path, column, value):
    path = write_lines(tmp_path / "hole.csv", set_cell(log_lines(), 17, column, value))
    err = error_of(path)
    assert_error(err, path, column=column, row=17)
    assert "empty" in str(err)


@pytest.mark.parametrize(
    ("column", "cell", "shown"),
    [
        ("time", "abc", "'abc'"),
        ("theta", '"1,5"', "'1,5'"),
        ("added_inertia", "1e-4kg", "'1e-4kg'"),
        ("theta", "x" * 60, "'" + "x" * 20 + "…'"),
    ],
)
def test_text_in_numeric_cell(tmp_path, column, cell, shown):
    path = write_lines(tmp_path / "text.csv", set_cell(log_lines(), 23, column, cell))
    err = error_of(path)
    assert_error(err, path, column=column, row=23)
    assert shown in str(err) and "x" * 21 not in str(err)


@pytest.mark.parametrize(("column", "cell"), [("theta", "inf"), ("time", "-Infinity"), ("theta", "1e999")])
def test_infinite_value(tmp_path, column, cell):
    path = write_lines(tmp_path / "inf.csv", set_cell(log_lines(), 30, column, cell))
    err = error_of(path)
    assert_error(err, path, column=column, row=30)
    assert "infinite" in str(err)


def test_nan_text(tmp_path):
    path = write_lines(tmp_path / "nan.csv", set_cell(log_lines(), 5, "theta", "NaN"))
    err = error_of(path)
    assert_error(err, path, column="theta", row=5)
    assert "missing" in str(err)


def test_first_bad_cell_in_file_order_is_reported(tmp_path):
    lines = set_cell(log_lines(), 30, "run", "")
    lines = set_cell(lines, 12, "added_inertia", "zz")
    path = write_lines(tmp_path / "two.csv", lines)
    assert_error(error_of(path), path, column="added_inertia", row=12)


# ----------------------------------------------------------------- row-level errors


def test_time_not_increasing(tmp_path):
    lines = log_lines()
    t14, t15 = lines[13].split(",")[2], lines[14].split(",")[2]
    lines = set_cell(set_cell(lines, 14, "time", t15), 15, "time", t14)
    path = write_lines(tmp_path / "swap.csv", lines)
    err = error_of(path)
    assert_error(err, path, column="time", row=15)
    assert "increase" in str(err)


def test_duplicated_row(tmp_path):
    """An exact copy of a row (a sample written twice) is dropped with a note; the same
    time with another reading is two samples at one instant: an error naming the row."""
    lines = log_lines()
    lines.insert(20, lines[19])  # copy of line 20 becomes line 21
    path = write_lines(tmp_path / "dup.csv", lines)
    log = read_log(path)
    assert [r.n_samples for r in log.runs] == [40, 40]
    assert any("row(s) 21 repeat the row above exactly" in n for n in log.notes), log.notes
    lines = set_cell(lines, 21, "theta", repr(float(lines[19].split(",")[3]) + Q))
    path = write_lines(tmp_path / "dup.csv", lines)
    err = error_of(path)
    assert_error(err, path, column="time", row=21)
    assert "repeats" in str(err)


def test_time_restart_without_run_column_splits_the_runs(tmp_path):
    """A clock that restarts at 0 without a run column: each stretch is a run, and a note
    names the row where time drops back."""
    lines = log_lines(run_col=False, setup=False, inertia=False)
    path = write_lines(tmp_path / "restart.csv", lines)
    log = read_log(path)
    assert [(r.name, r.n_samples, r.first_row) for r in log.runs] == [("1", 40, 2),
                                                                      ("2", 40, 42)]
    assert any("time restarts at row(s) 42 " in n for n in log.notes), log.notes


def test_uneven_sampling_is_data(tmp_path):
    """A jittered step (1.5 periods) is data: the run is kept whole, the period is the
    median step, and nothing is noted."""
    lines = log_lines()
    t = float(lines[25].split(",")[2])
    path = write_lines(tmp_path / "gap.csv", set_cell(lines, 26, "time", repr(t + 0.5 * DT)))
    log = read_log(path)
    assert [r.n_samples for r in log.runs] == [40, 40] and log.notes == ()
    assert log.sample_period == pytest.approx(DT, rel=1e-12)
    assert log.runs[0].time[24] == pytest.approx(t + 0.5 * DT)


def test_break_in_time_splits_the_run(tmp_path):
    """A step of 6 periods (over BREAK_PERIODS = 5) is a break: run 'a' becomes 'a' and
    'a.2', each with its own first row, and a note names the split."""
    lines = log_lines()
    for row in range(22, 42):  # rows 22.. of run 'a' come 5 periods later (a 6-period step)
        t = float(lines[row - 1].split(",")[2])
        lines = set_cell(lines, row, "time", repr(t + 5 * DT))
    path = write_lines(tmp_path / "break.csv", lines)
    log = read_log(path)
    assert [r.name for r in log.runs] == ["a", "a.2", "b"]
    assert [r.n_samples for r in log.runs] == [20, 20, 40]
    assert log.runs[1].first_row == 22
    assert len(log.notes) == 1 and "'a'" in log.notes[0] and "'a.2'" in log.notes[0]
    assert "split" in log.notes[0]
    # a piece shorter than min_samples_per_run stays joined to its neighbour: no data lost
    log = read_log(path, min_samples_per_run=21)
    assert [r.n_samples for r in log.runs] == [40, 40] and log.notes == ()


def test_break_where_the_gear_rests_keeps_the_run_whole(tmp_path):
    """A pause during the hold (or the stuck tail) is no break in the physics: the gear
    rests on one side of it, so the run stays whole (no note) and the release is found
    after the pause."""
    t = np.arange(60) * DT
    t[8:] += 10 * DT  # the logger paused for 10 periods after the 8th held sample
    theta = np.full(60, 0.157)
    theta[20:] = 0.157 * np.exp(-3.0 * (t[20:] - t[20])) * np.cos(60.0 * (t[20:] - t[20]))
    theta = np.round(theta / Q) * Q
    path = tmp_path / "hold_pause.csv"
    pd.DataFrame({"time": t, "theta": theta}).to_csv(path, index=False)
    log = read_log(path)
    assert [r.n_samples for r in log.runs] == [60] and log.notes == ()


def test_runs_with_different_rates_are_data(tmp_path):
    runs = (("a", "s", 0.0), ("b", "s", 0.0), ("c", "s", 0.0))
    lines = log_lines(runs, periods={"b": 0.005})
    path = write_lines(tmp_path / "rates.csv", lines)
    log = read_log(path)
    assert [r.n_samples for r in log.runs] == [40, 40, 40] and log.notes == ()
    assert log.sample_period == pytest.approx(DT, rel=1e-12)  # the median step
    np.testing.assert_allclose(np.diff(log.runs[1].time), 0.005, rtol=1e-9)


def test_non_contiguous_run(tmp_path):
    runs = (("a", "s", 0.0), ("b", "s", 0.0), ("a", "s", 0.0))
    path = write_lines(tmp_path / "split.csv", log_lines(runs))
    err = error_of(path)
    assert_error(err, path, column="run", row=82)
    assert "contiguous" in str(err)


def test_setup_changes_within_run(tmp_path):
    path = write_lines(tmp_path / "setup.csv", set_cell(log_lines(), 33, "setup", "s9"))
    assert_error(error_of(path), path, column="setup", row=33)


def test_negative_added_inertia(tmp_path):
    path = write_lines(tmp_path / "neg.csv", set_cell(log_lines(), 50, "added_inertia", "-1e-4"))
    err = error_of(path)
    assert_error(err, path, column="added_inertia", row=50)
    assert ">= 0" in str(err)


def test_added_inertia_varies_within_run(tmp_path):
    path = write_lines(tmp_path / "vary.csv", set_cell(log_lines(), 50, "added_inertia", "2e-4"))
    err = error_of(path)
    assert_error(err, path, column="added_inertia", row=50)
    assert "constant" in str(err)


def test_run_without_motion_is_kept(tmp_path):
    lines = log_lines((("a", "s", 0.0), ("still", "s", 0.0)))
    for row in range(42, 82):  # run 'still' jitters by one encoder step only
        lines = set_cell(lines, row, "theta", repr(0.1 + Q * (row % 2)))
    path = write_lines(tmp_path / "still.csv", lines)
    log = read_log(path)
    assert [r.name for r in log.runs] == ["a", "still"]
    assert len(log.notes) == 1 and "'still'" in log.notes[0] and "never move" in log.notes[0]


def test_log_without_motion(tmp_path):
    lines = log_lines((("a", "s", 0.0), ("still", "s", 0.0)))
    for row in range(2, 82):  # every run jitters by one encoder step only
        lines = set_cell(lines, row, "theta", repr(0.1 + Q * (row % 2)))
    path = write_lines(tmp_path / "still.csv", lines)
    err = error_of(path)
    assert_error(err, path, column="theta", row=2)
    assert "no run shows motion" in str(err)


def test_log_without_motion_unquantized(tmp_path):
    lines = ["time,theta,run"]
    lines += [f"{i * DT!r},0.1,a" for i in range(30)]
    lines += [f"{i * DT!r},0.25,b" for i in range(30)]
    path = write_lines(tmp_path / "flat.csv", lines)
    err = error_of(path)
    assert_error(err, path, column="theta", row=2)
    assert "no run shows motion" in str(err) and "1e-09 rad" in str(err)
    # one moving run makes the still one data
    lines[1:31] = [f"{i * DT!r},{0.1 * math.sin(i / 7.3)!r},a" for i in range(30)]
    log = read_log(write_lines(tmp_path / "flat2.csv", lines))
    assert "'b'" in log.notes[0]


def test_too_few_samples(tmp_path):
    lines = log_lines((("a", "s", 0.0),)) + ["b,s,0.0,0.1,0.0", "b,s,0.004,0.12,0.0"]
    path = write_lines(tmp_path / "short.csv", lines)
    err = error_of(path)
    assert_error(err, path, column="run", row=42)
    assert "'b'" in str(err) and "only 2" in str(err)


def test_counts_without_scale(tmp_path):
    path = write_lines(tmp_path / "raw.csv", log_lines(counts=True))
    err = error_of(path)
    assert_error(err, path, column="theta")
    assert "--counts-per-rev" in str(err) and "raw encoder counts" in str(err)
    lines = log_lines(counts=True)
    lines[0] = lines[0].replace("theta", "counts")
    path2 = write_lines(tmp_path / "raw2.csv", lines)
    err2 = error_of(path2)
    assert_error(err2, path2, column="counts")
    assert "--counts-per-rev" in str(err2)


def test_counts_per_rev_with_radians(tmp_path):
    path = write_lines(tmp_path / "rad.csv", log_lines(offset=0.01))
    err = error_of(path, counts_per_rev=CPR)
    assert_error(err, path, column="theta", row=2)
    assert "drop --counts-per-rev" in str(err)


@pytest.mark.parametrize(
    "kwargs", [{"counts_per_rev": 0}, {"counts_per_rev": -5.0}, {"period_tolerance": 0.0}]
)
def test_bad_arguments(good, kwargs):
    assert good[0].name in str(error_of(good[0], **kwargs))


def test_large_log_loads_fast(tmp_path):
    import time

    n = 100_000
    t = np.arange(n) * DT
    theta = Q * np.rint(0.157 * np.exp(-t / 50) * np.cos(t) / Q)
    path = tmp_path / "big.csv"
    write_log(path, [Run("1", t, theta)])
    start = time.perf_counter()
    log = read_log(path)
    assert time.perf_counter() - start < 2.0  # typically ~0.15 s
    assert log.n_samples == n and log.resolution == pytest.approx(Q, rel=1e-9)


# ----------------------------------------------------------------- property test


def _corrupt(lines: list[str], data: st.DataObject) -> list[str]:
    lines = list(lines)
    kind = data.draw(
        st.sampled_from(
            ["blank", "text", "swap_time", "drop_col", "dup_row", "inf", "header", "del_row", "truncate"]
        )
    )
    rows = len(lines)
    width = len(lines[0].split(","))
    row = data.draw(st.integers(0, rows - 1))
    col = data.draw(st.integers(0, width - 1))

    def put(r: int, c: int, value: str) -> None:
        cells = lines[r].split(",")
        if c < len(cells):
            cells[c] = value
        lines[r] = ",".join(cells)

    if kind == "blank":
        put(row, col, "")
    elif kind == "text":
        put(row, col, data.draw(st.text(st.characters(exclude_categories=("Cs",)), max_size=25)))
    elif kind == "inf":
        put(row, col, data.draw(st.sampled_from(["inf", "-inf", "Infinity", "1e400"])))
    elif kind == "swap_time" and rows > 2:
        names = lines[0].split(",")
        c = names.index("time") if "time" in names else col
        r1, r2 = data.draw(st.integers(1, rows - 1)), data.draw(st.integers(1, rows - 1))
        cells1, cells2 = lines[r1].split(","), lines[r2].split(",")
        if c < len(cells1) and c < len(cells2):  # an earlier "truncate" may have cut a row
            put(r1, c, cells2[c])
            put(r2, c, cells1[c])
    elif kind == "drop_col":
        lines = [",".join(x for i, x in enumerate(line.split(",")) if i != col) for line in lines]
    elif kind == "dup_row":
        lines.insert(row, lines[row])
    elif kind == "del_row":
        del lines[row]
    elif kind == "header":
        names = lines[0].split(",")
        how = data.draw(st.sampled_from(["shuffle", "mangle", "random"]))
        if how == "shuffle":
            names = data.draw(st.permutations(names))
        elif how == "mangle":
            name = names[col]
            names[col] = "".join(data.draw(st.permutations(list(name)))) if name else "x"
        else:
            names[col] = data.draw(st.text(max_size=10).filter(lambda s: "\x00" not in s))
        lines[0] = ",".join(names)
    elif kind == "truncate":
        text = "\n".join(lines)
        cut = data.draw(st.integers(0, len(text)))
        lines = text[:cut].split("\n")
    return lines


@settings(
    max_examples=150,
    deadline=None,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(
    data=st.data(),
    n_runs=st.integers(1, 3),
    n=st.integers(8, 30),
    counts=st.booleans(),
    setup=st.booleans(),
    inertia=st.booleans(),
    n_corruptions=st.integers(1, 3),
    pass_cpr=st.booleans(),
)
def test_corrupted_logs_fail_cleanly(
    tmp_path_factory, data, n_runs, n, counts, setup, inertia, n_corruptions, pass_cpr
):
    runs = tuple((f"r{k}", f"s{k % 2}", 1e-4 * k) for k in range(n_runs))
    lines = log_lines(runs, n, counts=counts, setup=setup, inertia=inertia)
    for _ in range(n_corruptions):
        if lines and lines[0]:
            lines = _corrupt(lines, data)
    path = tmp_path_factory.mktemp("prop") / "corrupted log.csv"
    path.write_bytes(("\n".join(lines) + "\n").encode("utf-8", errors="surrogatepass"))
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    try:
        log = read_log(path, counts_per_rev=CPR if pass_cpr else None)
    except LogError as err:
        msg = str(err)
        assert "\n" not in msg and "\r" not in msg
        assert str(path) in msg
    else:
        assert log.n_samples >= 8 and len(log.runs) >= 1
        for run in log.runs:
            assert np.all(np.diff(run.time) > 0)
            assert np.all(np.isfinite(run.theta))
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before
