"""Logs written the way real loggers, spreadsheets and controllers write them.

Each variant is written from a shipped log (``data/synthetic``) as a test station would
write it: a preamble above the header, ``#`` comments and a footer, a units row under the
header, logs written one after another, space-separated cells, unit suffixes in the names
(``time_ms``, ``t[s]``, ``time [ns]``), a 16- or 32-bit count register that rolls over, a
counter zeroed at each release, ISO 8601 date-times, a last line cut mid-write, a gzip or
MATLAB ``.mat`` file. Either it reads to the same log as the original — the same runs, samples,
readings and encoder step, so the fit (a deterministic function of the log) is the same
physics, which one end-to-end ``hdid fit`` checks — or it ends with one line naming the
file, the row or column, and the fix.
"""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pandas as pd
import pytest

from hdid import LogError, read_log
from synthetic import ROOT, SYNTH

PAPER = SYNTH / "csf8_paper.csv"
COUNTS = SYNTH / "csf8_paper_counts.csv"
RICH = SYNTH / "csf8_rich_1khz.csv"
CPR = 4000  # the shipped counts log's encoder (data/synthetic/truth.json)


def assert_same_log(log, ref, *, time_tol: float = 1e-12, theta_offset: bool = False):
    """Same runs, samples, readings (up to one constant, for ``theta_offset``: a counter's
    other zero) and encoder step; each run's time may start elsewhere (only differences
    enter the fit)."""
    assert [r.n_samples for r in log.runs] == [r.n_samples for r in ref.runs]
    assert [r.setup for r in log.runs] == [r.setup for r in ref.runs]
    shift = log.runs[0].theta[0] - ref.runs[0].theta[0] if theta_offset else 0.0
    for a, b in zip(log.runs, ref.runs):
        np.testing.assert_allclose(a.time - a.time[0], b.time - b.time[0], rtol=0,
                                   atol=time_tol)
        # float64 rounding of the unit conversions (degrees, ms) and of readings far from
        # zero (a 32-bit counter's 3e6 rad): a few units in the last place of the largest
        atol = 8 * np.finfo(float).eps * max(1.0, float(np.max(np.abs(a.theta))))
        np.testing.assert_allclose(a.theta - shift, b.theta, rtol=1e-12, atol=atol)
    assert log.resolution == pytest.approx(ref.resolution, rel=1e-9)


@pytest.fixture(scope="module")
def paper():
    return PAPER.read_text(), pd.read_csv(PAPER), read_log(PAPER)


@pytest.fixture(scope="module")
def counts():
    return pd.read_csv(COUNTS), read_log(COUNTS, counts_per_rev=CPR)


def _write(path, text: str, *, bom: bool = False, crlf: bool = False):
    if crlf:
        text = text.replace("\n", "\r\n")
    path.write_bytes((("\ufeff" if bom else "") + text).encode())
    return path


# ------------------------------------------------------------ the table in the text

#: (name, the original text → the variant's text, write options). Each of these failed on
#: the reader before this file: a preamble was taken as the header, a units row as a row
#: of empty cells, a whitespace-only line as a row, a footer comment as a row.
LAYOUTS = {
    "hash preamble": (lambda t: "# station 4, 2026-11-27\n# operator: kb\n" + t, {}),
    "text preamble, CRLF, BOM": (lambda t: "Station 4\nDate: 2026-11-27\n\n" + t,
                                 dict(bom=True, crlf=True)),
    "preamble, ';' and decimal commas": (
        lambda t: "# station 4; bench B\n" + t.replace(",", ";").replace(".", ","), {}),
    "units row": (lambda t: t.replace("theta\n", "theta\n,,s,rad\n", 1), {}),
    "units row in brackets, tab": (
        lambda t: t.replace("theta\n", "theta\n\t\t[s]\t[rad]\n", 1).replace(",", "\t"), {}),
    "Excel's sep= line": (lambda t: "sep=,\n" + t, {}),
    "a # footer without a line end": (lambda t: t + "# end of log", {}),
    "comments, whitespace lines and a footer": (
        lambda t: t.replace("\n2,", "\n# run 2 follows\n  \n2,").replace("\n3,", "\n\t\n3,")
        + "# end of log, 500 samples\n", {}),
}


