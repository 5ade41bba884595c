"""The shipped paper log's tau_c posterior under the default priors (issue 17, ``post7``):
does the chain reach the Coulomb-limit plateau, and what does it then say?

Run (pinned to one core; once per tree to compare, same seed and length)::

    PYTHONPATH=TREE/src taskset -c 0 python benchmarks/posterior_coulomb_limit.py \
        --tag main --max-steps 10000 [--seed 1] [--log data/synthetic/csf8_paper.csv]

Fits the log (``hdid.fit``), runs the default ``hdid.sample_posterior`` (emcee, the mode
search, every default prior of the tree under ``PYTHONPATH``) and records: tau_c's and
the stick-band half-width's 95 % intervals, the share of the kept chain's draws (all
steps, all walkers) with tau_c below 1 mN m and 0.1 mN m, arviz's R-hat / ESS, τ_max
and the quantity it belongs to, the optima the walkers started from, the warnings, the
wall time per stage and ``os.getloadavg()`` before and after. Appends one record to
``benchmarks/results/posterior_coulomb_limit_post7.json`` (the tree's source fingerprint
and git revision with it) and rewrites the ``.md`` table from all records.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import argparse
import datetime as _dt
import json
import os
import subprocess
import time
from pathlib import Path

import numpy as np

import hdid

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
SHIPPED = ROOT / "data" / "synthetic" / "csf8_paper.csv"
NAME = "posterior_coulomb_limit_post7"
BAND = "stick_band_halfwidth_rad"


def _load():
    return [round(x, 2) for x in os.getloadavg()]


def _rev(src: Path) -> str:
    try:
        return subprocess.run(["git", "-C", str(src), "rev-parse", "--short", "HEAD"],
                              capture_output=True, text=True).stdout.strip()
    except OSError:
        return "?"


def _fingerprint(src: Path) -> str:
    """Hash of the tree under test's ``hdid/**/*.py`` (the one imported, not this file's)."""
    import hashlib

    h = hashlib.sha256()
    for f in sorted((src / "hdid").rglob("*.py")):
        h.update(str(f.relative_to(src)).encode())
        h.update(f.read_bytes())
    return h.hexdigest()[:16]


def run(log: Path, seed: int, max_steps: int, tag: str) -> dict:
    src = Path(hdid.__file__).resolve().parents[1]
    la0 = _load()
    t0 = time.perf_counter()
    fit = hdid.fit(log)
    t_fit = time.perf_counter() - t0
    post = hdid.sample_posterior(fit, seed=seed, max_steps=max_steps, progress=False)
    la1 = _load()
    d = post.to_dict()
    diag = d["posterior_diagnostics"]
    conv = diag["convergence"] or {}
    i = post.labels.index("tau_c")
    tau_c_chain = np.exp(post.chain[..., i])  # the fit's unknowns: log tau_c
    tau_c = np.asarray(post.samples["tau_c"])
    tau = dict(diag["tau"])
    worst_tau = max(tau, key=lambda k: tau[k])
    return {
        "tag": tag, "log": str(log.relative_to(ROOT) if log.is_relative_to(ROOT) else log),
        "seed": seed, "max_steps": max_steps,
        "src": str(src), "rev": _rev(src), "src_fingerprint": _fingerprint(src),
        "date_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "load_start": la0, "load_end": la1, "fit_s": t_fit,
        "fit_tau_c": fit.values["tau_c"],
        "tau_c_ci95": d["posterior"]["tau_c"]["ci95"],
        "tau_c_median": d["posterior"]["tau_c"]["median"],
        "band_ci95": d["posterior"][BAND]["ci95"],
        "tau_s_ci95": d["posterior"]["tau_s"]["ci95"],
        "v_s_ci95": d["posterior"]["v_s"]["ci95"],
        "c_v_ci95": d["posterior"]["c_v"]["ci95"],
        "share_tau_c_below_1mNm": float(np.mean(tau_c_chain < 1e-3)),
        "share_tau_c_below_0.1mNm": float(np.mean(tau_c_chain < 1e-4)),
        "thinned_share_below_1mNm": float(np.mean(tau_c < 1e-3)),
        "tau_c_min_in_chain": float(tau_c_chain.min()),
        "converged": diag["converged"], "rhat_max": conv.get("rhat_max"),
        "ess_bulk_min": conv.get("ess_bulk_min"), "ess_tail_min": conv.get("ess_tail_min"),
        "worst": conv.get("worst"),
        "rhat_tau_c": (conv.get("per_quantity") or {}).get("tau_c"),
        "tau_max": diag["tau_max"], "tau_max_of": worst_tau, "tau_tau_c": tau.get("tau_c"),
        "steps": diag["n_steps"], "burn_in": diag["burn_in"],
        "move_acceptance": diag["move_acceptance"],
        "modes": diag["modes"], "widths": d["posterior_width"],
        "wall_s": diag["wall_time_s"], "stage_s": diag["stage_s"],
        "warnings": diag["warnings"], "limits": diag.get("limits"),
    }


def render(records: list[dict]) -> str:
    head = _common.md_head(
        ["tag", "rev", "seed", "steps", "tau_c 95 % [mN m]", "share < 1 mN m", "band 95 % [mrad]",
         "converged", "R-hat max", "ESS bulk/tail min", "τ_max (of)", "optima (tau_c mN m)",
         "wall s", "load start→end"])
    rows = []
    for r in records:
        c = _common.chain_cells(r)
        opt = ", ".join(f"{m['values']['tau_c'] * 1e3:.3g} ({m['weight']:.2f})" for m in r["modes"])
        rows.append(
            f"| {r['tag']} | {r['rev']} | {r['seed']} | {r['steps']} | {c['tau_c']} | {c['share']} "
            f"| {c['band']} | {r['converged']} | {c['rhat']} | {c['ess']} | {c['tau']} | {opt} "
            f"| {c['wall']} | {c['load']} |")
    warn = []
    for r in records:
        for w in r["warnings"]:
            if not w.startswith("NOT CONVERGED"):
                warn.append(f"- {r['tag']} (seed {r['seed']}): {w}")
    return ("# The shipped log's tau_c posterior and the Coulomb-limit plateau (issue 17, post7)\n\n"
            "Written by `benchmarks/posterior_coulomb_limit.py`; one core (`taskset -c 0`), "
            "load (1-min average) at start and end. Share: kept chain, every step and walker.\n\n"
            + head + "\n".join(rows) + "\n\nWarnings other than NOT CONVERGED:\n\n"
            + ("\n".join(warn) or "- none") + "\n")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--tag", required=True)
    ap.add_argument("--log", type=Path, default=SHIPPED)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--max-steps", type=int, default=10000)
    ap.add_argument("--render", action="store_true", help="only rewrite the .md from the JSON")
    a = ap.parse_args(argv)
    out = RESULTS / f"{NAME}.json"
    records = json.loads(out.read_text())["records"] if out.exists() else []
    if not a.render:
        r = run(a.log.resolve(), a.seed, a.max_steps, a.tag)
        print(json.dumps({k: r[k] for k in ("tag", "tau_c_ci95", "band_ci95",
                                             "share_tau_c_below_1mNm", "converged", "rhat_max",
                                             "tau_max", "wall_s", "load_start", "load_end")}))
        records.append(r)
        out.write_text(json.dumps({"records": records}, indent=2, default=float) + "\n")
    (RESULTS / f"{NAME}.md").write_text(render(records))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
