"""``import hdid`` changes no process-wide setting; hdid's calls still compute in float64.

Each check runs in a fresh Python process without ``hdid.configure()`` (the rest of the
suite is configured in conftest.py, as the CLI configures its process).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import reference_numbers as ref

ROOT = Path(__file__).resolve().parents[1]
PAPER = ROOT / "data" / "synthetic" / "csf8_paper.csv"


def _fresh(code: str, tmp_path) -> dict:
    env = {k: v for k, v in os.environ.items() if k != "EQX_ON_ERROR"}
    env["HDID_CACHE_DIR"] = str(tmp_path / "cache")  # must stay untouched without configure
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                         env=env, cwd=tmp_path, timeout=900)
    assert out.returncode == 0, out.stderr[-3000:]
    return json.loads(out.stdout.strip().splitlines()[-1])


def test_library_without_configure_is_float64_and_leaves_the_process_alone(tmp_path):
    code = f"""
import json, os, sys
import hdid
r = hdid.fit({str(PAPER)!r})
with hdid.bare_figures():  # a figure only saved: no pyplot
    hdid.save_figure(r.plot(), "fit.png")
import jax, jax.numpy as jnp
print(json.dumps({{
    "x64": bool(jax.config.jax_enable_x64),
    "user_dtype": str(jnp.ones(1).dtype),
    "eqx_env": os.environ.get("EQX_ON_ERROR"),
    "cache_dir": jax.config.jax_compilation_cache_dir,
    "pyplot": "matplotlib.pyplot" in sys.modules,
    "predict_dtype": str(r.predict().dtype),
    "fit": r.to_dict(),
}}))
"""
    got = _fresh(code, tmp_path)
    # the caller's JAX keeps its precision and settings; no backend chosen, no env written
    assert got["x64"] is False and got["user_dtype"] == "float32"
    assert got["eqx_env"] is None and got["cache_dir"] is None and got["pyplot"] is False
    assert not (tmp_path / "cache").exists()
    assert (tmp_path / "fit.png").stat().st_size > 10_000
    # hdid's own arithmetic is float64: the same numbers as the configured recording
    # (tolerance: tests/reference_numbers.py; a float32 fit misses k1 by ~1e-4 relative,
    # thousands of times more)
    assert got["predict_dtype"] == "float64"
    stored = json.loads(ref.STORE.read_text())["csf8_paper"]
    now = {k: [ref._encode(v), s] for k, (v, s) in ref.flatten(got["fit"]).items()}
    bad = ref.compare(stored, now, exact=False)
    assert not bad, "\n".join(bad[:20])


def test_configure_sets_up_the_process(tmp_path):
    code = """
import json, os
import hdid
hdid.configure()
import jax, jax.numpy as jnp
print(json.dumps({"x64": bool(jax.config.jax_enable_x64), "dtype": str(jnp.ones(1).dtype),
                  "eqx_env": os.environ.get("EQX_ON_ERROR"),
                  "cache_dir": jax.config.jax_compilation_cache_dir}))
"""
    got = _fresh(code, tmp_path)
    assert got == {"x64": True, "dtype": "float64", "eqx_env": "nan",
                   "cache_dir": str(tmp_path / "cache")}


def test_to_dict_is_strict_json_whatever_the_values():
    """A NaN or infinite number (an undetermined std, a bracket that does not exist) is
    written as null by the library itself, not only by the CLI: ``allow_nan=False``."""
    import dataclasses
    import math

    import hdid
    from hdid._results._summaries import ParameterEstimate

    r = hdid.fit(PAPER, n_starts=1, max_steps=3, nested=False)  # any fit will do
    p = r.parameters["k1"]
    r.parameters["k1"] = dataclasses.replace(p, std=math.inf)
    r.derived["stick_band_halfwidth_rad"] = (math.nan, math.nan)
    assert isinstance(r.parameters["k1"], ParameterEstimate)
    d = r.to_dict()
    json.dumps(d, allow_nan=False)
    assert d["parameters"]["k1"]["std"] is None
    assert d["stick_band_halfwidth_std_rad"] is None
