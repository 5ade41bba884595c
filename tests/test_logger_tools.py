"""Logs as robotics and automation tools write them: ROS topic dumps, a microcontroller's
serial prints, a TwinCAT Scope export, a PX4 flight-log export, a spreadsheet's CSV, a
motor-and-output set-up's two encoders.

Every log is drawn here by numpy (:func:`test_logger_grids.world`: a Coulomb-damped
ring-down, its exact solution, on a 14-bit encoder), never read from a shipped file, and
written as the tool writes it. It must read to the same log as the same samples in hdid's
own CSV (the same samples, times, readings and encoder step), or end with one line naming
the row and the fix. Each test failed on the reader before this file, except the guards
(forms that already read, kept so).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from hdid import LogError, read_log
from test_logger_files import assert_same_log
from test_logger_grids import world

CPR = 16384
Q = 2 * math.pi / CPR
FS = 500.0


@pytest.fixture(scope="module")
def run():
    """One release: ``(time [s], counts)`` and its log read from hdid's own CSV."""
    t, counts = world(np.random.default_rng(3), fs=FS, cpr=CPR, f_n=31.0, amps=(0.15,))[0]
    return t, counts


@pytest.fixture(scope="module")
def ref(run, tmp_path_factory):
    t, counts = run
    path = tmp_path_factory.mktemp("ref") / "ref.csv"
    path.write_text("time,theta\n" + "".join(f"{float(a)!r},{b}\n" for a, b in zip(t, counts)))
    return read_log(path, counts_per_rev=CPR)


def _rad(counts) -> list[str]:
    return [repr(float(c * Q)) for c in counts]


def _note(log, text: str) -> str:
    hits = [n for n in log.notes if text in n]
    assert hits, log.notes
    return hits[0]


# ------------------------------------------------------------------ ROS

#: A stamp in nanoseconds since 1970 (2023-11-14), beyond float64's 2^53 integers.
EPOCH_NS = 1_700_000_123_456_789_123


def _stamps(t):
    return EPOCH_NS + np.round(t * 1e9).astype(np.int64)


def _stamped(path, header, t, counts):
    """``header`` then one 'ns stamp,angle [rad]' line per reading: two tools' shape."""
    path.write_text(header + "\n" + "".join(
        f"{s},{v}\n" for s, v in zip(_stamps(t), _rad(counts))))
    return path


def _receipts(t, rng):
    """When the recorder got each message: the stamp plus 0.2-0.6 ms of transport."""
    return _stamps(t) + rng.integers(200_000, 600_000, t.size)


def test_rostopic_echo_p_of_a_joint_state(tmp_path, run, ref):
    """``rostopic echo -p /joint_states``: the header line starts with '%time' (read as a
    comment before), times are integer ns since 1970 (1.7e18: as floats, steps of 256 ns),
    the sample's stamp is ``field.header.stamp``, the angle ``field.position0`` [rad]."""
    t, counts = run
    rng = np.random.default_rng(1)
    path = tmp_path / "joint_states.csv"
    path.write_text(
        "%time,field.header.seq,field.header.stamp,field.header.frame_id,field.name0,"
        "field.position0,field.velocity0,field.effort0\n" + "".join(
            f"{r},{i},{s},base_link,wg_joint,{v},0.0,0.0\n"
            for i, (r, s, v) in enumerate(zip(_receipts(t, rng), _stamps(t), _rad(counts)))))
    log = read_log(path)
    # the stamps' differences are whole ns, exact in float64 once taken from the first
    assert_same_log(log, ref, time_tol=1e-12)
    assert "header stamp" in _note(log, "ROS log")


def test_rostopic_stamp_in_seconds_and_nanoseconds(tmp_path, run, ref):
    """The stamp as ``field.header.stamp.secs`` / ``.nsecs`` (a message's header printed
    field by field), the angle ``field.position``."""
    t, counts = run
    ns = _stamps(t)
    path = tmp_path / "secs.csv"
    path.write_text(
        "%time,field.header.seq,field.header.stamp.secs,field.header.stamp.nsecs,"
        "field.header.frame_id,field.position\n" + "".join(
            f"{r},{i},{s // 10**9},{s % 10**9},enc,{v}\n" for i, (r, s, v) in
            enumerate(zip(_receipts(t, np.random.default_rng(2)), ns, _rad(counts)))))
    assert_same_log(read_log(path), ref, time_tol=1e-12)


