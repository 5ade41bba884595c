"""`hdid diagnose` warm, with and without reading stored programs in the background.

:func:`hdid._problems._programs.prefetch` reads the candidates' stored programs (the XLA
executable from JAX's persistent cache: 0.2–2.7 s each) in a background thread while the
caller fits; it can only help where a core is free, so each process runs on **both**
cores (no ``taskset``), and the comparison means something only on a quiet machine: the
load average is written beside every row. One cache folder, filled by a first (cold)
process; then ``--repeats`` warm processes per setting, alternating (``HDID_PREFETCH=0``
= off, the default = on). Every warm row's verdict and candidates' ΔBIC must be the same
(the prefetch changes where a program is read, not what runs): the file says whether
they are.

    python benchmarks/program_prefetch.py [--src src] [--repeats 3] [--out program_prefetch]
    python benchmarks/program_prefetch.py --render
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import interpretation_section, parse_or_render, result_writer, run_meta  # noqa: E402
import diagnose_speed  # noqa: E402
from diagnose_speed import LOG, summarize_programs  # noqa: E402


def measure(src: str, cache: Path, prefetch: bool) -> dict:
    """One process of :mod:`diagnose_speed` on both cores (``taskset -c 0,1``)."""
    old = os.environ.get("HDID_PREFETCH")
    os.environ["HDID_PREFETCH"] = "1" if prefetch else "0"
    try:
        return diagnose_speed.measure(src, cache, "0,1", LOG)
    finally:
        os.environ.pop("HDID_PREFETCH") if old is None else os.environ.update(HDID_PREFETCH=old)


def render(res: dict) -> str:
    m = res["meta"]
    lines = [
        f"# `hdid diagnose {Path(res['log']).name}` warm: programs read in the background or not",
        "",
        f"Measured {m['date']} on {m['cpu']} ({m['cores']} cores, shared; every process on "
        f"both cores), load average (1/5/15 min) at start {m['load']}, at end "
        f"{m.get('load_end', '?')}. Source {res['src']} (fingerprint {m['src']}). One cache "
        "folder filled by the cold row; warm rows alternate `HDID_PREFETCH=0` (off) and the "
        "default (on). Compile = the caller's wait for programs; background = the reads "
        "done while it fitted.", "",
        "| prefetch | cache | wall s | CPU s | compile (wait) s | background s | fitting s | "
        "programs | load start → end | verdict (first candidates) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in res["rows"]:
        if "error" in r:
            lines.append(f"| {r['prefetch']} | {r['cache']} | error: "
                         f"{r['error'].strip().splitlines()[-1][:120]} |")
            continue
        t = r["timing"]
        ps = summarize_programs(r.get("programs", []))
        prog = "; ".join(f"{k} {v['n']}" for k, v in sorted(ps.items()))
        if t.get("programs_prefetched"):
            prog += f" ({t['programs_prefetched']} in the background)"
        first = ", ".join(f"{lb} {d:.3f}" for lb, d in r["candidates"][:3])
        cells = [r["prefetch"], r["cache"], f"{r['process_wall_s']:.1f}", f"{r['cpu_s']:.1f}",
                 f"{t['compile_s']:.1f}", f"{t.get('compile_background_s', 0.0):.1f}",
                 f"{t['run_s']:.1f}", prog, f"{r['load_start']} → {r['load_end']}",
                 f"{r['verdict']} ({first})"]
        lines.append("| " + " | ".join(cells) + " |")
    warm = [r for r in res["rows"] if r["cache"] == "warm" and "error" not in r]
    same = len({json.dumps([r["verdict"], r["candidates"]]) for r in warm}) == 1
    lines += ["", f"Every warm row's verdict and candidates' ΔBIC identical: **{same}**.", ""]
    for on in (False, True):
        w = sorted(r["process_wall_s"] for r in warm if r["prefetch"] == ("on" if on else "off"))
        if w:
            lines.append(f"- prefetch {'on' if on else 'off'}: warm wall median "
                         f"{w[len(w) // 2]:.1f} s over {len(w)} processes")
    lines += [""] + interpretation_section(res)
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--src", default="src", help="source folder holding hdid/")
    ap.add_argument("--repeats", type=int, default=3)
    ap.add_argument("--out", default="program_prefetch")
    args = parse_or_render(ap, argv, lambda a: a.out, render)
    if args is None:
        return 0
    res = {"meta": run_meta(), "log": str(LOG), "src": args.src, "rows": []}
    write = result_writer(args.out, render)

    plan = [("cold", True)] + [("warm", on) for _ in range(args.repeats) for on in (False, True)]
    with tempfile.TemporaryDirectory(prefix="program_prefetch_") as cache:
        for state, on in plan:
            rec = measure(args.src, Path(cache), on)
            rec.update(prefetch="on" if on else "off", cache=state)
            write(res, row=rec, label=f"{rec['prefetch']} {state}")
    write(res, end=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
