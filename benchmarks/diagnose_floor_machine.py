"""Does the floor calibration's χ²/F depend on the machine? (issue 19, lead, after diag9)

Re-fits, on this machine, the first ``N`` clean calibration logs of ``DESIGN`` stored in
``results/diagnose_floor.json`` (same seeds, same recipe, same base fit as
``diagnose_floor.py``: :func:`diagnose_floor.base_row`) and compares each log's ratio with
the stored one. Writes ``results/diagnose_floor_machine_{design}.json``. With ``final``:
the logs of ``results/diagnose_floor_final_{design}*.json`` instead (seeds 7000 + i), the
first fit's ratio here against the ratio ``hdid.diagnose`` reported for its final base
(``…_machine_{design}_final.json``).

    taskset -c 1 python benchmarks/diagnose_floor_machine.py N rich|paper [final]
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import RESULTS, cpu_model, import_generate  # noqa: E402


def _final(name: str) -> dict:
    rows = {}
    for f in sorted(RESULTS.glob(f"diagnose_floor_final_{name}*.json")):
        for x in json.loads(f.read_text()):
            rf = x["rounding_floor"]
            rows[x["seed"]] = {"ratio": rf["chi2_over_floor"], "chi2": rf.get("chi2"),
                               "floor": rf.get("floor")}
    return rows


def main(n: int, name: str, final: bool = False) -> None:
    import hdid
    from hdid._simulation._synthetic import synthesize

    from diagnose_calibration import RICH, _second_setup
    from diagnose_floor import base_row

    stored = json.loads((RESULTS / "diagnose_floor.json").read_text())
    old = (_final(name) if final else
           {r["seed"]: r for r in stored["rows"] if r["design"] == name and r["kind"] == "calibration"})
    seeds = sorted(old)[:n]
    gen = import_generate()
    design = dict(RICH if name == "rich" else gen.PAPER_DESIGN)
    truth = {k: v for k, v in gen.TRUTH_CSF8.items() if k != "ratio"}
    fitted = hdid.fit(gen.make_log(truth, **{**design, "seed": 9001}))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for seed in seeds:
            path = Path(tmp) / f"{name}_{seed}.csv"
            synthesize(path, amplitudes=list(design["amplitudes"]), rate=design["fs"],
                       duration=design["duration"], hold=design["hold"], offset=0.005,
                       model=fitted.model, seed=seed)
            if len(design["offsets_by_setup"]) > 1:
                _second_setup(path)
            row = base_row(str(path), f"{name} cal {seed}")
            rows.append({"seed": seed, "ratio_here": row["ratio"], "ratio_stored": old[seed]["ratio"],
                         "chi2_here": row["chi2"], "chi2_stored": old[seed]["chi2"],
                         "floor_here": row["floor"], "floor_stored": old[seed]["floor"],
                         "load1": row["load1"]})
    here = np.array([r["ratio_here"] for r in rows]); st = np.array([r["ratio_stored"] for r in rows])
    summary = {"design": name, "logs": len(rows), "cpu_here": cpu_model(),
               "cpu_stored": stored["meta"].get("cpu"), "stored": "diagnose's final base (diagnose_floor_final)"
               if final else f"first fit, src {stored['meta']['by_design'][name]['src']}",
               "mean_here": here.mean(), "mean_stored": st.mean(),
               "max_abs_diff": float(np.max(np.abs(here - st))),
               "n_differ_1e-6": int(np.sum(np.abs(here - st) > 1e-6)),
               "n_here_above_stored": int(np.sum(here > st + 1e-6))}
    print(json.dumps(summary, indent=1))
    (RESULTS / f"diagnose_floor_machine_{name}{'_final' if final else ''}.json").write_text(
        json.dumps({"summary": summary, "rows": rows}, indent=1, default=float) + "\n")


if __name__ == "__main__":
    main(int(sys.argv[1]), sys.argv[2], sys.argv[3:4] == ["final"])
