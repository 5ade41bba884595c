"""Time columns under a logger's own name, the header a header-less log needs, and a count
register too slow for its swing (seed-7071 world test: logs 00, 01, 03, 04, 09).

Every log is drawn here (a damped 20 Hz swing, radians printed to 1e-6), never read from a
shipped file.
"""

from __future__ import annotations

import datetime

import numpy as np
import pytest

from hdid import LogError, read_log

FS = 500.0
H = 1.0 / FS
N = 400


def _swing(n=N, h=H):
    """``(t [s], theta [rad])``: a damped 20 Hz swing of n samples h apart."""
    t = np.arange(n) * h
    return t, 0.05 * np.exp(-2.0 * t) * np.cos(2 * np.pi * 20.0 * t)


def _lines(times, theta):
    return "".join(f"{a},{b:.6f}\n" for a, b in zip(times, theta))


def _period_ok(log, h=H):
    """The printed stamps carry 1 µs or better: 1e-3 of a 2 ms period is far above it."""
    assert abs(log.sample_period - h) < 1e-3 * h


@pytest.mark.parametrize("header, scale", [
    ("timestamp_us", 1e6), ("Time Stamp [ms]", 1e3), ("Timestamp (s)", 1.0)])
def test_timestamp_names_with_their_unit_are_the_time(tmp_path, header, scale):
    """``timestamp`` with a unit (brackets, parentheses or a ``_unit`` suffix) reads as
    'time' in that unit."""
    t, theta = _swing()
    path = tmp_path / "log.csv"
    path.write_text(f"{header},theta [rad]\n" + _lines([f"{a * scale:.6f}" for a in t], theta))
    _period_ok(read_log(path))


def test_a_time_column_beside_a_timestamp_one_wins_and_both_are_named(tmp_path):
    """'time' [s] and 'timestamp [ms]' (the same instants): 'time' is read, and one note
    names both (were 'timestamp [ms]' read as s, the period would be 1000× off)."""
    t, theta = _swing()
    path = tmp_path / "log.csv"
    path.write_text("timestamp [ms],time,theta\n" + "".join(
        f"{a * 1e3:.3f},{a:.6f},{b:.6f}\n" for a, b in zip(t, theta)))
    log = read_log(path)
    _period_ok(log)
    named = [n for n in log.notes if "'time'" in n and "'timestamp [ms]'" in n]
    assert len(named) == 1, log.notes


def test_a_bare_timestamp_of_datetimes_beside_time_is_named(tmp_path):
    t, theta = _swing()
    d0 = datetime.datetime(2026, 11, 27, 10, 33, 49)
    path = tmp_path / "log.csv"
    path.write_text("Timestamp,time,theta\n" + "".join(
        f"{(d0 + datetime.timedelta(seconds=a)).isoformat(sep=' ')},{a:.6f},{b:.6f}\n"
        for a, b in zip(t, theta)))
    log = read_log(path)
    _period_ok(log)
    assert any("'time'" in n and "'Timestamp'" in n for n in log.notes), log.notes


def test_a_bare_integer_timestamp_is_still_px4_microseconds(tmp_path):
    """Guard: the tool convention (PX4's integer µs since boot) is unchanged."""
    t, theta = _swing()
    path = tmp_path / "log.csv"
    path.write_text("timestamp,theta\n" + _lines([str(5_000_000 + round(a * 1e6)) for a in t],
                                                  theta))
    _period_ok(read_log(path))


@pytest.mark.parametrize("decimals", [6, 3])
def test_a_bare_timestamp_of_decimal_epoch_seconds_is_the_time(tmp_path, decimals):
    """A Python logger's ``time.time()`` printed as ``%.6f`` (or whole ms) under a bare
    'timestamp': seconds since 1970, relative to the first row (refused as missing 'time'
    before). The stamps are printed to 1 µs/1 ms on a 2 ms period, so the median step is
    exact to far better than 1e-3 of it."""
    t, theta = _swing()
    path = tmp_path / "log.csv"
    path.write_text("timestamp,theta\n" + _lines(
        [f"{1764331200.25 + a:.{decimals}f}" for a in t], theta))
    log = read_log(path)
    _period_ok(log)
    assert log.runs[0].time[0] == 0.0
    assert any("since 1970" in n for n in log.notes), log.notes


@pytest.mark.parametrize("unit, scale, h", [("ms", 1e3, 1 / 300), ("us", 1e6, H), ("s", 1.0, H)])
def test_the_header_a_headerless_log_is_told_to_add_reads_it(tmp_path, unit, scale, h):
    """A header-less log is refused with the header line to add, its time unit from the
    steps (the largest unit sampling at >= 5 Hz); that header, added, reads the log at its
    true period (the old 'time,theta' read ms as s: a period 1000× too long)."""
    t, theta = _swing(h=h)
    body = _lines([f"{a * scale:.3f}" for a in t], theta)
    bare = tmp_path / "bare.csv"
    bare.write_text(body)
    with pytest.raises(LogError) as err:
        read_log(bare)
    message = str(err.value)
    assert "\n" not in message
    header = message.split("add a header line '", 1)[1].split("'", 1)[0]
    assert header == f"time [{unit}],theta [rad]"
    fixed = tmp_path / "fixed.csv"
    fixed.write_text(header + "\n" + body)
    _period_ok(read_log(fixed), h)


def test_headerless_whole_counts_are_told_to_be_counts(tmp_path):
    t, theta = _swing()
    bare = tmp_path / "bare.csv"
    bare.write_text("".join(f"{a * 1e3:.0f},{round(b * 4000 / (2 * np.pi)) + 30000}\n"
                            for a, b in zip(t, theta)))
    with pytest.raises(LogError, match=r"'time \[ms\],counts'.*--counts-per-rev"):
        read_log(bare)


def _register_log(path, cpr, fs, hz):
    """A 16-bit signed register logging a swing of amplitude 0.3 rad at `hz`, sampled at
    `fs`, on an encoder of `cpr` counts per revolution (wrapping as the register does)."""
    t = np.arange(int(0.4 * fs)) / fs
    counts = np.rint(0.3 * np.exp(-3 * t) * np.cos(2 * np.pi * hz * t) * cpr / (2 * np.pi)
                     + 20000).astype(np.int64)
    wrapped = (counts + 2**15) % 2**16 - 2**15
    path.write_text("time,counts\n" + "".join(f"{a:.6f},{c}\n" for a, c in zip(t, wrapped)))
    return path


def test_a_register_moving_near_half_its_range_per_reading_is_ambiguous(tmp_path):
    """0.3 rad at 20 Hz on 2**20 counts per rev: up to 0.3 * 2pi * 20 / 2000 * 2**20 / 2pi
    = 3146 counts per reading at 2 kHz (clean wraps), but 31460 at 200 Hz (near half the
    2**16 register): only the latter note says the unwrapping is ambiguous."""
    slow = read_log(_register_log(tmp_path / "a.csv", 2**20, 200.0, 20.0), counts_per_rev=2**20)
    fast = read_log(_register_log(tmp_path / "b.csv", 2**20, 2000.0, 20.0), counts_per_rev=2**20)
    wrap = [n for n in slow.notes if "rolls over" in n]
    assert len(wrap) == 1 and "ambiguous" in wrap[0] and "log faster" in wrap[0], slow.notes
    clean = [n for n in fast.notes if "rolls over" in n]
    assert len(clean) == 1 and "ambiguous" not in clean[0], fast.notes
