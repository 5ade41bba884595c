"""Logs as test-station software writes them: its clock, its number format, its layout.

Each file is re-printed from a shipped log (or, for a 4 kHz logger, a log of the reference
simulator) as a station writes it: a 16-bit millisecond or 32-bit microsecond timer that
rolls over, stamps coarser than the sampling (4 kHz stamped to 1 ms), runs interleaved
row by row or side by side in one column each, a reading the logger missed, digit
grouping, a time of day past midnight or with a decimal comma, a LabVIEW ``.lvm`` file, a
``Position`` header, an Excel workbook. Either it reads to the same log as the original
(the same runs, samples, readings and encoder step: the fit is a function of the log) or
it ends with one line naming the row and the fix. Each test failed on the reader before
this file, except those marked as guards (what must stay an error).
"""

from __future__ import annotations

import sys

import numpy as np
import pandas as pd
import pytest

from hdid import LogError, read_log
from synthetic import SYNTH
from test_logger_files import assert_same_log

PAPER = SYNTH / "csf8_paper.csv"
COUNTS = SYNTH / "csf8_paper_counts.csv"
CPR = 4000  # the shipped counts log's encoder (data/synthetic/truth.json)


@pytest.fixture(scope="module")
def paper():
    return pd.read_csv(PAPER), read_log(PAPER)


@pytest.fixture(scope="module")
def counts():
    return pd.read_csv(COUNTS), read_log(COUNTS, counts_per_rev=CPR)


def _csv(path, frame: pd.DataFrame, *, sep: str = ",", fmt=None, header=None):
    """Write ``frame`` as a station does: each cell by ``fmt[column]`` (a format string or
    a function), the header as given."""
    fmt = fmt or {}
    cols = list(frame.columns)
    cells = [[(fmt[c](v) if callable(fmt.get(c)) else format(v, fmt.get(c, "")))
              for c, v in zip(cols, row)] for row in frame.itertuples(index=False)]
    head = header or sep.join(cols)
    path.write_text(head + "\n" + "".join(sep.join(r) + "\n" for r in cells))
    return path


def _note(log, text: str) -> str:
    hits = [n for n in log.notes if text in n]
    assert hits, log.notes
    return hits[0]


# ------------------------------------------------------------------ the logger's clock

def test_a_16_bit_millisecond_timer_that_rolls_over(tmp_path, counts):
    """A free-running uint16 ms timer (0 … 65 535) stamps every run: it wraps to 0 inside
    run 2. Read as written, time drops back by 65 532 ms inside a labelled run (an error
    before); undone, the step is the usual 4 ms."""
    frame, ref = counts
    ms = np.rint(frame["time"].to_numpy() * 1e3).astype(np.int64)
    start = np.flatnonzero(frame["run"].diff().fillna(0).to_numpy() != 0)
    ms = ms + 65_000 + 300 * np.searchsorted(start, np.arange(ms.size), side="right")
    out = frame.assign(time=ms % 65_536).rename(columns={"time": "time [ms]"})
    log = read_log(_csv(tmp_path / "timer.csv", out), counts_per_rev=CPR)
    assert_same_log(log, ref, time_tol=1e-9)
    assert "16-bit timer rolls over" in _note(log, "timer")


def test_a_32_bit_microsecond_timer_wraps_inside_a_run_without_run_column(tmp_path, paper):
    """One run stamped by a uint32 us timer that wraps mid-motion: one run, not two (a
    clock restart, which it read as before, splits the release in two)."""
    frame, ref = paper
    run1 = frame[frame["run"] == 1]
    us = (np.rint(run1["time"].to_numpy() * 1e6).astype(np.int64) + 2**32 - 250_000) % 2**32
    out = pd.DataFrame({"time [us]": us, "theta": run1["theta"].to_numpy()})
    log = read_log(_csv(tmp_path / "us.csv", out, fmt={"theta": ".12g"}))
    assert [r.n_samples for r in log.runs] == [ref.runs[0].n_samples]
    np.testing.assert_allclose(np.diff(log.runs[0].time), np.diff(ref.runs[0].time),
                               rtol=0, atol=1e-9)  # whole microseconds, exact
    assert "32-bit timer" in _note(log, "timer")


