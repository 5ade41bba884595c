"""Process-wide JAX configuration: float64 everywhere and a persistent compilation cache.

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


def enable_compilation_cache() -> Path | None:
    """Turn on JAX's persistent compilation cache (set HDID_NO_CACHE=1 to disable)."""
    if os.environ.get("HDID_NO_CACHE"):
        return None
    path = _cache_dir()
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError:
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", -1)
    return path


enable_compilation_cache()
