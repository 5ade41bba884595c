"""A logger that restarts its timer at each run, also just before the timer register ends.

Started ``d`` before its end, a timer's time jumps *forward* by nearly a register length
(``2**bits`` ticks less ``d`` and the run before it) and wraps a little later. The wrap is
undone (:mod:`hdid._log._timer`); the forward jump is a restart and starts a run of its own
(``'1'``, ``'2'``, as for a timer that drops back), whether the gear moves there or not —
read as a pause in one run at rest it kept two runs together and left the fit to simulate
71 minutes. A forward step of more than ``RESTART_PERIODS`` (1000) median steps starts a run
too; shorter pauses at rest stay inside their run (the break rule).
"""

from __future__ import annotations

import numpy as np
import pytest

from hdid import LogError
from hdid._log import read_log


def _swing(n: int, period: float, amp: float) -> np.ndarray:
    """A decaying swing [rad] sampled every ``period`` s (a few hertz, moving every step)."""
    t = np.arange(n) * period
    return amp * np.exp(-t / 2.0) * np.cos(2 * np.pi * 3.0 * t)


def _write(path, ticks: np.ndarray, theta: np.ndarray, unit: str) -> str:
    rows = "\n".join(f"{int(k)},{v:.9f}" for k, v in zip(ticks, theta))
    path.write_text(f"time [{unit}],theta [rad]\n{rows}\n")
    return str(path)


def _two_runs(n1: int, n2: int, step: int, bits: int, before_end: int, first: int):
    """Ticks of two runs of a ``bits``-bit timer: the first from ``first``, the second
    restarted ``before_end`` ticks before the register's end (it wraps inside the run)."""
    span = 2 ** bits
    run1 = first + step * np.arange(n1)
    run2 = (span - before_end + step * np.arange(n2)) % span
    return np.concatenate([run1, run2])


def test_us_timer_restarted_near_its_end_at_rest_starts_a_run(tmp_path):
    # 32-bit µs timer, 1 ms steps; the second run never moves (released inside the stick
    # band), so the restart falls at rest; its timer starts 150 ms before the register's end
    n1, n2 = 400, 300
    ticks = _two_runs(n1, n2, 1000, 32, 150_000, first=96_970)
    theta = np.concatenate([_swing(n1, 1e-3, 0.4), np.full(n2, -0.025)])
    log = read_log(_write(tmp_path / "restart_us.csv", ticks, theta, "us"))
    assert [(r.name, r.time.size) for r in log.runs] == [("1", n1), ("2", n2)]
    # every step inside a run is the logger's 1 ms (the wrap undone, no 71-min pause)
    for r in log.runs:
        assert np.allclose(np.diff(r.time), 1e-3, rtol=0, atol=1e-9)
    restart_row = n1 + 2  # file line of the first sample after the restart (header = 1)
    assert any("restarts" in note and f"row(s) {restart_row} " in note for note in log.notes)


def test_ms_timer_restart_is_found_by_the_register_not_the_pause_length(tmp_path):
    # 16-bit ms timer sampling at 10 Hz: restarted 300 ms before its end, after a 10 s
    # run, the forward jump is ~552 steps, under RESTART_PERIODS: only the register's
    # length tells it a restart. Both runs move.
    n1, n2 = 100, 90
    ticks = _two_runs(n1, n2, 100, 16, 300, first=40)
    theta = np.concatenate([_swing(n1, 0.1, 0.5), _swing(n2, 0.1, -0.3)])
    log = read_log(_write(tmp_path / "restart_ms.csv", ticks, theta, "ms"))
    assert [(r.name, r.time.size) for r in log.runs] == [("1", n1), ("2", n2)]


def _paused_log(tmp_path, pause: int, labelled: bool):
    """A 300-sample swing, a pause of ``pause`` steps, then 200 samples at rest (1 ms
    steps, time in seconds, no timer), all in run '3' where ``labelled``."""
    n1, n2, h = 300, 200, 1e-3
    theta = np.concatenate([_swing(n1, h, 0.4), np.full(n2, 0.01)])
    t = np.concatenate([np.arange(n1) * h, (n1 - 1 + pause + np.arange(n2)) * h])
    path = tmp_path / f"pause_{pause}_{labelled}.csv"
    run, head = ("3,", "run,") if labelled else ("", "")
    path.write_text(head + "time [s],theta [rad]\n"
                    + "\n".join(f"{run}{a:.6f},{b:.9f}" for a, b in zip(t, theta)) + "\n")
    return read_log(str(path))


def test_long_pause_at_rest_starts_a_run_short_one_does_not(tmp_path):
    # a pause of 2000 steps with the gear at rest after it is a new start; one of 50 steps
    # at rest stays inside its run (the break rule's reading)
    for pause, runs in ((2000, [("1", 300), ("2", 200)]), (50, [("1", 500)])):
        log = _paused_log(tmp_path, pause, labelled=False)
        assert [(r.name, r.time.size) for r in log.runs] == runs, pause


def test_long_pause_inside_a_labelled_run_starts_a_run(tmp_path):
    # the same pause under a 'run' column (both stretches labelled '3'): a logger stopped
    # and started again inside one labelled test; the fit would otherwise simulate the
    # 2000-step pause. 50 steps stay inside the run; time that drops back inside a
    # labelled run is still refused by the time check (not split)
    for pause, runs in ((2000, [("3", 300), ("3.2", 200)]), (50, [("3", 500)])):
        log = _paused_log(tmp_path, pause, labelled=True)
        assert [(r.name, r.time.size) for r in log.runs] == runs, pause
        assert any("labelled run" in note for note in log.notes) == (pause > 1000)
    # a pause of -299 steps: the second stretch starts again at t = 0, inside '3'
    with pytest.raises(LogError, match=f"row {300 + 2}: time 0 is not after"):
        _paused_log(tmp_path, -(300 - 1), labelled=True)
