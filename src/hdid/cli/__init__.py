"""Command line: ``hdid fit``, ``hdid diagnose`` and ``hdid simulate`` (pyhf's ``cli/``: one
file per command — parse, call the public library, print, write JSON).

The commands only parse arguments, call the library, print a report and write files;
all science lives in the library. Heavy imports (jax) happen inside the commands so
that ``hdid --help`` answers at once.
"""

from __future__ import annotations

from ._common import EXIT_PARTIAL, MAX_SAMPLES_PER_RUN
from ._main import main

__all__ = ["EXIT_PARTIAL", "MAX_SAMPLES_PER_RUN", "main"]
