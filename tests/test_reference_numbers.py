"""Same numbers before and after: every shipped log's fit against the recorded one.

The numbers were recorded by ``python tests/reference_numbers.py --write`` (the commit is
in the file's ``_recorded_at``); tolerances and what is left out are explained in
``tests/reference_numbers.py``. ``HDID_REFERENCE_EXACT=1`` compares to 1e-10 (same
machine as the recording, and the same CPU cores: XLA's CPU reductions split their sums
by the threads the process may use, so a run pinned to one core with ``taskset -c 0``
sums in another order than the 2-core recording; the rich case's start #5, a start that
ends Δχ² ≈ 29 400 above the best, then moves by ~1e-7 relative, and four near-zero
covariances by ~1e-10 — every tree, main included, fails exact mode pinned and passes it
unpinned); ``HDID_REFERENCE_ALL=1`` adds the slow cases (the EMPS real
log's driven fit, ~3 min more on one core), which CI leaves to the
by-hand run before a restructuring lands.
"""

from __future__ import annotations

import json
import os

import pytest

import reference_numbers as ref

SLOW = {"emps_train"}
STORED = json.loads(ref.STORE.read_text())
CASES = sorted(k for k in STORED if not k.startswith("_"))


@pytest.mark.parametrize("name", CASES)
def test_same_numbers_as_recorded(name):
    if name in SLOW and not os.environ.get("HDID_REFERENCE_ALL"):
        pytest.skip(f"{name}: slow; HDID_REFERENCE_ALL=1 runs it")
    if name == "emps_train" and not (ref.EMPS / "emps_train.csv").exists():
        pytest.skip(f"emps_train.csv not in {ref.EMPS} (kept outside the repository)")
    now = {k: [ref._encode(v), s] for k, (v, s) in ref.flatten(ref._cases()[name]()).items()}
    bad = ref.compare(STORED[name], now, exact=bool(os.environ.get("HDID_REFERENCE_EXACT")))
    assert not bad, f"{name}: {len(bad)} numbers moved:\n" + "\n".join(bad[:30])


def test_comparison_catches_a_moved_number():
    """The comparison itself: a shift of 2e-3 σ in k1 fails, 5e-4 σ passes (default)."""
    stored = STORED["csf8_paper"]
    key = "parameters/k1/value"
    value, sigma = stored[key]
    for shift, ok in ((2e-3, False), (5e-4, True)):
        now = dict(stored)
        now[key] = [value + shift * sigma, sigma]
        assert (not ref.compare(stored, now, exact=False)) is ok
    now = dict(stored)
    now[key] = [value * (1 + 1e-9), sigma]
    assert ref.compare(stored, now, exact=True)


def test_unconverged_starts_are_compared_by_cost_only_unless_exact():
    """Where a start the recording marks unconverged stopped depends on the order of XLA's
    sums (the cores in use: tests/reference_numbers.py); its cost, the result and every
    converged start are still compared in default mode, and everything in exact mode."""
    stored = STORED["hidden_hysteresis_1khz"]
    conv = {int(k.rsplit("/", 1)[1]): v[0] for k, v in stored.items()
            if k.startswith("starts/converged/")}
    u = min(i for i, c in conv.items() if not c)  # a start the recording marks unconverged
    c = min(i for i, c in conv.items() if c)  # and a converged one
    moved = dict(stored)
    # what a one-core process gave for an unconverged start (measured 2026-11-25: it ran
    # to convergence in 58 iterations, and another unconverged start's k1 moved by 2.4 %)
    moved[f"starts/converged/{u}"] = [True, None]
    moved[f"starts/iterations/{u}"] = [58.0, stored[f"starts/iterations/{u}"][1]]
    v, s = stored[f"starts/parameter_values/k1/{u}"]
    moved[f"starts/parameter_values/k1/{u}"] = [v * 0.976, s]
    assert not ref.compare(stored, moved, exact=False)
    assert len(ref.compare(stored, moved, exact=True)) == 3
    # a converged start's end point, the result's parameters and the unconverged start's
    # cost (on its siblings' scale, as every cost: 2e-3 of it) still count (a start's k1
    # moved by a tenth: its siblings' scale is the largest k1 among the starts, 37x its own)
    v, s = stored[f"starts/costs/{u}"]
    for key, value in ((f"starts/parameter_values/k1/{c}", stored[f"starts/parameter_values/k1/{c}"][0] * 0.9),
                       ("parameters/k1/value", stored["parameters/k1/value"][0] * 1.001),
                       (f"starts/costs/{u}", v + 2e-3 * s)):
        other = dict(stored)
        other[key] = [value, stored[key][1]]
        assert ref.compare(stored, other, exact=False), key