def test_a_millisecond_timer_printed_in_seconds_that_rolls_over(tmp_path, paper):
    """The same uint16 ms timer written as seconds (``65.532``, then ``0.000``): its tick is
    the printed 0.001 s, its length 65.536 s."""
    frame, ref = paper
    ms = np.rint(frame["time"].to_numpy() * 1e3).astype(np.int64)
    ms = (ms + 65_300 + 700 * (frame["run"].to_numpy() - 1)) % 65_536
    out = frame.assign(time=[f"{v / 1e3:.3f}" for v in ms])
    log = read_log(_csv(tmp_path / "sec.csv", out, fmt={"theta": ".12g"}))
    assert_same_log(log, ref, time_tol=1e-9)
    _note(log, "16-bit timer")


def test_a_timer_wrap_and_a_clock_restart_are_told_apart(tmp_path, paper):
    """No run column: run 1's ms timer wraps (65 535 → 0), then the clock is restarted at
    run 2's release (back to 0 from mid-range). The wrap continues the run; the restart
    starts one: two runs, each whole."""
    frame, ref = paper
    parts = []
    for k, start in ((1, 65_300), (2, 0)):
        run = frame[frame["run"] == k]
        ms = (np.rint(run["time"].to_numpy() * 1e3).astype(np.int64) + start) % 65_536
        parts.append(pd.DataFrame({"time [ms]": ms, "theta": run["theta"].to_numpy()}))
    log = read_log(_csv(tmp_path / "both.csv", pd.concat(parts), fmt={"theta": ".12g"}))
    assert [r.n_samples for r in log.runs] == [r.n_samples for r in ref.runs[:2]]
    for a, b in zip(log.runs, ref.runs[:2]):
        np.testing.assert_allclose(a.theta, b.theta, rtol=0, atol=1e-12)
    _note(log, "timer rolls over")
    _note(log, "time restarts")


@pytest.fixture(scope="module")
def fast_log():
    """The paper plant logged at 4 kHz (reference simulator; 2 runs of 0.3 s)."""
    from hdid.reference import logs
    return logs.make_log(logs.TRUTH_CSF8, [0.157, -0.12], 4000.0, 0.3, 0.02, {"A": 0.0}, 5)


def test_4khz_samples_stamped_to_the_millisecond(tmp_path, fast_log):
    """A 4 kHz logger stamping each sample to 1 ms writes every time four times with
    different readings (an error before: two samples at one instant). The stamps lie
    within one print unit of uniform steps, so time is rebuilt from them."""
    ref = read_log(_csv(tmp_path / "ref.csv", fast_log, fmt={"time": ".12g", "theta": ".12g"}))
    ms = np.floor(fast_log["time"].to_numpy() * 1e3 + 1e-9).astype(np.int64)
    stamped = fast_log.assign(time=ms).rename(columns={"time": "time [ms]"})
    log = read_log(_csv(tmp_path / "ms.csv", stamped, fmt={"theta": ".12g"}))
    # the step is fitted to 2 x 1200 stamps cut to 1 ms: its error ~ 1 ms/sqrt(12) over
    # sqrt(sum of (k - mean k)^2) ~ 0.29 ms / 1e4 = 3e-8 s per step, 3e-5 s over a run;
    # 1e-4 s is a tenth of one stamp (the stamps alone are 1 ms coarse)
    assert_same_log(log, ref, time_tol=1e-4)
    assert log.sample_period == pytest.approx(2.5e-4, rel=1e-3)
    _note(log, "rebuilt")


def test_4khz_ms_stamps_with_a_restarted_clock_and_no_run_column(tmp_path, fast_log):
    """The same stamps without a ``run`` column, the clock restarted at each release: each
    stretch is rebuilt before rows that repeat (a held reading stamped twice) could be
    taken as written twice, then split at the restart."""
    ms = np.floor(fast_log["time"].to_numpy() * 1e3 + 1e-9).astype(np.int64)
    out = pd.DataFrame({"time [ms]": ms, "theta": fast_log["theta"].to_numpy()})
    log = read_log(_csv(tmp_path / "restart.csv", out, fmt={"theta": ".12g"}))
    assert [r.n_samples for r in log.runs] == fast_log.groupby("run").size().tolist()
    _note(log, "rebuilt")
    _note(log, "time restarts")


