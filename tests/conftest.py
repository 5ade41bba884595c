"""Suite-wide fixtures."""

from __future__ import annotations

import sys

import pytest

import hdid

# The suite tests hdid's internals directly (simulators, effects, problems), not only its
# float64 entry points: configure the process as the CLI does, before JAX is imported.
# (tests/test_config.py checks the library without this, in fresh processes.)
hdid.configure()


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Free JAX's compiled programs after a test module when the process holds too many.

    Every XLA:CPU executable holds memory mappings for its JIT code (a first ``hdid.fit``
    adds ~2 700, another model ~1 400; counted in /proc/self/maps). The suite fits a few
    hundred models in one process, and with nothing freed it reached the kernel's limit of
    65 530 mappings (``vm.max_map_count``; 65 381 program headers in the core dump): the
    next mmap failed inside XLA and the process died with SIGSEGV at test ~248. The
    library's own bound (:func:`hdid._problems._programs.release` when the process holds
    more than ``MAX_MAPS_FRACTION`` of the limit after a new program) is applied here too,
    after each module, since tests also compile programs outside the store (simulators,
    Jacobians, plots). It used to clear JAX's caches after every module: on nine modules
    of fits (2026-11-24, both runs side by side at load ~4) that cost 308 s of CPU against
    272 s with this bound — the modules share the paper log's programs.
    """
    yield
    if "jax" in sys.modules:
        from hdid._problems import _programs

        if _programs._maps_over_limit():
            _programs.release()
