"""Suite-wide fixtures."""

from __future__ import annotations

import gc
import sys

import pytest

import hdid

# The suite tests hdid's internals directly (simulators, effects, problems), not only its
# float64 entry points: configure the process as the CLI does, before JAX is imported.
# (tests/test_config.py checks the library without this, in fresh processes.)
hdid.configure()


@pytest.fixture(autouse=True, scope="module")
def _release_compiled_programs():
    """Free JAX's compiled programs after each test module.

    Every XLA:CPU executable holds memory mappings for its JIT code (a first ``hdid.fit``
    adds ~2 700, another model ~1 400; counted in /proc/self/maps). The suite fits a few
    hundred models in one process, and without this it reached the kernel's limit of
    65 530 mappings (``vm.max_map_count``; 65 381 program headers in the core dump): the
    next mmap failed inside XLA and the process died with SIGSEGV at test ~248. Modules
    share nothing compiled that is worth the risk; the persistent cache keeps recompiles
    cheap.
    """
    yield
    if "jax" in sys.modules:
        sys.modules["jax"].clear_caches()
        gc.collect()