def test_a_repeated_stamp_in_a_slower_log_stays_an_error(tmp_path, paper):
    """Guard: a 250 Hz log stamped to 1 ms with one stamp written twice is no faster
    logger (its steps are 4 print units): the row is named."""
    frame = paper[0][paper[0]["run"] == 1].copy()
    ms = np.rint(frame["time"].to_numpy() * 1e3).astype(np.int64)
    ms[13] = ms[12]  # in the motion: the two readings differ
    out = pd.DataFrame({"time [ms]": ms, "theta": frame["theta"].to_numpy()})
    with pytest.raises(LogError) as err:
        read_log(_csv(tmp_path / "glitch.csv", out, fmt={"theta": ".12g"}))
    assert err.value.row == 15 and "two samples at one instant" in str(err.value)


def test_a_time_of_day_that_crosses_midnight(tmp_path, paper):
    """Times of day (hh:mm:ss.fff) of a run that passes midnight: 23:59:59.996 is followed
    by 00:00:00.000 (before: time dropped back by a day inside the run)."""
    frame, ref = paper

    def clock(sec):
        sec = sec % 86_400
        return f"{int(sec // 3600):02d}:{int(sec % 3600 // 60):02d}:{sec % 60:06.3f}"

    runs = frame["run"].to_numpy()
    sec = 86_400 - 0.3 + frame["time"].to_numpy() + 0.7 * (runs - 1)  # run 1 crosses
    out = frame.assign(time=[clock(s) for s in sec])
    log = read_log(_csv(tmp_path / "midnight.csv", out, fmt={"theta": ".12g"}))
    assert_same_log(log, ref, time_tol=1e-9)  # stamps to the millisecond, 4 ms steps


# ------------------------------------------------------------------ the layout

def test_runs_interleaved_row_by_row(tmp_path, paper):
    """Two stations logged into one file, each row labelled by its run: the rows are
    grouped by run, each in file order (an error before)."""
    frame, ref = paper
    order = np.lexsort((frame["run"].to_numpy(), frame.groupby("run").cumcount().to_numpy()))
    log = read_log(_csv(tmp_path / "inter.csv", frame.iloc[order],
                        fmt={"time": ".12g", "theta": ".12g"}))
    assert_same_log(log, ref)
    _note(log, "interleaved")


def test_interleaved_rows_whose_time_drops_stay_an_error(tmp_path, paper):
    """Guard: interleaved runs one of which has time that drops are out of order, not
    interleaved: the time check names the row."""
    frame = paper[0]
    order = np.lexsort((frame["run"].to_numpy(), frame.groupby("run").cumcount().to_numpy()))
    out = frame.iloc[order].reset_index(drop=True)
    out.loc[20, "time"], out.loc[24, "time"] = out.loc[24, "time"], out.loc[20, "time"]
    with pytest.raises(LogError):
        read_log(_csv(tmp_path / "bad.csv", out, fmt={"time": ".12g", "theta": ".12g"}))


def test_one_column_per_run_side_by_side(tmp_path, paper):
    """A wide export: a time column and one angle column per run (``theta_1 [deg]`` …),
    the last run shorter (its cells below are empty): read as runs '1' … '4'."""
    frame, ref = paper
    wide = pd.DataFrame({"time [s]": frame[frame["run"] == 1]["time"].to_numpy()})
    for k, run in frame.groupby("run"):
        cells = [f"{v:.12g}" for v in np.degrees(run["theta"].to_numpy())]
        if k == 4:
            cells[-5:] = [""] * 5
        wide[f"theta_{k} [deg]"] = cells
    log = read_log(_csv(tmp_path / "wide.csv", wide, fmt={"time [s]": ".12g"}))
    assert [r.name for r in log.runs] == ["1", "2", "3", "4"]
    assert [r.n_samples for r in log.runs] == [r.n_samples for r in ref.runs[:3]] + [
        ref.runs[3].n_samples - 5]
    for a, b in zip(log.runs, ref.runs):
        np.testing.assert_allclose(a.theta, b.theta[:a.n_samples], rtol=0, atol=1e-12)
    _note(log, "one angle column per run")