@pytest.mark.parametrize("variant", LAYOUTS)
def test_layout_variants_read_to_the_same_log(tmp_path, paper, variant):
    text, _, ref = paper
    change, options = LAYOUTS[variant]
    log = read_log(_write(tmp_path / "log.csv", change(text), **options))
    assert_same_log(log, ref)
    assert log.notes == ref.notes


@pytest.mark.parametrize("footer", ["END\n", "Samples: 500\nEnd of data\n", ",,End,\n"])
def test_a_text_footer_is_dropped(tmp_path, paper, footer):
    """Words below the last row (no number in the row, or words for the time) are a
    footer: dropped with a note. A missing value there is still an error (it may be a lost
    sample)."""
    text, _, ref = paper
    log = read_log(_write(tmp_path / "footer.csv", text + footer))
    assert_same_log(log, ref)
    assert any("footer" in n and "row 502" in n for n in log.notes), log.notes
    with pytest.raises(LogError) as err:
        read_log(_write(tmp_path / "nan.csv", text + "4,B,NaN,NaN\n"))
    assert err.value.row == 502


def test_rows_are_numbered_in_the_file_below_a_preamble(tmp_path, paper):
    """Messages name the row as the file numbers it: 2 preamble lines move row 101 to 103."""
    text = paper[0]
    lines = text.splitlines()
    lines[100] = lines[100].rsplit(",", 1)[0] + ",0.1x"  # file row 101: theta no number
    path = _write(tmp_path / "hole.csv", "# station 4\nDate: x\n" + "\n".join(lines) + "\n")
    with pytest.raises(LogError) as err:
        read_log(path)
    assert err.value.row == 103 and err.value.column == "theta"
    lines = text.splitlines()
    lines[100] += ",9"  # an extra cell
    path = _write(tmp_path / "extra.csv", "# station 4\nDate: x\n" + "\n".join(lines) + "\n")
    with pytest.raises(LogError) as err:
        read_log(path)
    assert err.value.row == 103


def test_a_units_row_converts_its_column(tmp_path, paper):
    """``;;ms;deg`` under the header reads time in ms and theta in degrees."""
    _, frame, ref = paper
    d = frame.copy()
    d["time"] = (d["time"] * 1e3).round(6)
    d["theta"] = np.degrees(d["theta"])
    text = d.to_csv(index=False, sep=";", float_format="%.15g")
    text = text.replace("theta\n", "theta\n;;ms;deg\n", 1)
    assert_same_log(read_log(_write(tmp_path / "units.csv", text)), ref)


def test_an_unknown_unit_in_a_units_row_is_named(tmp_path, paper):
    text = paper[0].replace("theta\n", "theta\n,,s,furlong\n", 1)
    with pytest.raises(LogError) as err:
        read_log(_write(tmp_path / "u.csv", text))
    assert "furlong" in str(err.value) and "theta" in err.value.column


@pytest.mark.parametrize("with_run", [False, True])
def test_logs_written_one_after_another(tmp_path, paper, with_run):
    """``cat run1.csv run2.csv …``: each log brings its header (and byte-order mark).
    Without a run column each log is a run (time restarts in each); with one, the rows keep
    their labels. A note names the repeated headers."""
    _, frame, ref = paper
    parts = [frame[frame.run == r] if with_run else frame[frame.run == r].drop(columns="run")
             for r in (1, 2, 3, 4)]
    text = "".join(("\ufeff" if i else "") + p.to_csv(index=False) for i, p in enumerate(parts))
    log = read_log(_write(tmp_path / "cat.csv", text, bom=True, crlf=True))
    assert_same_log(log, ref)
    assert [r.name for r in log.runs] == ["1", "2", "3", "4"]
    assert [r.first_row for r in log.runs] == [2, 128, 254, 380]
    assert any("header repeats at row(s) 127, 253, 379" in n for n in log.notes), log.notes


