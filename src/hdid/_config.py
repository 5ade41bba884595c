"""Process-wide JAX configuration: float64 everywhere; the persistent compilation cache on request.

Imported first by every module that touches JAX.
"""

from __future__ import annotations

import os
from pathlib import Path

# Equinox's runtime checks (eqx.error_if, used inside optimistix and lineax) are host
# callbacks by default, and JAX never writes executables with host callbacks to the
# persistent compilation cache — every CLI call would recompile for ~20 s. As NaNs they
# stay in the compiled code; hdid checks every result for finiteness and says so.
os.environ.setdefault("EQX_ON_ERROR", "nan")

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)


def _cache_dir() -> Path:
    env = os.environ.get("HDID_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "hdid" / "jax"


# Why the library does not turn the persistent cache on by itself. With jaxlib 0.10.2 on
# CPU, a long process that has compiled and freed many programs (the test suite: ~250
# fits of different models) was killed by SIGSEGV inside JAX's cache write, three runs
# out of three at the same call: ``executable.serialize()`` returned an error, and the
# C++ exception carrying it crashed in libgcc's unwinder (``_Unwind_Find_FDE``, core dump
# analysed with gdb), i.e. the unwinder's frame tables were already stale. A fresh
# process serializes and reads back the same program without error. A crash cannot be
# caught, so the cache is used where it pays and processes are short: the ``hdid``
# command and the worker processes it starts (``HDID_CACHE=1`` in the environment, which
# children inherit). Python sessions opt in with :func:`hdid.enable_compilation_cache`.
_ENV = "HDID_CACHE"


def enable_compilation_cache(path: str | os.PathLike | None = None) -> Path | None:
    """Turn on JAX's persistent compilation cache for this process and its children.

    A later process that compiles the same programs (a CLI call, a batch worker, a new
    Python session that also calls this) reads them from disk instead of compiling for
    ~20 s. The ``hdid`` command does this itself. Long-lived processes that compile many
    different models may be safer without it (see the comment above this function in
    ``hdid/_config.py``).

    **Arguments:**

    - `path`: the cache folder; default ``$HDID_CACHE_DIR`` or ``~/.cache/hdid/jax``.

    **Returns** the folder in use, or ``None`` when ``HDID_NO_CACHE`` is set or the
    folder cannot be created.
    """
    if os.environ.get("HDID_NO_CACHE"):
        return None
    if path is not None:
        os.environ["HDID_CACHE_DIR"] = str(path)
    folder = _cache_dir()
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    os.environ[_ENV] = "1"
    jax.config.update("jax_compilation_cache_dir", str(folder))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    return folder


if os.environ.get(_ENV) == "1":
    enable_compilation_cache()
