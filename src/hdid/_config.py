"""hdid's JAX settings, made explicit: importing hdid changes nothing in the process.

- :func:`float64` — hdid computes in float64. Every public entry point (``hdid.fit``,
  ``fit_many``, ``fit_driven``, ``fit_joint``, ``simulate``, ``simulate_driven``,
  ``diagnose``, ``model_ladder``, ``sample_posterior`` and the results' computing methods)
  runs inside ``jax.enable_x64(True)``, a *thread-local* switch: the caller's own JAX code
  keeps its own precision. Worker threads and processes that hdid starts enter it again.
- :func:`configure` — what an application calls once, first thing, before it imports JAX
  or equinox (the ``hdid`` command does): float64 process-wide, JAX's persistent
  compilation cache in hdid's cache folder, and equinox's runtime checks as NaN
  (``EQX_ON_ERROR=nan``; hdid checks every result for finiteness and says so). The last
  one is what lets a later process reuse compiled programs: JAX never writes executables
  with host callbacks — equinox's default checks — to the persistent cache, so without it
  every new process recompiles (~20 s per model structure). A script can call
  ``hdid.configure()`` for the same speed; without it, hdid still computes in float64.
"""

from __future__ import annotations

import contextlib
import functools
import os
import sys
from pathlib import Path


def cache_dir() -> Path:
    """hdid's cache folder: ``$HDID_CACHE_DIR``, else ``$XDG_CACHE_HOME/hdid/jax``."""
    env = os.environ.get("HDID_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "hdid" / "jax"


_cache_dir = cache_dir  # the program store's name for it


def enable_compilation_cache() -> Path | None:
    """Turn on JAX's persistent compilation cache in :func:`cache_dir` (process-wide;
    ``HDID_NO_CACHE=1`` leaves it off). Returns the folder, or None."""
    if os.environ.get("HDID_NO_CACHE"):
        return None
    path = cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    import jax

    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    return path


def configure(*, x64: bool = True, compilation_cache: bool = True,
              equinox_errors: str | None = "nan") -> None:
    """Set up this process for hdid: call it first, before importing JAX or equinox.

    ``x64``: float64 for all JAX code of the process (hdid's own calls are float64
    either way). ``compilation_cache``: :func:`enable_compilation_cache`.
    ``equinox_errors``: the value of ``EQX_ON_ERROR`` (``None`` leaves it); equinox reads
    it once, on import, so it takes effect only if equinox is not imported yet — otherwise
    a ``RuntimeWarning`` says so. The variable is also inherited by child processes.
    """
    if equinox_errors is not None:
        if "equinox" in sys.modules:
            if os.environ.get("EQX_ON_ERROR", "raise") != equinox_errors:
                import warnings

                warnings.warn(
                    f"hdid.configure(equinox_errors={equinox_errors!r}): equinox is already "
                    "imported and keeps its setting; call hdid.configure() before importing "
                    "equinox (or JAX libraries built on it) for fast restarts",
                    RuntimeWarning, stacklevel=2)
        else:
            os.environ["EQX_ON_ERROR"] = equinox_errors
    import jax

    if x64:
        jax.config.update("jax_enable_x64", True)
    if compilation_cache:
        enable_compilation_cache()


def float64(fn=None):
    """``with float64():`` or ``@float64``: hdid's arithmetic, float64, thread-local."""
    if fn is None:
        return _float64_context()

    @functools.wraps(fn)
    def wrapper(*args, **kwargs):
        with _float64_context():
            return fn(*args, **kwargs)

    return wrapper


@contextlib.contextmanager
def _float64_context():
    import jax

    if jax.config.jax_enable_x64:
        yield
        return
    with jax.enable_x64(True):
        yield


def float64_methods(cls):
    """Class decorator: every public method and property of ``cls`` runs in
    :func:`float64` (results whose methods simulate, predict or plot)."""
    for name, attr in list(vars(cls).items()):
        if name.startswith("_"):
            continue
        if isinstance(attr, property):
            setattr(cls, name, property(float64(attr.fget), attr.fset, attr.fdel, attr.__doc__))
        elif isinstance(attr, (classmethod, staticmethod)):
            setattr(cls, name, type(attr)(float64(attr.__func__)))
        elif callable(attr):
            setattr(cls, name, float64(attr))
    return cls
