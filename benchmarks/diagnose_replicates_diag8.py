"""Replicates of one independent-suite plant and design with the hidden effect fixed and
only ``make_log``'s seed changed (release instants, encoder phase): how often is the true
position-periodic form named first (issue 19, branch ``diag8``; ``_diagnosis/_rival``)?

    taskset -c 1 python benchmarks/diagnose_replicates_diag8.py 8905:ripple:4 \
        8905:kinematic_error:4 8805:ripple:3

``PLANT:HIDDEN:N``: the rich plant and design of suite seed ``PLANT``
(:func:`diagnose_independent.draw`), the hidden effect's magnitudes as the suite draws
them (the suite's own draw for its ripple seeds 8805/8905, else a draw with seed
``PLANT + 20000``), ``N`` logs with seeds ``PLANT + 1000·j``. Writes
``results/diagnose_replicates_diag8.json`` (one record per log, printed as it goes).
"""

from __future__ import annotations

import json
import os
import re
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
import diagnose_independent as di  # noqa: E402
from _common import RESULTS, import_generate  # noqa: E402


def main(argv: list[str]) -> None:
    import hdid

    hdid.configure()
    gen, hid = import_generate(), di._hidden_module()
    out = []
    for spec in argv:
        plant, hidden, reps = spec.split(":")
        plant = int(plant)
        truth, des = di.draw("rich", plant)
        own = hidden == "ripple" and plant in (8805, 8905)
        rng = np.random.default_rng(plant + (10_000 if own else 20_000))
        hp = di.hidden_params(hidden, truth, des, rng)
        kw = hid.reference_kwargs(hidden, truth, **hp)
        mk = {k: v for k, v in des.items() if k != "gear_factor"}
        for j in range(int(reps)):
            seed = plant + 1000 * (j + 1)
            df = gen.make_log(truth, **mk, seed=seed, hidden=kw)
            t = time.perf_counter()
            d = hdid.diagnose(df)
            wall = time.perf_counter() - t
            ok = [c for c in d.candidates if c.error is None]
            lr = [re.search(r"2·ln LR = ([-+0-9.]+)", n).group(1) for n in d.notes
                  if "white floor" in n and "ranked first" in n]
            rec = dict(plant=plant, hidden=hidden, order=hp.get("order"), seed=seed,
                       verdict=d.verdict, first=ok[0].label if ok else None,
                       top=[(c.label, round(c.delta_bic, 1)) for c in ok[:3]], lr=lr,
                       wall=round(wall), load=os.getloadavg()[0])
            out.append(rec)
            print(json.dumps(rec), flush=True)
            (RESULTS / "diagnose_replicates_diag8.json").write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main(sys.argv[1:])
