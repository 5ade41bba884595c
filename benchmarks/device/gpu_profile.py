"""Where the GPU time of ``fit_many(lanes="logs")`` goes (issue 37 item 5), for one device run.

The device run of 2026-11-28 (gpu_path.md section 5) found the logs-as-lanes solve growing
about linearly with the logs (27 s for 100, 123 s for 600) although every call is
``GPU_WIDTH`` = 8192 lanes wide (short calls padded). This script separates the candidates:

1. ``calls``: every lane program call of a ``fit_many`` (the wrappers block on the result)
   — program, lanes ``W``, real lanes ``h``, Levenberg–Marquardt iterations the call ran
   (its while loop's trips: the largest per-lane count), wall and process CPU — so that the
   solve's time splits into calls × iterations × time per iteration, and host time between
   calls (phase wall minus call wall), with the per-log one-lane calls made beside them
   (the stuck-run check, the drop starts' costs) counted and timed;
2. ``replay``: the largest solve call of the first batch replayed at fixed iteration budgets
   (1 and 4: slope = time per iteration, intercept = a call's fixed cost), with one real
   lane instead of all, and the forward pass (``_lane_costs``) and analysis program alone;
3. ``widths``: the same forward pass on the first ``W`` lanes for smaller ``W`` (and with
   ``--width-solve`` a 2-iteration solve at the smallest; new compiles): does a call's time
   follow its width (device-bound) or not (launch- or host-bound)?
4. ``trace``: a ``jax.profiler`` trace of one 2-iteration replay, summarised here with
   :class:`jax.profiler.ProfileData` — kernels launched, device busy time (union of kernel
   spans) against the wall, the kernels that take the time;
5. ``sizes``: ``fit_many`` of more logs with the same instrumentation, within the budget.

    python benchmarks/device/gpu_profile.py --logs /tmp/hd_logs.pkl --out prof.json \\
        --sizes 100 1000 --widths 1024 4096 --budget-s 170 --trace-dir /tmp/hd_trace
"""

import argparse
import json
import os
import pickle
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: _common
import _common  # noqa: E402

import jax  # noqa: E402
import numpy as np  # noqa: E402

import hdid  # noqa: E402
from hdid._fitting import _log_lanes  # noqa: E402

CALLS: list[dict] = []
CAPTURED: dict = {}


def _block(x):
    return jax.tree_util.tree_map(lambda a: a.block_until_ready() if hasattr(a, "block_until_ready") else a, x)


def _wrap(name, fn):
    def wrapped(problems, U, *rest):
        w0, c0 = time.perf_counter(), time.process_time()
        out = _block(fn(problems, U, *rest))
        rec = {"prog": name, "W": int(U.shape[0]), "wall_s": time.perf_counter() - w0,
               "cpu_s": time.process_time() - c0}
        if name == "solve":
            on, budget = np.asarray(rest[0]), np.asarray(rest[1])
            steps = np.asarray(out[3])
            rec |= {"h": int(on.sum()), "budget": int(budget.max()), "iters": int(steps[on].max(initial=0)),
                    "lane_iters": int(steps[on].sum())}
            if rec["h"] > CAPTURED.get("h", -1):
                CAPTURED.update(h=rec["h"], args=(problems, U, *rest))
        CALLS.append(rec)
        return out
    return wrapped


#: per-log calls made by fit_bucket outside the lane programs (one-lane JAX work on the default
#: device: the stuck-run check in the solve phase, the drop starts' costs in the grid phase)
PER_LOG: dict = {}


def _count(name, fn):
    def counted(*a, **k):
        w0 = time.perf_counter()
        out = _block(fn(*a, **k))
        rec = PER_LOG.setdefault(name, {"calls": 0, "wall_s": 0.0})
        rec["calls"] += 1
        rec["wall_s"] += time.perf_counter() - w0
        return out
    return counted


_log_lanes._untrapped = _count("untrapped", _log_lanes._untrapped)
_log_lanes._costs = _count("drop_start_costs", _log_lanes._costs)
_log_lanes._lane_solve = _wrap("solve", _log_lanes._lane_solve)
_log_lanes._lane_costs = _wrap("costs", _log_lanes._lane_costs)
_log_lanes._lane_analysis = _wrap("analysis", _log_lanes._lane_analysis)


