"""Encoder counters that roll over: a 16-, 24- or 32-bit count register wraps from its
largest value to its smallest (or back) in one sample.

A controller logs an incremental encoder's count register as it stands. Past the end of
its range the register wraps: a 16-bit signed counter steps from 32 767 to −32 768, an
unsigned one from 65 535 to 0. Read as they stand, the counts after a wrap are
2**bits counts (many revolutions) away from those before it — a motion no encoder
makes between two samples. The register's width is told by the readings themselves: the
smallest of 16, 24 and 32 bits whose signed or unsigned range holds every reading, and a
wrap is a step between consecutive rows (in file order: the counter runs on between
runs) larger than half that range which, undone, is nearer the steps around it (the
gear's speed) than as read. Each wrap is undone by adding ±2**bits to every
reading after it, the readings are moved by whole register turns to lie nearest zero,
and the log's notes say so.

The unwrapping is sure only while the counter moves well under half the register between
readings. Beyond a quarter of it, the step's change from one reading to the next (the
swing's acceleration) can reach half the register, where a wrap and a fast step read
alike: the note then says the unwrapping is ambiguous (log faster, or a wider counter).
"""

from __future__ import annotations

import numpy as np

#: Widths [bits] of the count registers that loggers write.
REGISTER_BITS = (16, 24, 32)


def _width(counts: np.ndarray) -> int | None:
    """The narrowest register whose signed or unsigned range holds every reading."""
    lo, hi = float(np.min(counts)), float(np.max(counts))
    for bits in REGISTER_BITS:
        half = 2.0 ** (bits - 1)
        if (lo >= -half and hi < half) or (lo >= 0 and hi < 2 * half):
            return bits
    return None


def unwrap_rollover(counts: np.ndarray, rows: np.ndarray, column: str
                    ) -> tuple[np.ndarray, str | None]:
    """Counts with every register wrap undone, and a note naming the wraps (None if none).

    ``counts`` are whole-number readings in file order, ``rows`` their file line numbers
    (for the note), ``column`` the column's header name.
    """
    if counts.size < 2 or not np.all(np.isfinite(counts)):
        return counts, None
    bits = _width(counts)
    if bits is None:
        return counts, None
    span = 2.0 ** bits
    steps = np.diff(counts)
    wide = np.abs(steps) > span / 2
    wraps = np.flatnonzero(wide)
    if wraps.size:
        # a wrap breaks the motion's continuity: undone, the step is nearer the steps
        # around it (the speed) than as read — a fast swing of a fine encoder whose
        # readings happen to fit the register, with steps of half of it, is no wrap
        ok = np.flatnonzero(~wide)
        if ok.size:
            left = ok[np.clip(np.searchsorted(ok, wraps) - 1, 0, None)]
            right = ok[np.clip(np.searchsorted(ok, wraps), None, ok.size - 1)]
            speed = 0.5 * (steps[left] + steps[right])
        else:
            speed = np.zeros(wraps.size)
        undone = steps[wraps] - span * np.rint(steps[wraps] / span)
        wraps = wraps[np.abs(undone - speed) < np.abs(steps[wraps] - speed)]
    if wraps.size == 0:
        return counts, None
    turns = np.zeros_like(counts)
    turns[wraps + 1] = -np.rint(steps[wraps] / span)
    out = counts + span * np.cumsum(turns)
    # whole register turns are the same reading: keep the readings nearest zero (an
    # unsigned counter just below its end reads as just below zero, not as 2**bits)
    out = out - span * np.rint(np.median(out) / span)
    shown = ", ".join(str(int(rows[i + 1])) for i in wraps[:5])
    more = f" and {wraps.size - 5} more" if wraps.size > 5 else ""
    # the motion at the wraps: the steps across them, undone, and those on either side
    near = np.clip(np.concatenate([wraps - 1, wraps, wraps + 1]), 0, steps.size - 1)
    fastest = float(np.max(np.abs(np.diff(out)[near])))
    if fastest > span / 4:
        return out, (
            f"column {column!r}: the {bits}-bit count register rolls over at row(s) "
            f"{shown}{more}, but the counter moves up to {fastest:.0f} counts between readings "
            f"(more than a quarter of its {int(span)}): a wrap and a fast step are not told "
            f"apart, so the unwrapping by ±{int(span)} counts is ambiguous — log faster or "
            "log a wider counter (32 bits)"
        )
    return out, (
        f"column {column!r}: the {bits}-bit count register rolls over at row(s) {shown}{more} "
        f"(a step of more than {int(span // 2)} counts between two samples that the steps "
        f"around it do not continue): unwrapped by ±{int(span)} counts"
    )
