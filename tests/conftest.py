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


#: Seconds the longest test files take (setup + call + teardown of their tests, summed, from
#: a full ``-n 2 --dist loadfile`` run's ``--junitxml``; load ~10, divided by 5.4 to a quiet
#: 2-core machine). Only their order is used (see ``pytest_xdist_make_scheduler``); a file
#: not listed counts as short. Refresh after a file's cost changes a lot: run the suite with
#: ``--junitxml=j.xml`` and sum each file's ``time`` attributes.
LONG_FILES = {
    "tests/test_driven.py": 116, "tests/test_real_pendulum.py": 107, "tests/test_fit.py": 100,
    "tests/test_cli.py": 99, "tests/test_real_emps.py": 88, "tests/test_batch.py": 79,
    "tests/test_real_logs_synthetic.py": 65, "tests/test_printed_readings.py": 62,
    "tests/test_posterior.py": 58, "tests/test_reference_numbers.py": 54,
    "tests/test_batch_dask.py": 53, "tests/test_posterior_basin.py": 52,
    "tests/test_notebooks.py": 50, "tests/test_design.py": 34, "tests/test_effect_plugins.py": 33,
    "tests/test_diagnose.py": 32, "tests/test_json_schema.py": 30, "tests/test_model.py": 26,
    "tests/test_result_protocol.py": 26, "tests/test_readme.py": 24,
    "tests/test_posterior_limits.py": 24, "tests/test_pendulum_starts.py": 22,
}


def _file_cost(scope: str, n_tests: int) -> tuple[float, int]:
    """How long a file is expected to take: its listed seconds, then its number of tests."""
    return LONG_FILES.get(scope.split("::")[0], 0.0), n_tests


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    """``--dist loadfile`` with the longest files first.

    pytest-xdist hands a worker the next file when it is nearly idle, in order of the
    files' number of tests (most first), so a long file with few tests (one fit of a real
    log, a notebook) is handed out late; handed out last, it runs alone on one worker while
    the other has nothing left. Longest first (the classic rule for two machines, "LPT")
    leaves only short files for the end, so the workers finish within about the last short
    file of each other. (Simulated on the per-file seconds above, in xdist's order the two
    workers happened to end within 2 s of each other: this keeps it so as files change.)
    """
    if config.getvalue("dist") != "loadfile" or not config.getvalue("loadscopereorder"):
        return None  # other modes, and --no-loadscope-reorder (collection order), as xdist has them
    from xdist.scheduler import LoadFileScheduling

    class LongestFileFirst(LoadFileScheduling):
        _ordered = False

        def _assign_work_unit(self, node):
            if not self._ordered:  # the queue is complete when the first file is handed out
                order = sorted(self.workqueue.items(), key=lambda kv: _file_cost(kv[0], len(kv[1])),
                               reverse=True)
                self.workqueue.clear()
                self.workqueue.update(order)
                self._ordered = True
            super()._assign_work_unit(node)

    return LongestFileFirst(config, log)