def test_rosbag2_csv_export(tmp_path, run, ref):
    """A rosbag2 export: ``timestamp`` (the recorder's receipt, ns),
    ``header.stamp.sec`` / ``header.stamp.nanosec`` (ROS 2's names), ``position``."""
    t, counts = run
    ns = _stamps(t)
    path = tmp_path / "bag2.csv"
    path.write_text("timestamp,header.stamp.sec,header.stamp.nanosec,header.frame_id,position\n"
                    + "".join(f"{r},{s // 10**9},{s % 10**9},enc,{v}\n" for r, s, v in
                              zip(_receipts(t, np.random.default_rng(4)), ns, _rad(counts))))
    assert_same_log(read_log(path), ref, time_tol=1e-12)


@pytest.mark.parametrize("header, note, says", [
    # std_msgs/Float64: no header, so '%time' (the receipt) is the time, and the note says
    # so; the angle is field.data
    ("%time,field.data", "ROS log", "receipt"),
    # a rosbag2 export without header fields: 1.7e18 is ns since 1970, not PX4's µs since
    # boot (read so, the sample period would be 2 s)
    ("timestamp,position", "'timestamp'", "ns since 1970"),
], ids=["float64_topic_receipt_time", "integer_timestamp_unit_by_size"])
def test_a_bare_ns_stamp_column_is_read_with_a_note(tmp_path, run, ref, header, note, says):
    t, counts = run
    log = read_log(_stamped(tmp_path / "stamped.csv", header, t, counts))
    assert_same_log(log, ref, time_tol=1e-12)
    assert says in _note(log, note)


def test_a_joint_state_of_several_joints_is_refused_with_the_fix(tmp_path, run):
    """Two joints' positions: which is the gear's is not in the file — one line naming
    them (before: 'missing columns')."""
    t, counts = run
    path = tmp_path / "two_joints.csv"
    path.write_text("%time,field.header.stamp,field.position0,field.position1\n" + "".join(
        f"{s},{s},{v},0.5\n" for s, v in zip(_stamps(t), _rad(counts))))
    with pytest.raises(LogError, match=r"2 joints .*'field.position1'.*rename the column"):
        read_log(path)


def test_plotjuggler_csv_export(tmp_path, run, ref):
    """PlotJuggler's export: ``__time`` in epoch seconds (float64 keeps them to 0.2 µs),
    the series ``/joint_states/wg_joint/position``."""
    t, counts = run
    path = tmp_path / "pj.csv"
    path.write_text("__time,/joint_states/wg_joint/position,/joint_states/wg_joint/velocity\n"
                    + "".join(f"{1_700_000_123.25 + a:.6f},{v},0.0\n"
                              for a, v in zip(t, _rad(counts))))
    log = read_log(path)
    # epoch seconds printed to 1 us and held in float64 (spacing 2.4e-7 s at 1.7e9 s)
    assert_same_log(log, ref, time_tol=1e-6)
    _note(log, "PlotJuggler")


# ------------------------------------------------------------------ serial prints

def test_arduino_millis_capture_with_a_partial_line_and_baud_garbage(tmp_path, run, ref):
    """A terminal capture of ``Serial.print("t_ms="); …`` lines: it opens mid-line
    (``=1251 pos=2460``) after bytes from a wrong baud rate; both are dropped (noted)."""
    t, counts = run
    ms = 81_234 + np.round(t * 1e3).astype(np.int64)
    body = "".join(f"t_ms={a} pos={b}\r\n" for a, b in zip(ms, counts)).encode()
    path = tmp_path / "capture.txt"
    path.write_bytes(b"\xf8\x00\x9c\xfe~\xe0\r\n=1251 pos=2460\r\n" + body)
    log = read_log(path, counts_per_rev=CPR)
    assert_same_log(log, ref, time_tol=1e-9)
    assert "first 2 line(s)" in _note(log, "serial capture")


def test_teensy_micros_wrapping_at_2_32(tmp_path, run, ref):
    """``us=… pos=…`` from micros(), a 32-bit counter that rolls over inside the run."""
    t, counts = run
    us = (2**32 - 150_000 + np.round(t * 1e6).astype(np.int64)) % 2**32
    path = tmp_path / "teensy.txt"
    path.write_text("".join(f"us={a} pos={b}\n" for a, b in zip(us, counts)))
    log = read_log(path, counts_per_rev=CPR)
    assert_same_log(log, ref, time_tol=1e-9)
    _note(log, "32-bit timer")


def test_a_sketch_printing_csv_with_millis_and_a_partial_first_line(tmp_path, run, ref):
    """``Serial.println("millis,counts")`` once, then ``millis(),count`` lines, captured
    from mid-line: the header names the time by the function that reads it (ms)."""
    t, counts = run
    ms = 5_000 + np.round(t * 1e3).astype(np.int64)
    path = tmp_path / "sketch.csv"
    path.write_text("3,2461\nmillis,counts\n" + "".join(f"{a},{b}\n" for a, b in zip(ms, counts)))
    assert_same_log(read_log(path, counts_per_rev=CPR), ref, time_tol=1e-9)


