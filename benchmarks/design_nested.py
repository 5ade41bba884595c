"""Backlash vs soft wind-up, a nested pair: the separation with the rival also started at the corner that is
the true form, against the realised 2·ln LR on simulated logs.

    taskset -c 1 python benchmarks/design_nested.py [--n 5]     # compute, write results/design_nested.*
    python benchmarks/design_nested.py --render                  # the .md from the stored .json

Soft wind-up with ``K1 → 0``, ``T1/K1 = b/2N``, ``K2 = K3 = k1`` is a free play ``b`` then a linear spring
(``hdid._diagnosis._nesting``). On the independent suite's paper log 9902 (hidden hysteresis; diagnose's
backlash and soft wind-up refits are the two forms), on the combined design rate ×4 + encoder ×16 (1 kHz,
64 000 counts/rev), the separation with backlash true is computed as ``hdid.design`` computes it
(``_separate.separations``, the rival fitted globally over 4 sets of release instants), and realised on ``--n``
logs simulated from the backlash form (seed 9902, as ``design_check.py``'s ``_realised``): both forms fitted by
``best_rival_fit``, the soft wind-up also from the corner. The soft wind-up's ``K1`` and std per log say whether
each noisy fit sits at the corner (the nesting rule: zero within 2 std).
"""

import argparse
import dataclasses
import json
import math
import sys
import time

from _common import RESULTS, cpu_model, load, src_fingerprint

NAME = "design_nested"


def run(n: int) -> dict:
    import numpy as np

    import design_check as dc
    from hdid._config import float64
    from hdid._design._best_rival import best_rival_fit
    from hdid._design._check import simulate_logs
    from hdid._design._separate import separations
    from hdid._diagnosis._separating import experiments_for

    out = {"src": src_fingerprint(), "cpu": cpu_model(), "n": n, "load_start": load("start")}
    t = time.process_time()
    _, (a, b), _ = dc._pair_fits("paper", 9902, ("backlash", "soft_windup"))
    fa, fb = a.fit.result(), b.fit.result()
    out["fits"] = {"delta_bic": [a.delta_bic, b.delta_bic], "soft_windup": b.values, "backlash": a.values,
                   "cpu_s": time.process_time() - t}
    ex = {e.name: e for e in experiments_for(fa, fb)}
    e = dataclasses.replace(ex["rate x4"], name="rate x4 + encoder x16", resolution=ex["encoder x16"].resolution,
                            releases=())
    out["experiment"] = e.describe()
    t = time.process_time()
    s = separations(fa, fb, [e], include=(0,))[0]
    (m_a, sd_a), (m_b, sd_b) = s.expected()
    out["separation"] = {"lambda": list(s.best), "draws": [list(d) for d in s.draws], "k": list(s.k),
                         "trace": s.trace, "predicted": [[m_a, sd_a], [m_b, sd_b]],
                         "cpu_s": time.process_time() - t, **load("after separation")}
    print("separation", out["separation"], flush=True)
    vals, logs = [], []
    t = time.process_time()
    with float64():
        truth, other = fa, fb
        for k, log in enumerate(simulate_logs(truth, e, n, seed=9902)):
            rt = best_rival_fit(log, truth, e, window=0)
            ro = best_rival_fit(log, other, e, window=0, truth=truth)
            other = ro if k == 0 and ro is not None else other
            x = dc._chi2(ro, e.resolution) - dc._chi2(rt, e.resolution)
            p = ro.parameters["K1"]
            logs.append({"two_ln_lr": x, "K1": p.value, "K1_std": p.std, "k1": rt.parameters["k1"].value})
            vals.append(x)
            print(k, logs[-1], flush=True)
    v = np.asarray(vals)
    out["realised"] = {"n": int(v.size), "mean": float(v.mean()), "median": float(np.median(v)),
                       "sd": float(v.std(ddof=1)), "true_form_lower_chi2": int((v > 0).sum()), "logs": logs,
                       "cpu_s": time.process_time() - t, **load("after realised")}
    return out


def _f(x):
    return "inf" if isinstance(x, float) and math.isinf(x) else ("n/a" if x is None else f"{x:.3g}")


def render(r: dict) -> str:
    s, re_ = r["separation"], r["realised"]
    (m_a, sd_a), (m_b, sd_b) = s["predicted"]
    at = sum(1 for g in re_["logs"] if g["K1_std"] is None or abs(g["K1"]) <= 2.0 * g["K1_std"])
    lines = [
        "# Backlash vs soft wind-up (a nested pair): separation and realised 2·ln LR", "",
        f"src {r['src']}, {r['cpu']}; log 9902 (paper), {r['experiment']} (rate ×4 + encoder ×16); "
        f"loads {s['load1']:.1f} (separation), {re_['load1']:.1f} (realised)", "",
        "| truth | λ (rival fitted globally; draws) | predicted 2·ln LR | realised (n) | true form better |",
        "|---|---|---|---|---|",
        f"| backlash | {_f(s['lambda'][0])} ({', '.join(_f(x) for x in s['draws'][0])}) | {_f(m_a)} ± {_f(sd_a)} | "
        f"{_f(re_['mean'])} ± {_f(re_['sd'])}, median {_f(re_['median'])} ({re_['n']}) | "
        f"{re_['true_form_lower_chi2']}/{re_['n']} |",
        f"| soft_windup | {_f(s['lambda'][1])} ({', '.join(_f(x) for x in s['draws'][1])}) | {_f(m_b)} ± {_f(sd_b)} | "
        "(not re-run) | |", "",
        f"Soft wind-up's K1 on the {re_['n']} realised fits (k1 ≈ {_f(re_['logs'][0]['k1'])} N m/rad): "
        + ", ".join(f"{_f(g['K1'])} ± {_f(g['K1_std'])}" for g in re_["logs"])
        + f" — at the corner (zero within 2 std) on {at}/{re_['n']}.", "",
        f"CPU s: separation {s['cpu_s']:.1f}, realised fits {re_['cpu_s']:.1f} (process time).", ""]
    if "before" in r:
        b = r["before"]
        lines += [f"Before ({b['note']}): backlash true λ {b['lambda_backlash_true']} (draws "
                  f"{', '.join(str(x) for x in b['draws'])}), predicted {b['predicted']}, realised {b['realised']}; "
                  f"soft wind-up true λ {b['lambda_soft_windup_true']}.", ""]
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--n", type=int, default=5, help="simulated backlash logs")
    ap.add_argument("--render", action="store_true", help="only re-render the .md from the stored .json")
    args = ap.parse_args(argv)
    path = RESULTS / f"{NAME}.json"
    if args.render:
        r = json.loads(path.read_text())
    else:
        r = run(args.n)
        path.write_text(json.dumps(r, indent=1, default=lambda x: None) + "\n")
    (RESULTS / f"{NAME}.md").write_text(render(r))
    return 0


if __name__ == "__main__":
    sys.exit(main())