def test_one_column_per_run_below_a_text_preamble(tmp_path, paper):
    """The wide export under a station's preamble (``Operator: kb``, a blank line): the
    header is the line naming a time and the per-run angle columns, not the first text
    line (read before as a 2-cell header: 'row 4 has 5 cells')."""
    frame, ref = paper
    wide = pd.DataFrame({"time [s]": frame[frame["run"] == 1]["time"].to_numpy()})
    for k, run in frame.groupby("run"):
        wide[f"theta_{k} [deg]"] = [f"{v:.12g}" for v in np.degrees(run["theta"].to_numpy())]
    path = _csv(tmp_path / "wide.csv", wide, sep="\t", fmt={"time [s]": ".12g"})
    path.write_text("# station 2, test rig\nOperator: kb\n\n" + path.read_text())
    log = read_log(path)
    assert [r.name for r in log.runs] == ["1", "2", "3", "4"]
    for a, b in zip(log.runs, ref.runs):  # the same readings (12 digits printed)
        np.testing.assert_allclose(a.theta, b.theta, rtol=0, atol=1e-12)


def test_one_column_per_run_with_its_units_in_a_units_row(tmp_path, paper):
    """The wide export with bare names (``time, theta_1, theta_2``) and a units row
    (``ms, deg, deg``): each run's column takes the row's angle unit. Before, the units
    row set only the time's unit and the degrees were read as radians (57x the swing;
    the fit diverged)."""
    frame, ref = paper
    wide = pd.DataFrame({"time": frame[frame["run"] == 1]["time"].to_numpy() * 1e3})
    for k, run in frame.groupby("run"):
        wide[f"theta_{k}"] = [f"{v:.12g}" for v in np.degrees(run["theta"].to_numpy())]
    units = ",".join(["ms"] + ["deg"] * 4)
    path = _csv(tmp_path / "wide.csv", wide, fmt={"time": ".12g"})
    head, body = path.read_text().split("\n", 1)
    path.write_text(head + "\n" + units + "\n" + body)
    log = read_log(path)
    assert [r.name for r in log.runs] == ["1", "2", "3", "4"]
    for a, b in zip(log.runs, ref.runs):  # the same readings (12 digits printed)
        np.testing.assert_allclose(a.theta, b.theta, rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.time, b.time, rtol=0, atol=1e-12)


def test_a_fine_encoder_sampled_slowly_still_tells_its_step(tmp_path):
    """2^17 counts/rev at 250 Hz on a 57 Hz gear: each release swings through six samples
    before it sticks, so no two levels of a run lie closer than hundreds of counts (more
    than the 64 divisors of the closest gap tried before: 'the readings lie on no grid',
    and the noise taken as 6x the floor). Printed to 1e-7 deg, the runs' two dozen levels tell
    the grid: a wrong one passes all by chance with probability ~(2e-9/4.8e-5) per level."""
    from hdid._log._resolution import MAX_STEP_DIVISOR
    q = 2 * np.pi / 2**17
    t = np.arange(40) / 250.0
    rows = []
    for k, (a, band) in enumerate([(0.3, 0.06), (-0.3, 0.05), (0.21, 0.04), (-0.17, 0.03)]):
        swing = a * np.cos(2 * np.pi * 57 * t) * np.exp(-9 * t)
        swing[t >= 6 / 250] = swing[5]  # stuck after six samples
        theta = np.round((np.concatenate([[a] * 3, swing]) + 1.2345) / q)  # counts
        rows += [(k + 1, i * 4.0, f"{np.degrees(c * q):.7f}") for i, c in enumerate(theta)]
        gaps = np.diff(np.unique(theta))
        assert gaps.min() > MAX_STEP_DIVISOR  # the case: no close levels in any run
    path = tmp_path / "sparse.csv"
    body = "".join(f"{r},{t:.3f},{v}\n" for r, t, v in rows)
    path.write_text("run,time [ms],theta [deg]\n" + body)
    log = read_log(path)
    # the printing (1e-7 deg = 1.7e-9 rad) bounds the step's error far below 1e-4 of it
    assert log.resolution == pytest.approx(q, rel=1e-4)