def _timed(fn, reps=3):
    walls = []
    for _ in range(reps):
        w0 = time.perf_counter()
        _block(fn())
        walls.append(time.perf_counter() - w0)
    return {"median_s": sorted(walls)[len(walls) // 2], "min_s": min(walls), "first_s": walls[0]}


def _summary(calls: list[dict]) -> dict:
    out = {}
    for prog in ("costs", "solve", "analysis"):
        cs = [c for c in calls if c["prog"] == prog]
        if cs:
            out[prog] = {"calls": len(cs), "wall_s": sum(c["wall_s"] for c in cs),
                         "cpu_s": sum(c["cpu_s"] for c in cs), "W": sorted({c["W"] for c in cs})}
            if prog == "solve":
                it = sum(c["iters"] for c in cs)
                out[prog] |= {"iters": it, "lane_iters": sum(c["lane_iters"] for c in cs),
                              "s_per_iter": out[prog]["wall_s"] / max(it, 1),
                              "h_max": max(c["h"] for c in cs)}
    return out


def fit_row(dfs, n: int, res: dict, save, key: str) -> None:
    CALLS.clear()
    PER_LOG.clear()
    items = [dfs[i % len(dfs)] for i in range(n)]
    load0 = os.getloadavg()[0]
    w0, c0 = time.perf_counter(), time.process_time()
    table = hdid.fit_many(items, lanes="logs")
    wall, cpu = time.perf_counter() - w0, time.process_time() - c0
    timing = {k: v for k, v in table.attrs["timing"].items() if isinstance(v, (int, float, str))}
    row = {"n_logs": n, "wall_s": wall, "cpu_s": cpu, "logs_per_s": n / wall, "load": [load0, os.getloadavg()[0]],
           "errors": int(table["error"].notna().sum()), "timing": timing, "calls": list(CALLS),
           "summary": _summary(CALLS), "per_log_calls": {k: dict(v) for k, v in PER_LOG.items()}}
    s = row["summary"]
    row["host_s"] = {ph: timing.get(f"{ph}_s", 0) - s.get(p, {}).get("wall_s", 0)
                     for ph, p in (("grid", "costs"), ("solve", "solve"), ("analyse", "analysis"))}
    res.setdefault(key, []).append(row)
    print(key, n, {k: row[k] for k in ("wall_s", "logs_per_s", "host_s", "per_log_calls")}, s, flush=True)
    save()


def replay(res: dict, save, widths, trace_dir, width_solve: bool) -> None:
    import jax.numpy as jnp

    problems, U, on, budget, state = CAPTURED["args"]
    W, h = int(U.shape[0]), CAPTURED["h"]
    solve, costs, analysis = _log_lanes._lane_solve, _log_lanes._lane_costs, _log_lanes._lane_analysis
    rep = res.setdefault("replay", {"W": W, "h": h})

    def run_solve(k, active=on, P=problems, U0=U, st=state):
        # the budget as fit_bucket passes it (an int64 NumPy array: no new trace)
        return solve(P, U0, active, jnp.asarray(np.where(np.asarray(active), k, 0).astype(budget.dtype)), st)

    for k in (1, 4):
        rep[f"solve_k{k}"] = _timed(lambda k=k: run_solve(k))
        rep[f"solve_k{k}"]["iters"] = CALLS[-1]["iters"]
        save()
    rep["per_iter_s"] = (rep["solve_k4"]["median_s"] - rep["solve_k1"]["median_s"]) / max(
        rep["solve_k4"]["iters"] - rep["solve_k1"]["iters"], 1)
    # the same call with fewer real lanes (the rest inactive, still computed): does a call's
    # time follow its live lanes at a fixed width?
    live = np.flatnonzero(np.asarray(on))
    for name, m in (("one_lane", 1), ("eighth", max(len(live) // 8, 1))):
        sub = jnp.asarray(np.isin(np.arange(W), live[:m]))
        rep[f"solve_k4_{name}"] = _timed(lambda sub=sub: run_solve(4, sub)) | {
            "h": int(m), "iters": CALLS[-1]["iters"], "lane_iters": CALLS[-1]["lane_iters"]}
    rep["solve_k4"]["lane_iters"] = next(c["lane_iters"] for c in reversed(CALLS) if c["h"] == h)
    rep["costs"] = _timed(lambda: costs(problems, U))
    rep["analysis"] = _timed(lambda: analysis(problems, U))
    print("replay", rep, flush=True)
    save()
    if trace_dir:
        try:
            with jax.profiler.trace(trace_dir):
                w0 = time.perf_counter()
                run_solve(2)
                wall = time.perf_counter() - w0
            res["trace"] = trace_summary(trace_dir) | {"wall_s": wall}
        except Exception as exc:  # noqa: BLE001 - a profile that fails is reported, not fatal
            res["trace"] = {"error": repr(exc)}
        print("trace", {k: v for k, v in res["trace"].items() if k != "planes"}, flush=True)
        save()
    wid = res.setdefault("widths", [])
    for i, w in enumerate(sorted(widths)):  # the forward pass at each width; the solve at the first only
        if w >= W or time.perf_counter() > T_END - 40:
            continue
        P = jax.tree_util.tree_map(lambda x: x[:w] if hasattr(x, "shape") and x.ndim and x.shape[0] == W else x,
                                   problems)
        row = {"W": w}
        w0 = time.perf_counter()
        row["costs"] = _timed(lambda: costs(P, U[:w]))
        if i == 0 and width_solve:
            st = jax.tree_util.tree_map(lambda x: x[:w], state)
            row["solve_k2"] = _timed(lambda: run_solve(2, on[:w], P, U[:w], st))
            row["solve_k2"]["iters"] = CALLS[-1]["iters"]
        row["first_calls_s"] = time.perf_counter() - w0  # compiles included
        wid.append(row)
        print("width", row, flush=True)
        save()


def trace_summary(trace_dir: str) -> dict:
    """Kernels per device line, their busy time (union of spans) and the top kernels; host
    events named like launches, copies, syncs."""
    from jax.profiler import ProfileData

    files = sorted(Path(trace_dir).rglob("*.xplane.pb"), key=os.path.getmtime)
    pd = ProfileData.from_file(str(files[-1]))
    planes = []
    for p in pd.planes:
        lines = []
        for ln in p.lines:
            ev = [(e.name, e.start_ns, e.duration_ns) for e in ln.events]
            if not ev:
                continue
            spans = sorted((s, s + d) for _, s, d in ev)
            busy, cur0, cur1 = 0.0, spans[0][0], spans[0][1]
            for a, b in spans[1:]:
                if a > cur1:
                    busy, cur0, cur1 = busy + cur1 - cur0, a, b
                else:
                    cur1 = max(cur1, b)
            busy += cur1 - cur0
            tot: dict = {}
            for name, _, d in ev:
                t = tot.setdefault(name[:80], [0, 0.0])
                t[0] += 1
                t[1] += d
            top = sorted(tot.items(), key=lambda kv: -kv[1][1])[:12]
            lines.append({"line": ln.name, "events": len(ev), "busy_ms": busy / 1e6,
                          "span_ms": (spans[-1][1] - spans[0][0]) / 1e6,
                          "top": [[n, c, d / 1e6] for n, (c, d) in top]})
        if lines:
            planes.append({"plane": p.name, "lines": lines})
    return {"file_bytes": os.path.getsize(files[-1]), "planes": planes}


T_END = 0.0


def main(argv=None) -> int:
    global T_END
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--logs", required=True, help="pickled DataFrames (gpu_path.py --make-logs)")
    ap.add_argument("--out", required=True)
    ap.add_argument("--sizes", type=int, nargs="+", default=[100, 1000])
    ap.add_argument("--widths", type=int, nargs="*", default=[1024, 4096])
    ap.add_argument("--width-solve", action="store_true",
                    help="also a 2-iteration solve at the smallest width (a compile of its own)")
    ap.add_argument("--budget-s", type=float, default=170.0)
    ap.add_argument("--trace-dir", default="")
    args = ap.parse_args(argv)
    T_END = time.perf_counter() + args.budget_s
    dfs = pickle.loads(Path(args.logs).read_bytes())
    res = {"generated": time.strftime("%Y-%m-%dT%H:%M:%S"), "machine": _common.machine(),
           "gpu_width": _log_lanes.GPU_WIDTH, "distinct_logs": len(dfs), "budget_s": args.budget_s}

    def save():
        (tmp := Path(args.out).with_suffix(".tmp")).write_text(json.dumps(res, indent=1))
        tmp.replace(args.out)

    w0 = time.perf_counter()
    hdid.fit_many(dfs[:2], lanes="logs")
    res["first_call_s"] = time.perf_counter() - w0
    print("first call", res["first_call_s"], flush=True)
    save()
    fit_row(dfs, args.sizes[0], res, save, "sizes")
    replay(res, save, args.widths, args.trace_dir, args.width_solve)
    for n in args.sizes[1:]:
        last = res["sizes"][-1]
        rate = last["wall_s"] / last["n_logs"]
        left = T_END - time.perf_counter()
        m = n if rate * n < 0.85 * left else int(0.85 * left / rate) // 50 * 50
        if m <= last["n_logs"]:
            res.setdefault("skipped", []).append({"n_logs": n, "estimate_s": rate * n, "left_s": left})
            save()
            continue
        fit_row(dfs, m, res, save, "sizes")
    res["load_end"] = os.getloadavg()[0]
    save()
    return 0


if __name__ == "__main__":
    sys.exit(main())
