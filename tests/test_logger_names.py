"""Angle columns named the way rigs name them (``Angle``, ``Encoder``), and a preamble of
``key: value`` lines above the header.

Each log is a small ring-down written with numpy the way a test station writes it (a
``;`` export with decimal commas and a units row, a ``#`` and ``Operator: HV`` preamble);
it must read to the readings written, converted from the header's unit, or end with one
line naming the column and the fix.
"""

from __future__ import annotations

import numpy as np
import pytest

from hdid import LogError, read_log

FS = 1000.0  # sample rate [Hz]
CPR = 4096  # encoder counts per revolution of the counts logs


def ringdown(n: int = 400) -> tuple[np.ndarray, np.ndarray]:
    """A 25 Hz ring-down about 0.3 rad, 0.1 rad swing: time [s], angle [rad]."""
    t = np.arange(n) / FS
    return t, 0.3 + 0.1 * np.exp(-3.0 * t) * np.cos(2 * np.pi * 25.0 * t)


def write(path, header: str, rows: np.ndarray, fmt: str, sep: str = ",",
          preamble: str = "", units: str | None = None, decimal_comma: bool = False):
    lines = [header] + ([units] if units is not None else [])
    for row in rows:
        line = sep.join(f % v for f, v in zip(fmt.split(), row))
        lines.append(line.replace(".", ",") if decimal_comma else line)
    path.write_text(preamble + "\n".join(lines) + "\n")
    return path


def theta_read(log) -> np.ndarray:
    return np.concatenate([r.theta for r in log.runs])


# exact up to the printed digits: half a unit in the last printed place
@pytest.mark.parametrize("header, scale, fmt, tol", [
    ("time;Angle", 1.0, "%.6f %.6f", 0.5e-6),
    ("time;Angle (deg)", np.pi / 180, "%.6f %.4f", 0.5e-4 * np.pi / 180),
    ("time;Angle [rad]", 1.0, "%.6f %.6f", 0.5e-6),
    ("time;Encoder [deg]", np.pi / 180, "%.6f %.4f", 0.5e-4 * np.pi / 180),
])
def test_angle_named_angle(tmp_path, header, scale, fmt, tol):
    t, theta = ringdown()
    path = write(tmp_path / "angle.csv", header, np.c_[t, theta / scale], fmt, sep=";",
                 decimal_comma=True)
    log = read_log(path)
    np.testing.assert_allclose(theta_read(log), theta, rtol=0, atol=tol * 1.01)


def test_angle_column_with_units_row_and_index(tmp_path):
    """``No.;time;Angle`` with a units row ``;us;mrad`` (a logger's ';' export)."""
    t, theta = ringdown()
    rows = np.c_[np.arange(t.size), t * 1e6, theta * 1e3]
    path = write(tmp_path / "angle_units.csv", "No.;time;Angle", rows, "%d %.0f %.1f",
                 sep=";", units=";us;mrad", decimal_comma=True)
    log = read_log(path)
    # 0.05 mrad: half the last printed place of the mrad readings
    np.testing.assert_allclose(theta_read(log), theta, rtol=0, atol=0.0501e-3)


def test_two_angle_columns_are_ambiguous(tmp_path):
    t, theta = ringdown()
    path = write(tmp_path / "two.csv", "time,Angle,Encoder", np.c_[t, theta, theta],
                 "%.6f %.6f %.6f")
    with pytest.raises(LogError) as err:
        read_log(path)
    msg = str(err.value)
    assert "\n" not in msg and "two angle columns" in msg and "'Angle'" in msg
    assert "Encoder" in msg and "theta" in msg


PREAMBLE = "# station 17, test rig log\nOperator: HV\n\n"


def test_preamble_above_encoder_header(tmp_path):
    """``# station``, ``Operator: HV`` and a blank line above ``run,time (us),Encoder (mrad)``."""
    t, theta = ringdown()
    rows = np.c_[np.ones_like(t), 4.29e9 + t * 1e6, theta * 1e3, np.zeros_like(t)]
    path = write(tmp_path / "pre.csv", "run,time (us),Encoder (mrad),Speed (rpm)", rows,
                 "%d %.0f %.3f %.1f", preamble=PREAMBLE)
    log = read_log(path)
    assert [r.n_samples for r in log.runs] == [t.size]
    # 0.5 um rad: half the last printed place of the mrad readings
    np.testing.assert_allclose(theta_read(log), theta, rtol=0, atol=0.501e-6)


def encoder_counts_log(tmp_path, units: str | None):
    t, theta = ringdown()
    counts = np.rint(theta / (2 * np.pi) * CPR)
    rows = np.c_[t * 1e6, counts]
    header = "time,Encoder" if units else "time [us],Encoder"
    path = write(tmp_path / "counts.csv", header, rows, "%.0f %d", preamble=PREAMBLE,
                 units=units)
    return path, counts * 2 * np.pi / CPR


@pytest.mark.parametrize("units", ["[us],counts", None])
def test_encoder_counts(tmp_path, units):
    """Integer ``Encoder`` readings are counts: radians with --counts-per-rev, and without
    it the one-line error asking for it (the rules of a ``counts`` column)."""
    path, theta = encoder_counts_log(tmp_path, units)
    log = read_log(path, counts_per_rev=CPR)
    np.testing.assert_allclose(theta_read(log), theta, rtol=0, atol=1e-12)
    assert log.resolution == pytest.approx(2 * np.pi / CPR, rel=1e-12)
    with pytest.raises(LogError) as err:
        read_log(path)
    msg = str(err.value)
    assert "\n" not in msg
    assert "counts-per-rev" in msg and "Operator" not in msg


def test_preamble_not_taken_for_header(tmp_path):
    """A log whose angle column has a name hdid does not know: the error names the file's
    real columns, not the preamble's ``Operator:``, ``HV``."""
    t, theta = ringdown()
    path = write(tmp_path / "winkel.csv", "time,Winkel", np.c_[t, theta], "%.6f %.6f",
                 preamble=PREAMBLE)
    with pytest.raises(LogError) as err:
        read_log(path)
    msg = str(err.value)
    assert "\n" not in msg and "'Winkel'" in msg and "Operator" not in msg
    assert "missing column 'theta'" in msg