def test_an_encoder_step_48_print_units_wide_is_told(tmp_path):
    """2^17 counts/rev printed to 1e-6 rad (the step is 48 print units), the middle level
    thousands of counts from the others (a stuck tail between the swing's extremes): the
    closest gap's interval (±2 %) places no difference from the middle level, so the grid
    was 'not told from chance'. The gaps between neighbouring levels (1, 2, 4, … counts)
    narrow the interval first; a wrong grid passes each level with chance ~2e-6/4.8e-5."""
    q = 2 * np.pi / 2**17
    ladder = 3000 + np.cumsum([0, 1, 2, 4, 8, 16, 32, 64, 128, 256, 512])
    counts = np.concatenate([-ladder[::-1], [0], ladder + 7])
    theta = (counts + 17_000) * q
    body = "".join(f"{0.004 * i:.3f},{v:.6f}\n" for i, v in enumerate(theta))
    path = tmp_path / "rad6.csv"
    path.write_text("time,theta\n" + body)
    # the printing (5e-7 rad a reading) over differences of ~4000 steps: rel. 1e-5
    assert read_log(path).resolution == pytest.approx(q, rel=1e-4)


def test_a_reading_the_logger_missed_is_dropped(tmp_path, paper):
    """An empty cell and a 'NaN' with their times (failed reads) are dropped samples, named
    in a note (an error before); two misses in a row stay the error naming the first."""
    frame, ref = paper
    out = frame.assign(theta=[f"{v:.12g}" for v in frame["theta"]])
    out.loc[40, "theta"], out.loc[300, "theta"] = "", "NaN"
    log = read_log(_csv(tmp_path / "miss.csv", out, fmt={"time": ".12g"}))
    assert [r.n_samples for r in log.runs] == [125 - 1, 125, 125 - 1, 125]
    assert "row(s) 42, 302" in _note(log, "no reading")
    assert log.resolution == pytest.approx(ref.resolution, rel=1e-9)
    out.loc[41, "theta"] = ""
    with pytest.raises(LogError) as err:
        read_log(_csv(tmp_path / "miss2.csv", out, fmt={"time": ".12g"}))
    assert err.value.row == 42 and err.value.column == "theta"


def test_a_driven_row_without_its_reading_stays_an_error(tmp_path):
    """Guard: a driven row's motor torque acts until the next row, so the row is not
    dropped (it would change the input): the empty cell is named."""
    lines = (SYNTH / "driven_csf8.csv").read_text().splitlines()
    cells = lines[40].split(",")
    cells[2] = ""  # theta
    lines[40] = ",".join(cells)
    path = tmp_path / "driven.csv"
    path.write_text("\n".join(lines) + "\n")
    with pytest.raises(LogError) as err:
        read_log(path)
    assert err.value.row == 41 and err.value.column == "theta"


def test_an_infinite_reading_stays_an_error(tmp_path, paper):
    """Guard: 'inf' is no missed read (an overflow, a parse of garbage): named."""
    out = paper[0].assign(theta=[f"{v:.12g}" for v in paper[0]["theta"]])
    out.loc[40, "theta"] = "inf"
    with pytest.raises(LogError) as err:
        read_log(_csv(tmp_path / "inf.csv", out, fmt={"time": ".12g"}))
    assert err.value.row == 42 and "infinite" in str(err.value)


# ------------------------------------------------------------------ the number format

def test_digit_grouping_in_a_tab_separated_export(tmp_path, counts):
    """Counts written with thousands separators (``12,108``) in a tab-separated file whose
    time shows a decimal point (``4.0``): the commas group digits (before: read as decimal
    commas, 12.108 counts)."""
    frame, ref = counts
    out = frame.assign(theta=frame["theta"] + 12_000, time=frame["time"] * 1e3)
    out = out.rename(columns={"time": "time [ms]"})
    log = read_log(_csv(tmp_path / "grouped.tsv", out, sep="\t",
                        fmt={"time [ms]": ",.1f", "theta": ",d"}), counts_per_rev=CPR)
    assert_same_log(log, ref, time_tol=1e-9, theta_offset=True)


