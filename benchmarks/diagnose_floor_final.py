"""The floor warning on the base fit ``diagnose`` ends with (issue 19, branch ``diag9``):
clean logs made as ``diagnose_calibration.py`` makes them (the design's seed-9001 log
fitted, logs simulated from that fit with hdid's simulator, 4000-count encoder; the paper
design's second set-up shifted by whole steps), new seeds 7000 + i, each through
``hdid.diagnose`` with every candidate; per log the verdict and ``rounding_floor`` (the
final base's χ²/F and whether it is above the design's threshold). The thresholds of
``_excess.py`` were calibrated on the base *as first fitted* (``diagnose_floor.py``).

    taskset -c 1 python benchmarks/diagnose_floor_final.py N rich|paper [FIRST]

Writes ``results/diagnose_floor_final_{design}.json`` (seeds 7000 … 7000 + N − 1), or with
FIRST > 0 ``…_{design}_from{FIRST}.json`` (seeds 7000 + FIRST onwards: more logs without
overwriting); ``--summary FILES`` prints a line each (several files of one design: also
pooled).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, import_generate  # noqa: E402


def main(n: int, design_name: str, first: int = 0) -> None:
    import hdid
    from hdid._simulation._synthetic import synthesize

    from diagnose_calibration import RICH, _second_setup

    hdid.configure()
    gen = import_generate()
    design = dict(RICH if design_name == "rich" else gen.PAPER_DESIGN)
    truth = {k: v for k, v in gen.TRUTH_CSF8.items() if k != "ratio"}
    fitted = hdid.fit(gen.make_log(truth, **{**design, "seed": 9001}))
    suffix = f"_from{first}" if first else ""
    out, dest = [], RESULTS / f"diagnose_floor_final_{design_name}{suffix}.json"
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(first, first + n):
            path = Path(tmp) / f"{design_name}_{i}.csv"
            synthesize(path, amplitudes=list(design["amplitudes"]), rate=design["fs"],
                       duration=design["duration"], hold=design["hold"], offset=0.005,
                       model=fitted.model, seed=7000 + i)
            if len(design["offsets_by_setup"]) > 1:
                _second_setup(path)
            t0, c0, load = time.perf_counter(), time.process_time(), os.getloadavg()[0]
            d = hdid.diagnose(path)
            out.append({"seed": 7000 + i, "verdict": d.verdict,
                        "rounding_floor": d.rounding_floor or {}, "warnings": d.warnings,
                        "wall": time.perf_counter() - t0, "cpu": time.process_time() - c0,
                        "load": load})
            print(json.dumps({k: out[-1][k] for k in ("seed", "verdict", "wall", "load")}),
                  flush=True)
            dest.write_text(json.dumps(out, indent=1) + "\n")


def summary(files: list[str]) -> None:
    import numpy as np

    from hdid._diagnosis._rates import upper_bound

    groups = [(Path(f).name, json.loads(Path(f).read_text())) for f in files]
    if len(groups) > 1:
        groups.append(("pooled", [x for _, R in groups for x in R]))
    for name, R in groups:
        r = np.array([x["rounding_floor"]["chi2_over_floor"] for x in R])
        warned = sum(bool(x["rounding_floor"]["exceeded"])
                     and x["verdict"] in ("adequate", "unexplained") for x in R)
        verdicts = {v: sum(x["verdict"] == v for x in R) for v in {x["verdict"] for x in R}}
        print(f"{name}: {len(R)} logs, chi2/F {r.mean():.3f} ± {r.std(ddof=1):.3f}, "
              f"median {np.median(r):.3f}, max {r.max():.3f}; warned {warned} "
              f"(one-sided 95 % bound {upper_bound(warned, len(R)):.1%}); verdicts {verdicts}")


if __name__ == "__main__":
    if sys.argv[1] == "--summary":
        summary(sys.argv[2:])
    else:
        main(int(sys.argv[1]), sys.argv[2], int(sys.argv[3]) if len(sys.argv) > 3 else 0)