@pytest.mark.parametrize("style", ["numpy.savetxt", "MATLAB % header, spaces"])
def test_a_header_written_as_a_comment(tmp_path, paper, style):
    """``numpy.savetxt(..., header='time,theta')`` writes ``# time,theta``; a MATLAB
    script may write ``% time [s] theta [rad]`` above space-separated columns."""
    _, frame, ref = paper
    data = frame.loc[frame.run == 1, ["time", "theta"]].to_numpy()  # one release
    path = tmp_path / "savetxt.csv"
    if style == "numpy.savetxt":
        np.savetxt(path, data, delimiter=",", header="time,theta", fmt="%.12g")
    else:
        np.savetxt(path, data, header="time [s]   theta [rad]", fmt="%.12g", comments="% ")
    log = read_log(path)
    assert len(log.runs) == 1
    np.testing.assert_array_equal(log.runs[0].theta, ref.runs[0].theta)


def test_a_gzip_compressed_log(tmp_path, paper):
    """A rotated, compressed log (``log.csv.gz``) reads as its text; cut short, it is named."""
    import gzip

    text, _, ref = paper
    packed = gzip.compress(text.encode())
    path = tmp_path / "log.csv.gz"
    path.write_bytes(packed)
    assert_same_log(read_log(path), ref)
    path.write_bytes(packed[: len(packed) // 2])
    with pytest.raises(LogError, match="gzip file is damaged or cut short"):
        read_log(path)


def test_space_separated_dat_file(tmp_path, paper):
    """A ``.dat`` export: cells separated by runs of spaces, lines indented, units in the
    header after a space (``time [s]``)."""
    _, frame, ref = paper
    text = frame.to_csv(index=False, sep=" ").replace("time theta", "time [s] theta (rad)")
    text = "   " + text.replace("\n", "\n   ")
    assert_same_log(read_log(_write(tmp_path / "log.dat", text)), ref)


# ------------------------------------------------------------ names and units

#: header of the time column, factor from seconds to its unit, printed decimals
TIME_NAMES = {
    "time_ms": (1e3, 6),
    "t[s]": (1.0, 6),
    "t": (1.0, 6),
    "t/s": (1.0, 6),
    "Time / ms": (1e3, 6),
    "Time_us": (1e6, 0),
    "time [ns]": (1e9, 0),
}


@pytest.mark.parametrize("header", TIME_NAMES)
def test_time_column_names_and_units(tmp_path, paper, header):
    _, frame, ref = paper
    factor, decimals = TIME_NAMES[header]
    d = frame.copy()
    d["time"] = (d["time"] * factor).round(decimals)
    if decimals == 0:
        d["time"] = d["time"].astype(np.int64)
    d = d.rename(columns={"time": header, "theta": "THETA_deg"})
    d["THETA_deg"] = np.degrees(d["THETA_deg"])
    path = tmp_path / "names.csv"
    d.to_csv(path, index=False, float_format="%.15g")
    assert_same_log(read_log(path), ref)


@pytest.mark.parametrize("header", ["theta [counts]", "Theta (cts)", "theta_counts"])
def test_an_angle_header_in_counts(tmp_path, counts, header):
    """``theta [counts]`` is raw counts: read with --counts-per-rev, and without it the
    error asks for it (it was an unknown unit)."""
    frame, ref = counts
    path = tmp_path / "cts.csv"
    frame.rename(columns={"theta": header}).to_csv(path, index=False)
    assert_same_log(read_log(path, counts_per_rev=CPR), ref)
    with pytest.raises(LogError, match="counts-per-rev"):
        read_log(path)


# ------------------------------------------------------------ time as loggers write it


@pytest.mark.parametrize("variant", ["iso", "iso with offset", "time of day"])
def test_date_times(tmp_path, paper, variant):
    """Each run 2 s after the last; date-times read as seconds after the first row."""
    _, frame, ref = paper
    d = frame.copy()
    seconds = d["time"] + 2.0 * (d["run"] - 1)
    stamps = pd.Timestamp("2026-11-27T10:00:00") + pd.to_timedelta(seconds, unit="s")
    form = "%H:%M:%S.%f" if variant == "time of day" else "%Y-%m-%dT%H:%M:%S.%f"
    d["time"] = stamps.dt.strftime(form)
    if variant == "iso with offset":
        d["time"] = d["time"] + "+01:00"
    path = tmp_path / "stamps.csv"
    d.to_csv(path, index=False)
    # microsecond printing of multiples of 4 ms: exact to the nanosecond
    assert_same_log(read_log(path), ref, time_tol=1e-9)


def test_a_cell_that_is_no_date_time_is_named(tmp_path, paper):
    _, frame, _ = paper
    d = frame.copy()
    stamps = pd.Timestamp("2026-11-27T10:00:00") + pd.to_timedelta(d["time"], unit="s")
    d["time"] = stamps.dt.strftime("%Y-%m-%d %H:%M:%S.%f")
    d.loc[40, "time"] = "overflow"
    path = tmp_path / "stamps.csv"
    d.to_csv(path, index=False)
    with pytest.raises(LogError) as err:
        read_log(path)
    assert err.value.row == 42 and err.value.column == "time" and "overflow" in str(err.value)


# ------------------------------------------------------------ count registers


#: (register offset added to the counts, how the register wraps) — offsets chosen so the
#: runs cross the register's end several times
ROLLOVERS = {
    "16-bit unsigned": (65_500, lambda c: c % 65_536),
    "16-bit signed": (32_700, lambda c: (c + 32_768) % 65_536 - 32_768),
    "32-bit signed": (2**31 - 50, lambda c: (c + 2**31) % 2**32 - 2**31),
    "16-bit signed, counting down": (-32_700, lambda c: (-c + 32_768) % 65_536 - 32_768),
}


@pytest.mark.parametrize("variant", ROLLOVERS)
def test_a_count_register_that_rolls_over_is_unwrapped(tmp_path, counts, variant):
    """Read as they stand, the counts after a wrap were 2**bits counts (16 or 2**20
    revolutions) away; unwrapped, every run keeps the set-up's one offset (the readings
    differ from the original by one constant across all runs) and a note names the wrap."""
    frame, ref = counts
    offset, wrap = ROLLOVERS[variant]
    d = frame.copy()
    raw = wrap(d["theta"].to_numpy(np.int64) + offset)
    assert np.any(np.abs(np.diff(raw)) > 30_000)  # the variant does wrap
    d["theta"] = raw
    path = tmp_path / "wrap.csv"
    d.to_csv(path, index=False)
    log = read_log(path, counts_per_rev=CPR)
    if "down" in variant:  # the counter counts the other way: the mirror image
        log_theta = [-r.theta for r in log.runs]
        shift = log_theta[0][0] - ref.runs[0].theta[0]
        for theta, r in zip(log_theta, ref.runs):
            np.testing.assert_allclose(theta - shift, r.theta, rtol=0, atol=1e-12)
    else:
        assert_same_log(log, ref, theta_offset=True)
    bits = variant.split("-")[0]
    assert any(f"{bits}-bit count register rolls over" in n for n in log.notes), log.notes


def test_an_output_count_register_that_rolls_over_is_unwrapped(tmp_path):
    """A driven log's output counts (2**19 per revolution) in a 32-bit register near its
    end: unwrapped like the input's, the output angle is the original's plus one constant."""
    out_cpr = 2**19
    d = pd.read_csv(SYNTH / "driven_csf8.csv")
    d["output_counts"] = np.rint(d.pop("theta_out") * out_cpr / (2 * np.pi)).astype(np.int64)
    plain = tmp_path / "plain.csv"
    d.to_csv(plain, index=False)
    d["output_counts"] = (d["output_counts"] + 2**31 - 5_000 + 2**31) % 2**32 - 2**31
    wrapped = tmp_path / "wrapped.csv"
    d.to_csv(wrapped, index=False)
    ref, log = (read_log(p, output_counts_per_rev=out_cpr) for p in (plain, wrapped))
    shift = log.runs[0].theta_out[0] - ref.runs[0].theta_out[0]
    for a, b in zip(log.runs, ref.runs):
        # readings near 2**31 counts (2.6e4 rad): a few units in the last place
        np.testing.assert_allclose(a.theta_out - shift, b.theta_out, rtol=0, atol=1e-10)
    assert any("'output_counts': the 32-bit count register" in n for n in log.notes)


def test_a_counter_zeroed_at_each_release_is_named(tmp_path, counts):
    """Every run starts at count 0 (the controller zeroed the counter at each release):
    runs 1 and 2 of set-up A are held at the same reading and move off it in opposite
    directions, which no spring does — one shared offset would fit nonsense (k1 came out
    at 3e-5 N m/rad instead of 940). The error names both runs and the fix; with each run
    its own set-up the log reads."""
    frame, _ = counts
    d = frame.copy()
    d["theta"] = d["theta"] - d.groupby("run")["theta"].transform("first")
    path = tmp_path / "zeroed.csv"
    d.to_csv(path, index=False)
    with pytest.raises(LogError) as err:
        read_log(path, counts_per_rev=CPR)
    assert "'1' and '2'" in str(err.value) and "own set-up" in str(err.value)
    assert err.value.row == 127  # run 2's first row
    d["setup"] = d["run"].astype(str)
    d.to_csv(path, index=False)
    assert len(read_log(path, counts_per_rev=CPR).runs) == 4


def test_a_fast_swing_is_no_wrap():
    """Only a step that the motion around it does not continue is a wrap: a fine encoder's
    fast swing whose readings happen to fit a 16-bit register, in steps of 34 000 counts
    between steps of 8 000 and 16 000, stays as read; a wrap between steps of 5 is undone."""
    from hdid._log._rollover import unwrap_rollover

    rows = np.arange(2, 8)
    swing = np.array([-30_000.0, -28_000, -20_000, 14_000, 30_000, 30_100])
    out, note = unwrap_rollover(swing, rows, "theta")
    assert note is None and np.array_equal(out, swing)
    wrapped = np.array([32_755.0, 32_760, 32_765, -32_766, -32_761, -32_756])
    out, note = unwrap_rollover(wrapped, rows, "theta")
    np.testing.assert_array_equal(np.diff(out), 5.0)
    assert "row(s) 5" in note


# ------------------------------------------------------------ single-turn angles


def _single_turn(frame, variant: str):
    """The log as a single-turn absolute encoder reads it, with the set-up's rest moved
    next to the wrap point (so the runs swing across it): counts in [0, cpr), radians in
    [-pi, pi), degrees in [0, 360)."""
    d = frame.copy()
    if variant == "counts [0, cpr)":
        d["theta"] = (d["theta"] + CPR - 20) % CPR  # rests 10-50 counts from the wrap
        return d
    if variant == "rad [-pi, pi)":
        d["theta"] = (d["theta"] + 2 * np.pi - 0.01) % (2 * np.pi) - np.pi
        return d
    d["theta [deg]"] = (np.degrees(d.pop("theta")) + 359.95) % 360.0
    return d


@pytest.mark.parametrize("variant", ["counts [0, cpr)", "rad [-pi, pi)", "deg [0, 360)"])
def test_a_single_turn_angle_that_wraps_is_unwrapped(tmp_path, paper, counts, variant):
    """Released next to the wrap point, the readings step by about one revolution between
    two samples (4000 counts, 2 pi, 360 deg) where the gear moved a few encoder steps. Read
    as they stand, the runs lie a revolution apart and every swing has a jump of 2 pi in it
    (the old reader gave runs 6.25 rad apart, a 'dropout' at a swing's peak); unwrapped,
    the readings are the original's plus one constant (the set-up's other zero), with the
    same encoder step, and a note names the wraps."""
    frame, ref = (counts[0], counts[1]) if variant.startswith("counts") else paper[1:]
    d = _single_turn(frame, variant)
    raw = d.filter(like="theta").to_numpy().ravel()
    assert np.ptp(raw) > 0.9 * (CPR if variant.startswith("counts") else
                                 2 * np.pi if "rad" in variant else 360)  # it does wrap
    path = tmp_path / "single_turn.csv"
    d.to_csv(path, index=False)
    log = read_log(path, counts_per_rev=CPR if variant.startswith("counts") else None)
    assert_same_log(log, ref, theta_offset=True)
    assert any("single-turn angle wraps at one revolution" in n for n in log.notes), log.notes
    assert not any("dropout" in n for n in log.notes), log.notes


def test_an_output_angle_that_wraps_at_one_revolution_is_unwrapped(tmp_path):
    """An absolute single-turn output encoder printing [-pi, pi), the driven log's output
    resting next to the wrap point: unwrapped like the input's, the output angle is the
    original's plus one constant and a note names the wraps."""
    d = pd.read_csv(SYNTH / "driven_csf8.csv")
    ref = read_log(SYNTH / "driven_csf8.csv")
    centre = np.median(d["theta_out"])
    d["theta_out"] = (d["theta_out"] - centre + 2 * np.pi - 0.002) % (2 * np.pi) - np.pi
    path = tmp_path / "out_wraps.csv"
    d.to_csv(path, index=False)
    log = read_log(path)
    shift = log.runs[0].theta_out[0] - ref.runs[0].theta_out[0]
    for a, b in zip(log.runs, ref.runs):
        # float64 rounding of the modulo and the unwrap (readings up to 2 pi): a few ulp
        np.testing.assert_allclose(a.theta_out - shift, b.theta_out, rtol=0, atol=1e-13)
        np.testing.assert_array_equal(a.theta, b.theta)
    assert any("'theta_out': a single-turn angle wraps" in n for n in log.notes), log.notes


def test_a_set_up_on_both_ends_of_the_range_shares_one_zero():
    """Two runs of one set-up resting on either side of the wrap point (4090-4095 and 1-6
    of 4096 counts), neither crossing it: read as they stand they are a revolution apart,
    which no shared zero fits; the run on the other end (the minority: most runs stay as
    read) moves by one revolution, named."""
    from hdid._log._revolutions import unwrap_revolutions

    q = 2 * np.pi / 4096
    rng = np.random.default_rng(3)
    a = (4090 + rng.integers(0, 6, 20)) * q
    b = (1 + rng.integers(0, 6, 20)) * q
    c = (4088 + rng.integers(0, 6, 20)) * q
    theta = np.concatenate([a, b, c])
    out, notes = unwrap_revolutions(theta, [0, 20, 40], [20, 40, 60], ["a", "b", "c"], None,
                                    np.arange(60) + 2, "theta", 4096)
    np.testing.assert_array_equal(out[:20], a)
    np.testing.assert_array_equal(out[40:], c)
    np.testing.assert_allclose(out[20:40], b + 2 * np.pi, rtol=0, atol=1e-12)
    assert len(notes) == 1 and "run(s) 'b'" in notes[0], notes


def test_a_read_dropout_across_the_wrap_point_stays_a_dropout(tmp_path, paper):
    """A bus servo's failed read (-pi) among readings near +1.5 rad is a step of 4.6 rad,
    more than half a revolution, and it comes back at the next sample: undone it would still
    be 1.6 rad from its neighbours, far beyond any one-sample change of the log (0.19 rad),
    so it is no wrap. It is dropped as a read dropout, as before, and no wrap is noted."""
    _, frame, ref = paper
    d = frame.copy()
    d["theta"] = d["theta"] + 1.5
    k = 40  # in the free swing of the first run
    d.loc[k, "theta"] = -np.pi
    path = tmp_path / "dropout.csv"
    d.to_csv(path, index=False)
    log = read_log(path)
    assert not any("wraps" in n for n in log.notes), log.notes
    assert [n for n in log.notes if "read dropout" in n and f"row {k + 2} " in n]
    np.testing.assert_allclose(log.runs[0].theta - 1.5, np.delete(ref.runs[0].theta, k),
                               rtol=0, atol=1e-12)


# ------------------------------------------------------------ time that restarts, rows twice


def test_time_that_restarts_without_a_run_column_splits_the_runs(tmp_path, paper):
    """A logger that restarts its clock at each release and writes no run column: time
    drops back to 0 at rows 127, 252 and 377. Each stretch is a run, the log is the
    original (four runs of 125 samples, the same readings), and a note names the rows.
    The old reader refused the log."""
    _, frame, ref = paper
    d = frame.copy()
    d["time"] = d["time"] - d.groupby("run")["time"].transform("first")
    path = tmp_path / "restarts.csv"
    d.drop(columns="run").to_csv(path, index=False)
    log = read_log(path)
    assert_same_log(log, ref)
    assert [r.name for r in log.runs] == ["1", "2", "3", "4"]
    assert [r.first_row for r in log.runs] == [2, 127, 252, 377]
    assert any("time restarts at row(s) 127 (0.496 s → 0 s), 252" in n for n in log.notes)


def test_logs_written_one_after_another_whose_clock_restarts(tmp_path, paper):
    """Two logs concatenated (the header repeated), each holding two releases with the
    clock restarted at each and no run column: four runs, a log's second stretch named
    after it ('1.2'), the readings the original's."""
    _, frame, ref = paper
    d = frame.copy()
    d["time"] = d["time"] - d.groupby("run")["time"].transform("first")
    first, second = (d[d.run.isin(r)].drop(columns="run") for r in ((1, 2), (3, 4)))
    text = first.to_csv(index=False) + second.to_csv(index=False)
    log = read_log(_write(tmp_path / "cat_restarts.csv", text))
    assert_same_log(log, ref)
    assert [r.name for r in log.runs] == ["1", "1.2", "2", "2.2"]
    assert any("time restarts at row(s) 127 " in n and "378 " in n for n in log.notes)


@pytest.mark.parametrize("case", ["two rows swapped", "restart inside a labelled run"])
def test_time_that_drops_back_otherwise_stays_an_error(tmp_path, paper, case):
    """Two rows out of order (time drops by one sample, not back to the stretch's start) ask
    to sort the rows; with a run column, a restart inside one run is an error (the labels
    say it is one release)."""
    _, frame, _ = paper
    d = frame.copy()
    if case == "two rows swapped":
        d.loc[[20, 21], "time"] = d.loc[[21, 20], "time"].to_numpy()
        d = d.drop(columns="run")
    else:
        d.loc[60:124, "time"] -= d.loc[60, "time"]
    path = tmp_path / "order.csv"
    d.to_csv(path, index=False)
    with pytest.raises(LogError) as err:
        read_log(path)
    assert err.value.column == "time" and err.value.row == (23 if "swapped" in case else 62)
    assert "is not after the previous" in str(err.value)


def test_a_row_written_twice_is_dropped(tmp_path, paper):
    """Rows 52 and 54 repeat the row above exactly (same time, same readings): the copies
    are dropped, the log is the original, and a note names them. The old reader refused
    the log ('repeats the previous row'). The same time with another reading is two
    samples at one instant: still an error naming the row."""
    _, frame, ref = paper
    d = pd.concat([frame.iloc[:50], frame.iloc[49:51], frame.iloc[50:]], ignore_index=True)
    path = tmp_path / "twice.csv"
    d.to_csv(path, index=False)
    log = read_log(path)
    assert_same_log(log, ref)
    assert any("row(s) 52, 54 repeat the row above exactly" in n for n in log.notes), log.notes
    d.loc[50, "theta"] += ref.resolution  # one encoder step off: a different reading
    d.to_csv(path, index=False)
    with pytest.raises(LogError) as err:
        read_log(path)
    assert err.value.row == 52 and err.value.column == "time"
    assert "different readings" in str(err.value)


# ------------------------------------------------------------ a last line cut mid-write


@pytest.mark.parametrize("cut", ["cell cut", "cells missing", "empty last cell"])
def test_a_last_line_cut_mid_write_is_dropped(tmp_path, paper, cut):
    """A logger stopped mid-write leaves its last line without a line end and short: it is
    dropped with a note (the other rows read as before). A whole last line without a line
    end is kept."""
    text, _, ref = paper
    body = text.rstrip("\n")
    whole = read_log(_write(tmp_path / "whole.csv", body))
    assert_same_log(whole, ref)
    assert whole.notes == ref.notes
    last = body.rsplit("\n", 1)[1]
    variant = {"cell cut": body[:-6], "cells missing": body.rsplit(",", 1)[0],
               "empty last cell": body.rsplit(",", 1)[0] + ","}[cut]
    log = read_log(_write(tmp_path / "cut.csv", variant))
    assert [r.n_samples for r in log.runs] == [125, 125, 125, 124]
    np.testing.assert_array_equal(log.runs[3].theta, ref.runs[3].theta[:-1])
    assert any("row 501" in n and "dropped" in n for n in log.notes), (last, log.notes)


# ------------------------------------------------------------ MATLAB files


def test_a_mat_file_reads_its_vectors_by_name(tmp_path, paper):
    from scipy import io as sio

    _, frame, ref = paper
    path = tmp_path / "log.mat"
    sio.savemat(path, {"run": frame["run"].to_numpy()[:, None],  # a column vector
                       "setup": frame["setup"].to_numpy().astype(str),
                       "t": frame["time"].to_numpy(),
                       "theta_deg": np.degrees(frame["theta"].to_numpy()),
                       "temperature": 21.5})
    assert_same_log(read_log(path), ref)


def test_mat_file_errors_name_the_file_and_the_fix(tmp_path, paper):
    from scipy import io as sio

    _, frame, _ = paper
    path = tmp_path / "other.mat"
    sio.savemat(path, {"t": frame["time"].to_numpy(), "qm": frame["theta"].to_numpy()})
    with pytest.raises(LogError, match=r"other\.mat: missing column 'theta'.*'qm'"):
        read_log(path)
    renamed = tmp_path / "renamed.csv"
    renamed.write_bytes(path.read_bytes())
    with pytest.raises(LogError, match=r"renamed\.csv: this is a MATLAB \.mat file"):
        read_log(renamed)


# ------------------------------------------------------------ end to end: hdid fit


def _station_rich_log(tmp_path):
    """The rich log as a station writes it: BOM, preamble, ';' with decimal commas, CRLF,
    a units row (time in ms), upper-case names."""
    d = pd.read_csv(RICH)
    d["time"] = (d["time"] * 1000).round(6)
    text = d.to_csv(index=False, sep=";", float_format="%.12g").replace(".", ",")
    text = text.replace("run;setup;time;theta\n", "Run;Setup;Time;Theta\n;;[ms];[rad]\n")
    return _write(tmp_path / "station.csv", "# station 4, 2026-11-27\n" + text,
                  bom=True, crlf=True)


def _hdid_fit(log, out, *options):
    proc = subprocess.run(
        [sys.executable, "-m", "hdid.cli", "fit", str(log), *options, "--json", str(out), "-q"],
        capture_output=True, text=True, cwd=ROOT,
    )
    return proc, (json.loads(out.read_text()) if proc.returncode == 0 else None)


def test_hdid_fit_reads_a_station_log_to_the_same_physics(tmp_path):
    """One fit of the station-written rich log against the original's: the same log, so
    the same numbers (to the optimiser's run-to-run reproducibility, far inside the std)."""
    station = _station_rich_log(tmp_path)
    assert_same_log(read_log(station), read_log(RICH))
    proc, fit = _hdid_fit(station, tmp_path / "station.json")
    assert proc.returncode == 0, proc.stderr
    _, ref = _hdid_fit(RICH, tmp_path / "ref.json")
    for name, p in ref["parameters"].items():
        q = fit["parameters"][name]
        if p["std"]:
            # the same log fits to the same optimum: a hundredth of its std at most
            assert abs(q["value"] - p["value"]) <= 0.01 * p["std"], name


def test_hdid_fit_error_is_one_line_exit_2(tmp_path, paper):
    """A units row with a unit the column does not know: exit 2, one line naming the file,
    the column and the fix, no traceback."""
    text = paper[0].replace("theta\n", "theta\n,,s,furlong\n", 1)
    path = _write(tmp_path / "bad.csv", text)
    proc, _ = _hdid_fit(path, tmp_path / "bad.json")
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and "bad.csv" in lines[0] and "furlong" in lines[0], proc.stderr
    assert "Traceback" not in proc.stderr