def test_counts_grouped_where_no_number_shows_its_decimal_separator(tmp_path, counts):
    """Counts ``12,108`` in a tab file whose other numbers are whole too: the comma may be
    a decimal comma (a European export) or a grouping mark, and is read as the decimal, as
    before; the error then says how to write the counts."""
    frame, _ = counts
    out = frame.assign(theta=frame["theta"] + 12_000, time=np.rint(frame["time"] * 1e3))
    out = out.rename(columns={"time": "time [ms]"})
    with pytest.raises(LogError) as err:
        read_log(_csv(tmp_path / "grouped.tsv", out, sep="\t",
                      fmt={"time [ms]": ".0f", "theta": ",d"}), counts_per_rev=CPR)
    assert err.value.row == 2 and "without digit grouping" in str(err.value)


def test_european_grouping_and_decimal_comma(tmp_path, paper):
    """A ';' export with '.' grouping digits and ',' the decimal (``1.004,0`` ms):
    before, the grouped cells were text."""
    frame, ref = paper
    out = frame.assign(time=frame["time"] * 1e3 + 996.0).rename(columns={"time": "time [ms]"})

    def european(v):
        return f"{v:,.1f}".replace(",", " ").replace(".", ",").replace(" ", ".")

    log = read_log(_csv(tmp_path / "eu.csv", out, sep=";",
                        fmt={"time [ms]": european, "theta": lambda v: f"{v:.12g}".replace(
                            ".", ",")}))
    assert_same_log(log, ref, time_tol=1e-9)


def test_a_time_of_day_with_a_decimal_comma(tmp_path, paper):
    """``10:00:00,004`` in a tab-separated European export (before: text, an error)."""
    frame, ref = paper
    sec = 36_000 + frame["time"].to_numpy() + 0.7 * (frame["run"].to_numpy() - 1)
    stamps = [f"{int(s // 3600):02d}:{int(s % 3600 // 60):02d}:{s % 60:06.3f}".replace(".", ",")
              for s in sec]
    out = frame.assign(time=stamps, theta=[f"{v:.12g}".replace(".", ",") for v in frame["theta"]])
    log = read_log(_csv(tmp_path / "clock.txt", out, sep="\t"))
    assert_same_log(log, ref, time_tol=1e-9)


# ------------------------------------------------------------------ names and files

@pytest.mark.parametrize("header", ["pos [deg]", "Position (deg)"])
def test_a_position_column_is_the_angle(tmp_path, paper, header):
    frame, ref = paper
    out = frame.assign(theta=np.degrees(frame["theta"])).rename(columns={"theta": header})
    log = read_log(_csv(tmp_path / "pos.csv", out, fmt={"time": ".12g", header: ".17g"}))
    assert_same_log(log, ref)


def test_theta_wins_over_a_position_column(tmp_path, paper):
    """Guard: a log with both ``theta`` and ``position`` (a drive's other signal) reads
    ``theta``, not an error about a column appearing twice nor the position."""
    frame, ref = paper
    out = frame.assign(position=99.0)
    log = read_log(_csv(tmp_path / "both.csv", out, fmt={"time": ".12g", "theta": ".12g"}))
    assert_same_log(log, ref)


def test_a_labview_lvm_file(tmp_path, paper):
    """LabVIEW's measurement file: a header block and a channel block, each ended by
    ``***End_of_Header***``, then ``X_Value`` (time), the channels and a ``Comment``
    column (before: the header was not found)."""
    frame, ref = paper
    run = frame[frame["run"] == 1]
    head = ("LabVIEW Measurement\t\nWriter_Version\t2\nSeparator\tTab\nDecimal_Separator\t.\n"
            "X_Columns\tOne\n***End_of_Header***\t\n\nChannels\t1\t\nSamples\t125\t\n"
            "X_Dimension\tTime\t\nDelta_X\t0.004000\t\n***End_of_Header***\t\t\n"
            "X_Value\ttheta\tComment\n")
    body = "".join(f"{t:.6f}\t{v:.12g}\n" for t, v in zip(run["time"], run["theta"]))
    path = tmp_path / "bench.lvm"
    path.write_text(head + body)
    log = read_log(path)
    assert [r.n_samples for r in log.runs] == [ref.runs[0].n_samples]
    np.testing.assert_allclose(log.runs[0].theta, ref.runs[0].theta, rtol=0, atol=1e-12)


