"""The ``hdid`` process ends as the interpreter would end it, less the teardown.

At exit the interpreter joins other threads, runs the exit handlers, flushes output and then
frees every module, JAX's compiled programs and XLA's client one by one (≈ 1 s of a cold
``hdid fit``). The ``hdid`` command (``main()`` called with no arguments, as the console script
and ``python -m hdid.cli`` call it) keeps the first three and skips the freeing; ``main([...])``,
as programs and tests call it, is click's own.
"""

from __future__ import annotations

import subprocess
import sys
import textwrap

import pytest

# A child that leaves a trace of each part of the exit: a thread still writing when the
# command ends, an exit handler, and an object whose finaliser runs only in the teardown.
CHILD = textwrap.dedent("""
    import atexit, sys, threading, time
    from hdid.cli import main

    class Freed:
        def __del__(self):
            print("teardown ran", flush=True)

    kept = Freed()
    def slow():
        time.sleep(0.3)
        print("thread done", flush=True)
    threading.Thread(target=slow).start()
    atexit.register(lambda: print("exit handler ran", flush=True))
    sys.argv = ["hdid", *sys.argv[1:]]
    print("before the command", end="")  # unflushed: the exit must flush it
    main({args})
""")


def _run(args: list[str], call: str = "") -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", CHILD.format(args=call), *args],
                          capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize("args, code", [(["--version"], 0), (["fit", "--no-such-option"], 2)])
def test_command_exits_without_teardown(args, code):
    p = _run(args)
    assert p.returncode == code, p.stderr
    out = p.stdout
    assert out.startswith("before the command") and "thread done" in out and "exit handler ran" in out
    # the thread is joined before the exit handlers, as the interpreter orders them
    assert out.index("thread done") < out.index("exit handler ran")
    assert "teardown ran" not in out
    if code == 2:  # a usage error stays one line on stderr
        assert len(p.stderr.strip().splitlines()) == 1 and "no-such-option" in p.stderr


def test_called_by_a_program_is_clicks_own():
    # main(["--version"]) exits through SystemExit and the interpreter's whole exit
    p = _run([], call='["--version"]')
    assert p.returncode == 0, p.stderr
    assert "exit handler ran" in p.stdout and "teardown ran" in p.stdout
