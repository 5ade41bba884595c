"""``hdid diagnose`` of the shipped 1 kHz hidden-effect log: cold and warm time, per code,
each call a fresh pinned process with its own cache folder.

    python benchmarks/diagnose_speed.py [--code before=/tmp/wt_before/src --code after=src] [--core 1]
    python benchmarks/diagnose_speed.py --render
"""

import argparse
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

from _common import DATA, ROOT, interpretation_section, load_text, parse_or_render, run_meta, user_env, write_result

NAME = "diagnose_speed"
LOG = DATA / "hidden_hysteresis_1khz.csv"

CHILD = r"""
import contextlib, json, resource, sys, time
t0 = time.perf_counter()
from hdid.cli import main
with contextlib.suppress(SystemExit):
    main(["diagnose", sys.argv[1], "--json", sys.argv[2], "--quiet"], standalone_mode=False)
wall, ru, d = time.perf_counter() - t0, resource.getrusage(resource.RUSAGE_SELF), json.load(open(sys.argv[2]))
try:
    from hdid._problems._programs import STATS as stats
except ImportError:
    stats = []
print("@@" + json.dumps({"wall_s": wall, "cpu_s": ru.ru_utime + ru.ru_stime, "timing": d.get("timing", {}),
                         "verdict": d["verdict"], "summary": d["summary"], "scanned": d.get("scanned", {}),
                         "candidates": [(c["variant"], c["delta_bic"]) for c in d["candidates"]], "programs": stats}))
"""


def measure(src: str, cache: Path, core: int, log: Path) -> dict:
    env = user_env(HDID_CACHE_DIR=str(cache), PYTHONPATH=str(Path(src).resolve()))
    with tempfile.TemporaryDirectory() as tmp:
        load0, t0 = load_text(), time.perf_counter()
        r = subprocess.run(["taskset", "-c", str(core), sys.executable, "-c", CHILD, str(log),
                            str(Path(tmp) / "d.json")], capture_output=True, text=True, env=env)
        times = {"process_wall_s": time.perf_counter() - t0, "load_start": load0, "load_end": load_text()}
    line = next((x for x in r.stdout.splitlines() if x.startswith("@@")), None)
    return {"error": (r.stderr or r.stdout)[-3000:], **times} if line is None else {**json.loads(line[2:]), **times}


def render(res: dict) -> str:
    m = res["meta"]
    lines = [f"# `hdid diagnose {Path(res['log']).name}`: time per code, cold and warm", "",
             f"Measured {m['date']} on {m['cpu']} ({m['cores']} cores, shared), each process pinned to core "
             f"{res['core']} with its own cache folder; load average (1/5/15 min) at start {m['load']}, at end "
             f"{m.get('load_end', '?')}. Source fingerprint of this checkout {m['src']}. \"cold\" = empty cache; "
             "\"warm\" = a second process with the cache the first left. Compile = JAX tracing, lowering and compiling "
             "or reading its cache (diagnose's own `timing`); the program store's rows say how many programs were read "
             "from it or traced, and the seconds of each.", "",
             "| code | cache | wall s | CPU s | compile s | fitting s | programs (store) | load start → end | verdict "
             "(first candidates) |", "|---|---|---|---|---|---|---|---|---|"]
    for r in res["rows"]:
        if "error" in r:
            lines.append(f"| {r['code']} | {r['cache']} | {r['process_wall_s']:.0f} | — | — | — | — | "
                         f"{r['load_start']} → {r['load_end']} | error: {r['error'].strip().splitlines()[-1][:120]} |")
            continue
        t = r["timing"]
        by_how: dict[str, list] = {}  # stored / traced / jit: how many programs, their seconds summed
        for p in r.get("programs", []):
            by_how.setdefault(p["how"], []).append(p)
        prog = "; ".join(f"{k} {len(v)}: {sum(p['prepare_s'] for p in v):.1f} + {sum(p['compile_s'] for p in v):.1f} s"
                         for k, v in sorted(by_how.items())) or "—"
        cands = ", ".join(f"{lb} {d:.1f}" for lb, d in r["candidates"][:3])
        lines.append(f"| {r['code']} | {r['cache']} | {r['process_wall_s']:.1f} | {r['cpu_s']:.1f} | "
                     f"{t.get('compile_s', float('nan')):.1f} | {t.get('run_s', float('nan')):.1f} | {prog} | "
                     f"{r['load_start']} → {r['load_end']} | {r['verdict']} ({cands}) |")
    lines += ["", "Programs column: `how n: prepare + compile s` — `stored`: read from the "
              "program store, `traced`: traced and lowered in this process, `jit`: the store "
              "off or failed; compile = XLA compile or a read of JAX's persistent cache.", "",
              *interpretation_section(res)]
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--code", action="append", metavar="LABEL=SRC",
                    help="a label and a source folder holding hdid/ (repeat; default: this tree)")
    ap.add_argument("--core", type=int, default=1)
    ap.add_argument("--log", default=str(LOG))
    ap.add_argument("--runs", default="cold,warm", help="cache states, in order")
    if (args := parse_or_render(ap, argv, NAME, render)) is None:
        return 0
    res = {"meta": run_meta(), "log": args.log, "core": args.core, "rows": []}
    for spec in args.code or [f"this={ROOT / 'src'}"]:
        label, src = spec.split("=", 1)
        with tempfile.TemporaryDirectory(prefix=f"diag_speed_{label}_") as cache:
            for state in args.runs.split(","):
                rec = measure(src, Path(cache), args.core, Path(args.log))
                res["rows"].append({**rec, "code": label, "cache": state, "src": src})
                print(f"{label} {state}: {rec['process_wall_s']:.1f} s (load {rec['load_start']} "
                      f"→ {rec['load_end']}) {rec.get('verdict', rec.get('error', '')[-300:])}")
                write_result(NAME, res, render)
    res["meta"]["load_end"] = load_text()
    write_result(NAME, res, render)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
