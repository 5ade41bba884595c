"""Fit time and peak memory against log length: what sets the CLI's refusal threshold (``MAX_SAMPLES_PER_RUN``).

    taskset -c 0 python benchmarks/long_log.py --samples 1000,2500,5000,10000,25000
    python benchmarks/long_log.py --render      # results/long_log.md from its JSON
"""

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import interpretation_section, last_json, parse_or_render, run_meta, run_timed, write_result

RATE = 10_000.0
AMPLITUDES = [0.157, -0.157, 0.08, -0.08]

CHILD = r"""
import json, resource, sys, time
import hdid
t0 = time.perf_counter()
log, t1 = hdid.read_log(sys.argv[1]), time.perf_counter()
r = hdid.fit(log)
print(json.dumps({"read_s": t1 - t0, "fit_s": time.perf_counter() - t1, "k1": r.parameters["k1"].value,
                  "peak_rss_mb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                  "rms_counts": r.rms_residual_rad / r.resolution_rad}))
"""


def one(n: int, timeout: float, tmp: Path) -> dict:
    from hdid._simulation._synthetic import synthesize

    path, t = tmp / f"long_{n}.csv", time.perf_counter()
    synthesize(path, amplitudes=AMPLITUDES, rate=RATE, duration=n / RATE, hold=0.01, counts_per_rev=4000, seed=1,
               overwrite=True)
    row = {"samples_per_run": n, "rows": len(AMPLITUDES) * n, "mb": path.stat().st_size / 1e6,
           "simulate_s": time.perf_counter() - t}
    try:
        wall, _, out = run_timed([sys.executable, "-c", CHILD, path], {**os.environ, "HDID_NO_CACHE": "1",
                                                                        "JAX_PLATFORMS": "cpu"}, timeout)
    except subprocess.TimeoutExpired:
        return {**row, "status": f"stopped after {timeout:.0f} s"}
    except RuntimeError as e:
        return {**row, "status": "failed", "stderr": str(e).strip().splitlines()[-1:]}
    return {**row, "process_s": wall, **last_json(out), "status": "ok"}


def render(res: dict) -> str:
    meta = res["meta"]
    lines = ["# Fit time and peak memory vs log length (`benchmarks/long_log.py`)", "",
             f"{meta['date']}, {meta['cpu']}, CPU affinity {meta['affinity']}, src {meta['src']}; "
             f"4 runs at 10 kHz; each fit in a fresh process, cold (compile included, no cache).", "",
             "| samples/run | rows | CSV [MB] | read [s] | fit [s] | peak RSS [MB] | k1 | RMS [counts] | load avg before "
             "| status |", "|---|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        f = lambda k, fmt: (format(r[k], fmt) if k in r else "–")  # noqa: E731
        lines.append(f"| {r['samples_per_run']} | {r['rows']} | {f('mb', '.2f')} | {f('read_s', '.2f')} | "
                     f"{f('fit_s', '.1f')} | {f('peak_rss_mb', '.0f')} | {f('k1', '.1f')} | "
                     f"{f('rms_counts', '.3f')} | {r['load_before']:.2f} | {r['status']} |")
    return "\n".join([*lines, "", *interpretation_section(res)])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--samples", default="1000,2500,5000,10000,25000", help="samples per run, comma-separated")
    ap.add_argument("--timeout", type=float, default=600.0, help="per fit [s]")
    if (args := parse_or_render(ap, argv, "long_log", render)) is None:
        return
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for n in (int(x) for x in args.samples.split(",")):
            load = os.getloadavg()[0]
            rows.append({**one(n, args.timeout, Path(tmp)), "load_before": load})
            print(json.dumps(rows[-1]), flush=True)
            if rows[-1]["status"] != "ok":
                break
    meta = run_meta(affinity=sorted(os.sched_getaffinity(0)), load_after=os.getloadavg()[0], rate_hz=RATE,
                    amplitudes=AMPLITUDES)
    write_result("long_log", {"meta": meta, "rows": rows}, render)


if __name__ == "__main__":
    main()