def _lvm_segment(run, x_value: str) -> str:
    """One segment of an .lvm file: the channel header (X0, Delta_X) and the samples, the
    X_Value column written empty (``"empty"``) or not at all (``"absent"``)."""
    head = ("Channels\t1\t\nSamples\t%d\t\nX_Dimension\tTime\t\nX0\t0.0000000000000000E+0\t\n"
            "Delta_X\t0.004000\t\n***End_of_Header***\t\t\n" % len(run))
    if x_value == "empty":
        return head + "X_Value\ttheta\tComment\n" + "".join(f"\t{v:.12g}\n" for v in run)
    return head + "theta\tComment\n" + "".join(f"{v:.12g}\n" for v in run)


@pytest.mark.parametrize("x_value", ["empty", "absent"])
def test_a_labview_file_whose_rows_lack_their_times(tmp_path, paper, x_value):
    """LabVIEW's "Empty time column" (X_Value cells left empty) and ``X_Columns No`` (no
    X_Value column): each sample's time is X0 + k·Delta_X of its segment's header; two
    segments, two runs (before: an empty cell, or no time column)."""
    frame, ref = paper
    head = ("LabVIEW Measurement\t\nWriter_Version\t2\nSeparator\tTab\nDecimal_Separator\t.\n"
            f"X_Columns\t{'One' if x_value == 'empty' else 'No'}\n***End_of_Header***\t\n\n")
    body = "".join(_lvm_segment(frame[frame["run"] == k]["theta"].to_numpy(), x_value)
                   for k in (1, 2))
    path = tmp_path / "bench.lvm"
    path.write_text(head + body)
    log = read_log(path)
    assert [r.n_samples for r in log.runs] == [r.n_samples for r in ref.runs[:2]]
    for a, b in zip(log.runs, ref.runs[:2]):
        np.testing.assert_allclose(a.time - a.time[0], b.time - b.time[0], rtol=0, atol=1e-12)
        np.testing.assert_allclose(a.theta, b.theta, rtol=0, atol=1e-12)


def test_an_excel_workbook(tmp_path, paper):
    pytest.importorskip("openpyxl")
    frame, ref = paper
    path = tmp_path / "log.xlsx"
    frame.to_excel(path, index=False)
    assert_same_log(read_log(path), ref)


def test_an_excel_workbook_without_openpyxl_says_how(tmp_path, monkeypatch):
    """Without the optional reader, one line: install openpyxl or export CSV."""
    path = tmp_path / "log.xlsx"
    path.write_bytes(b"PK\x03\x04" + bytes(64))
    monkeypatch.setitem(sys.modules, "openpyxl", None)
    with pytest.raises(LogError) as err:
        read_log(path)
    msg = str(err.value)
    assert "log.xlsx" in msg and "pip install openpyxl" in msg and "\n" not in msg


def test_hdid_fit_on_a_workbook_without_openpyxl_is_one_line_exit_2(tmp_path):
    """The command line, as a user without openpyxl runs it: exit 2, one line naming the
    file and the fix, no traceback (the library's error above, through the CLI)."""
    import subprocess

    from synthetic import ROOT

    path = tmp_path / "log.xlsx"
    path.write_bytes(b"PK\x03\x04" + bytes(64))
    code = ("import sys, runpy; sys.modules['openpyxl'] = None; "
            "sys.argv = ['hdid'] + sys.argv[1:]; runpy.run_module('hdid.cli', run_name='__main__')")
    proc = subprocess.run([sys.executable, "-c", code, "fit", str(path)], capture_output=True,
                          text=True, cwd=ROOT)
    assert proc.returncode == 2, proc.stderr
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "log.xlsx" in lines[0] and "pip install openpyxl" in lines[0]
