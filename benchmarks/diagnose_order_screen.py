"""The order scan's one-step screen on the shipped 1 kHz log: one Gauss–Newton step per
order (a full Jacobian from the LM program each, diag4) against every order from one
Jacobian and one program of the added columns (``_refit.gauss_newton_orders``, diag5).
Both in one process, programs already loaded (a first call of each before timing), at the
base model's best grid point with the effect at zero; CPU and wall seconds per screen of
all ``MAX_ORDER`` orders, and the largest relative difference of the gains.

    taskset -c 0 python benchmarks/diagnose_order_screen.py
"""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from _common import DATA, RESULTS, load_text, run_meta  # noqa: E402


def main() -> None:
    import numpy as np

    import hdid
    from hdid import _refit
    from hdid._diagnose_candidates import KINEMATIC_ORDERS, _reorder
    from hdid._io import read_log
    from hdid.effects import library

    meta = run_meta(cmd="taskset -c 0 python benchmarks/diagnose_order_screen.py")
    log = read_log(DATA / "hidden_hysteresis_1khz.csv")
    base = _refit.setup(log, hdid.Model.default(), {})
    u = _refit.grid(base, 1)[0]
    values = {**base.model.float_values(),
              **{k: float(v) for k, v in base.problem.unpack_np(u)[0].items()}}
    m0 = base.model.replace(**{k: v for k, v in values.items()
                               if k in base.model.float_values()})
    rows = []
    for key in ("ripple", "kinematic_error"):
        m = m0.with_effect(library({**values, "order": 1.0})[key])
        s = _refit.setup(log, m, {})
        u0 = _refit.warm(s, m.float_values(), _refit.tail_of(base.problem, u))
        added = [n for n in s.problem.free if n not in base.problem.free]
        orders = list(KINEMATIC_ORDERS)
        setups = [s] + [_reorder(s, key, n) for n in orders[1:]]
        _refit.gauss_newton_step(s, u0, added)  # programs loaded before timing
        _refit.gauss_newton_orders(s, u0, key, added, orders)
        t0, c0 = time.perf_counter(), time.process_time()
        old = [_refit.gauss_newton_step(sn, u0, added)[0] for sn in setups]
        t1, c1 = time.perf_counter(), time.process_time()
        new = [g for g, _ in _refit.gauss_newton_orders(s, u0, key, added, orders)]
        t2, c2 = time.perf_counter(), time.process_time()
        old, new = np.array(old), np.array(new)
        rows.append({"candidate": key, "orders": len(orders), "n_unknowns": s.problem.n_unknowns,
                     "per_order_wall_s": t1 - t0, "per_order_cpu_s": c1 - c0,
                     "one_jacobian_wall_s": t2 - t1, "one_jacobian_cpu_s": c2 - c1,
                     "max_rel_gain_diff": float(np.max(np.abs(new - old) / np.maximum(old, 1e-300))),
                     "best_order_same": int(np.argmax(old)) == int(np.argmax(new))})
        print(rows[-1], flush=True)
    meta["load_end"] = load_text()
    res = {"meta": meta, "rows": rows}
    (RESULTS / "diagnose_order_screen.json").write_text(json.dumps(res, indent=2) + "\n")
    lines = ["# Order screen: one Jacobian per order vs one for all orders", "",
             f"Measured {meta['date']} on {meta['cpu']} ({meta['cores']} cores, shared), pinned "
             f"to core 0; load at start {meta['load']}, at end {meta['load_end']}; src "
             f"{meta['src']}. Shipped 1 kHz log, base model's best grid point, the effect at "
             "zero; programs loaded before timing.", "",
             "| candidate | orders | unknowns | per order: wall s (CPU s) | one Jacobian: wall s "
             "(CPU s) | max rel. gain difference | same best order |", "|---|---|---|---|---|---|---|"]
    for r in rows:
        lines.append(f"| {r['candidate']} | {r['orders']} | {r['n_unknowns']} | "
                     f"{r['per_order_wall_s']:.2f} ({r['per_order_cpu_s']:.2f}) | "
                     f"{r['one_jacobian_wall_s']:.2f} ({r['one_jacobian_cpu_s']:.2f}) | "
                     f"{r['max_rel_gain_diff']:.1e} | {r['best_order_same']} |")
    (RESULTS / "diagnose_order_screen.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
