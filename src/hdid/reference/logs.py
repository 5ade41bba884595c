"""Synthetic logs from the independent reference simulators: one module for the tests, the
benchmarks, the calibrations and the notebooks (``from hdid.reference import logs``).

What it is for: logs whose truth is known, made by physics written a second time — the
event-driven numpy/scipy simulators of :mod:`hdid.reference` — so that hdid's fits,
diagnoses and posteriors are checked against code they share nothing with.  Nothing here
imports JAX or hdid's simulators, models or effects (``tests/test_driven_reference.py``
checks every module of :mod:`hdid.reference`).  A user makes logs with ``hdid simulate``
(hdid's own simulator); this module is the test oracle's.

* Free motion: :func:`make_log` (any truth and design, optionally with a hidden effect),
  the CSF-8-100-like :data:`TRUTH_CSF8`, the shipped designs :data:`PAPER_DESIGN`,
  :data:`RICH_DESIGN` and :data:`HIDDEN_DESIGN`, :func:`rest_gap` and :func:`encoder_step`.
* Broad plants (the diagnose suite's): :func:`draw_plant`, :func:`hidden_params`,
  :func:`suite_log`.
* Hidden effects: :data:`HIDDEN` (each library effect, and one outside the library, written
  in numpy for the reference simulator) and :func:`reference_kwargs`.
* Driven joint: the reference simulator :func:`simulate_driven` with its physics pieces
  (:func:`capacity`, :func:`sliding_friction`, :func:`inverse_stiffness`,
  :func:`positional_error`), and :func:`make_driven_log` with :data:`TRUTH_DRIVEN_CSF8` and
  :data:`DRIVEN_DESIGN`.

The shipped files of ``data/synthetic`` are these logs: ``python data/synthetic/generate.py``
regenerates them all, bit for bit (fixed seeds).
"""

from __future__ import annotations

from ._driven import capacity, inverse_stiffness, positional_error, simulate_driven, sliding_friction
from ._driven_log import DRIVEN_DESIGN, OUTPUT_COUNTS_PER_REV, TRUTH_DRIVEN_CSF8, make_driven_log
from ._hidden import HIDDEN, reference_kwargs
from ._suite import draw_plant, hidden_params, suite_log
from ._logs import (
    COUNTS_PER_REV,
    HIDDEN_DESIGN,
    PAPER_DESIGN,
    PARAM_NAMES,
    RICH_DESIGN,
    TRUTH_CSF8,
    encoder_step,
    make_log,
    rest_gap,
)

__all__ = [
    "COUNTS_PER_REV",
    "DRIVEN_DESIGN",
    "HIDDEN",
    "HIDDEN_DESIGN",
    "OUTPUT_COUNTS_PER_REV",
    "PAPER_DESIGN",
    "PARAM_NAMES",
    "RICH_DESIGN",
    "TRUTH_CSF8",
    "TRUTH_DRIVEN_CSF8",
    "capacity",
    "draw_plant",
    "encoder_step",
    "hidden_params",
    "inverse_stiffness",
    "make_driven_log",
    "make_log",
    "positional_error",
    "reference_kwargs",
    "rest_gap",
    "simulate_driven",
    "sliding_friction",
    "suite_log",
]
