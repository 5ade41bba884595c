"""Before/after a restructuring, through the public CLI only (so it runs on any tree):
``hdid fit LOG -q --json OUT`` for each source tree, alternating, (a) with an empty
persistent cache (cold: every program traced and compiled), (b) again with that cache
(the second call of a user: programs read from the store), and ``hdid --help``.
Same numbers are checked too: the JSON's parameters of both trees must agree.

Run::

    python benchmarks/architecture_speed.py --tree before=/tmp/snap_old/src \\
        --tree after=src [--repeats 3] [--log data/synthetic/csf8_paper.csv]

Each ``--tree NAME=SRC`` is put first on ``PYTHONPATH`` (an installed hdid is overridden).
Writes ``benchmarks/results/architecture_speed.{md,json}``; the load average is recorded
beside every timing (the machine is shared).
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
RESULTS = ROOT / "benchmarks" / "results"


def _run(src: str, args: list[str], cache: str) -> tuple[float, str, float]:
    env = {**os.environ, "PYTHONPATH": src, "HDID_CACHE_DIR": cache}
    load = os.getloadavg()[0]
    t0 = time.perf_counter()
    out = subprocess.run([sys.executable, "-m", "hdid.cli", *args], env=env,
                         capture_output=True, text=True)
    wall = time.perf_counter() - t0
    if out.returncode != 0:
        raise SystemExit(f"{src}: hdid {' '.join(args)} failed:\n{out.stderr[-2000:]}")
    return wall, out.stdout, load


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--tree", action="append", required=True, help="NAME=SRC")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--log", default=str(ROOT / "data" / "synthetic" / "csf8_paper.csv"))
    ap.add_argument("--out-dir", default=str(RESULTS))
    a = ap.parse_args()
    trees = dict(t.split("=", 1) for t in a.tree)
    rows: dict[str, dict[str, list]] = {n: {"cold": [], "warm": [], "help": [], "params": []}
                                        for n in trees}
    for rep in range(a.repeats):
        for name, src in trees.items():
            with tempfile.TemporaryDirectory() as cache, tempfile.TemporaryDirectory() as tmp:
                out = str(Path(tmp) / "fit.json")
                for kind in ("cold", "warm"):
                    wall, _, load = _run(src, ["fit", a.log, "-q", "--json", out], cache)
                    rows[name][kind].append((wall, load))
                d = json.loads(Path(out).read_text())
                rows[name]["params"].append({k: v["value"] for k, v in d["parameters"].items()})
                wall, _, load = _run(src, ["--help"], cache)
                rows[name]["help"].append((wall, load))
            print(f"rep {rep}: {name} cold {rows[name]['cold'][-1][0]:.1f} s, warm "
                  f"{rows[name]['warm'][-1][0]:.1f} s (load {rows[name]['warm'][-1][1]:.2f})",
                  flush=True)
    names = list(trees)
    ref = rows[names[0]]["params"][0]
    worst = 0.0
    for n in names:
        for p in rows[n]["params"]:
            for k, v in p.items():
                worst = max(worst, abs(v - ref[k]) / max(abs(ref[k]), 1e-300))
    lines = ["# Before/after a restructuring, public CLI only", "",
             f"`python benchmarks/architecture_speed.py {' '.join('--tree ' + t for t in a.tree)}"
             f" --repeats {a.repeats}`; log `{Path(a.log).name}`; "
             f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}; {os.cpu_count()} cores.", "",
             "| tree | cold fit: median (min) s | warm fit (stored programs): median (min) s "
             "| `hdid --help` s | load averages (1 min) |", "|---|---|---|---|---|"]
    for n in names:
        r = rows[n]

        def med(k):
            xs = [w for w, _ in r[k]]
            return f"{statistics.median(xs):.1f} ({min(xs):.1f})"

        loads = [ld for k in ("cold", "warm") for _, ld in r[k]]
        lines.append(f"| {n} | {med('cold')} | {med('warm')} | {med('help')} | "
                     f"{min(loads):.1f}–{max(loads):.1f} |")
    lines += ["", f"Largest relative difference of any fitted parameter between trees and "
              f"repeats: {worst:.2e}."]
    Path(a.out_dir).mkdir(parents=True, exist_ok=True)
    (Path(a.out_dir) / "architecture_speed.md").write_text("\n".join(lines) + "\n")
    (Path(a.out_dir) / "architecture_speed.json").write_text(json.dumps(
        {"trees": trees, "rows": rows, "max_rel_param_diff": worst}, indent=1))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