def test_a_bare_whole_number_time_key_is_refused_with_the_fix(tmp_path, run):
    """``t=123 pos=456`` from millis(): ``t`` has no unit, and millis() and micros() print
    alike: one line naming the row and the fix (before: 'not a CSV' errors)."""
    t, counts = run
    path = tmp_path / "bare.txt"
    path.write_text("".join(f"t={int(round(a * 1e3))} pos={b}\n" for a, b in zip(t, counts)))
    with pytest.raises(LogError, match=r"row 1: .*'t_ms=' \(millis\(\)\)"):
        read_log(path, counts_per_rev=CPR)


def test_a_garbled_line_inside_a_capture_is_named(tmp_path, run):
    """A line of noise between records may hide a lost sample: an error naming it."""
    t, counts = run
    lines = [f"ms={int(round(a * 1e3))} pos={b}\n" for a, b in zip(t, counts)]
    lines[100] = "ms=200 po\xbfs=1\n"
    path = tmp_path / "noisy.txt"
    path.write_text("".join(lines))
    with pytest.raises(LogError, match=r"row 101: .*not a record like the others"):
        read_log(path, counts_per_rev=CPR)


# ------------------------------------------------------------------ PLC scope, PX4

#: A TwinCAT Scope export's record rows and two channel blocks side by side.
SCOPE_BLOCK = (
    "Name\tScope Project\nFile\tC:\\rig\\wg.tcscopex\n"
    "StartRecord\t133457000000000000\tSaturday, 28. November 2026\t08:01:02\n"
    "EndRecord\t133457000100000000\tSaturday, 28. November 2026\t08:01:12\n\n"
    "Name\tActPos\tName\tI_act\nNetId\t5.1.2.3.1.1\tNetId\t5.1.2.3.1.1\n"
    "Port\t851\tPort\t851\nSampleTime[ms]\t2\tSampleTime[ms]\t2\n"
    "SymbolBased\tTRUE\tSymbolBased\tTRUE\n"
    "SymbolName\tMAIN.Axis.Position\tSymbolName\tMAIN.Axis.fCurrent\n"
    "SymbolComment\t\tSymbolComment\t\nUnit\tdeg\tUnit\tA\n"
    "Data-Type\tREAL64\tData-Type\tREAL64\nVariableSize\t8\tVariableSize\t8\n")


def _degrees(counts) -> list[str]:
    return [repr(float(v)) for v in counts * 360.0 / CPR]


@pytest.mark.parametrize("clock", ["ms", "file time"])
def test_twincat_scope_export(tmp_path, run, clock):
    """A TwinCAT Scope View CSV export: the record's rows, one block of channel rows
    (Name, SampleTime[ms], SymbolName, Unit, …) side by side, then per channel a time and
    a value, tab-separated with decimal commas and no header line. The time is ms since
    the first sample or, with "Full Timestamp", a Windows file time (100 ns ticks since
    1601: 1.3e17, beyond float64's integers). It reads as the same samples written with
    hdid's names."""
    t, counts = run
    deg = _degrees(counts)
    ms = [f"{a * 1e3:.0f}" for a in t]
    stamps = ms if clock == "ms" else [str(133_457_000_000_000_123 + round(a * 1e7)) for a in t]
    scope = tmp_path / "scope.csv"
    scope.write_text(SCOPE_BLOCK + "".join(f"{a}\t{v.replace('.', ',')}\t{a}\t0,25\n"
                                           for a, v in zip(stamps, deg)))
    plain = tmp_path / "plain.csv"
    plain.write_text("time [ms],theta [deg]\n" + "".join(f"{a},{v}\n" for a, v in zip(ms, deg)))
    log = read_log(scope)
    assert_same_log(log, read_log(plain))
    assert log.resolution == pytest.approx(Q, rel=1e-9)
    _note(log, "TwinCAT Scope export")


def test_a_twincat_export_without_a_time_per_channel_is_refused(tmp_path, run):
    """'Timelines: None' writes the values only: one line naming the row and the fix."""
    t, counts = run
    scope = tmp_path / "no_time.csv"
    scope.write_text(SCOPE_BLOCK + "".join(f"{v.replace('.', ',')}\t0,25\n"
                                           for v in _degrees(counts)))
    with pytest.raises(LogError, match=r"row 16: .*'Timelines: All'"):
        read_log(scope)


def test_px4_ulog_csv(tmp_path, run, ref):
    """``ulog2csv``'s wheel_encoders topic: ``timestamp`` in µs since boot (no unit in
    the name: ulog's convention), the angle ``encoder_position[0]`` in counts."""
    t, counts = run
    us = 48_123_456 + np.round(t * 1e6).astype(np.int64)
    path = tmp_path / "log_7_wheel_encoders_0.csv"
    path.write_text("timestamp,encoder_position[0],speed[0],pulses_per_rev[0]\n" + "".join(
        f"{a},{b},0,{CPR}\n" for a, b in zip(us, counts)))
    log = read_log(path, counts_per_rev=CPR)
    assert_same_log(log, ref, time_tol=1e-9)
    _note(log, "PX4 log")


def test_a_millis_timestamp_is_refused_rather_than_read_as_microseconds(tmp_path, run):
    """``timestamp`` of millis() (steps of 2): as µs it would be 500 kHz sampling."""
    t, counts = run
    path = tmp_path / "ms_stamp.csv"
    path.write_text("timestamp,counts\n" + "".join(
        f"{round(a * 1e3) + 700},{b}\n" for a, b in zip(t, counts)))
    with pytest.raises(LogError, match=r"500 kHz sampling .*'timestamp \[ms\]'"):
        read_log(path, counts_per_rev=CPR)


# ------------------------------------------------------------------ two encoders

def test_a_motor_and_output_encoder_pair_in_a_driven_log(tmp_path, run):
    """A driven log of a set-up with an encoder on each side: ``motor_pos`` and
    ``load_pos`` (counts) read as ``theta`` and ``theta_out``."""
    t, counts = run
    out = np.round(counts / 100.0 * 8).astype(np.int64)  # a 2^17 output encoder
    torque = 0.05 * np.sin(2 * np.pi * 3 * t)
    body = "".join(f"{float(a)!r},{float(m)!r},{b},{o}\n"
                   for a, m, b, o in zip(t, torque, counts, out))
    tool = tmp_path / "two.csv"
    tool.write_text("time,motor_torque,motor_pos,load_pos\n" + body)
    plain = tmp_path / "plain.csv"
    plain.write_text("time,motor_torque,theta,theta_out\n" + body)
    kw = dict(counts_per_rev=CPR, output_counts_per_rev=2**17)
    log, ref = read_log(tool, **kw), read_log(plain, **kw)
    assert_same_log(log, ref)
    np.testing.assert_array_equal(log.runs[0].theta_out, ref.runs[0].theta_out)
    assert log.output_resolution == ref.output_resolution


def test_the_output_encoder_of_a_free_motion_log_is_named_not_used(tmp_path, run, ref):
    """Guard and note: a free-motion log's ``load_pos`` is left out, and now said so
    (before it was left out silently)."""
    t, counts = run
    path = tmp_path / "free.csv"
    path.write_text("time,theta,load_pos\n" + "".join(
        f"{float(a)!r},{b},{round(b / 100)}\n" for a, b in zip(t, counts)))
    log = read_log(path, counts_per_rev=CPR)
    assert_same_log(log, ref)
    _note(log, "'load_pos' (the output's angle) is not used")


# ------------------------------------------------------------------ spreadsheets (guards)

@pytest.mark.parametrize("form", ["sep=;", "quoted", "quoted decimal comma", "1e-3",
                                  "1E-3", "NaN and empty at dropouts"])
def test_guard_spreadsheet_forms_that_read_already(tmp_path, run, ref, form):
    """Guards (each read before): Excel's ``sep=;`` first line, quoted numbers (with a
    decimal comma under ';'), scientific notation with e or E, a missed reading written
    as NaN or left empty (dropped, noted)."""
    t, counts = run
    rad = _rad(counts)
    if form == "sep=;":
        text = "sep=;\ntime;theta\n" + "".join(f"{float(a)!r};{v}\n" for a, v in zip(t, rad))
    elif form == "quoted":
        text = '"time","theta"\n' + "".join(f'"{float(a)!r}","{v}"\n' for a, v in zip(t, rad))
    elif form == "quoted decimal comma":
        text = '"time";"theta"\n' + "".join(
            f'"{float(a)!r}";"{v}"\n'.replace(".", ",") for a, v in zip(t, rad))
    elif form in ("1e-3", "1E-3"):
        e = form[1]
        text = "time,theta\n" + "".join(
            f"{a:.15e},{float(v):.17e}\n".replace("e", e) for a, v in zip(t, rad))
    else:
        cells = list(rad)
        cells[60], cells[140] = "NaN", ""
        text = "time,theta\n" + "".join(f"{float(a)!r},{v}\n" for a, v in zip(t, cells))
    path = tmp_path / "sheet.csv"
    path.write_text(text)
    log = read_log(path)
    if form.startswith("NaN"):
        assert log.runs[0].n_samples == ref.runs[0].n_samples - 2
        _note(log, "no reading at row(s) 62, 142")
        return
    assert_same_log(log, ref, time_tol=1e-12)
