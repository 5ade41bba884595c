"""Is a calibration log's truth consistent with hdid's likelihood? (Δχ² of the truth)

For each seed: the posterior calibration's truth and log (``posterior_sbc.draw_log``: drawn
from the default priors of the design's nominal log, written by the independent
simulator), fitted freely and with the seven physical parameters held at the truth
(release times, start angles and set-up offsets refitted).
Δχ² = data χ² at the truth minus the free fit's, in q²/12 units. If the model and the
likelihood are right, Δχ² follows χ²₇ (mean 7, 95 % point 14.07); far above it, the
simulator and the model disagree at that truth; below zero, the fit ended in a poorer
basin than the truth's. Three ways of reading the same logs separate the causes:

- ``Q``: quantized, as calibrated; χ² with the fit's own weights (``weight²``: a stretch of
  identical readings counts once);
- ``Q_w1``: the same fits with ``weight`` in place of ``weight²`` — the metric of the
  retired ``posterior_truth_chi2.py``, which counted a hold or stuck tail of n readings
  √n times;
- ``Z``: the same truth written unrounded and noise-free (``resolution`` given): only
  the dynamics and the substep error remain.

    python benchmarks/truth_chi2.py [--rich 20] [--paper 10] [--seed0 10600]

Writes ``results/truth_chi2.{json,md,png}``.
"""

from __future__ import annotations

import _common  # noqa: E402
import argparse
import time

import numpy as np

PHYSICAL = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v")
CHI2_7_95 = 14.07
NAME = "truth_chi2"


def _chi2(fit, q, power):
    p = fit.problem
    r = (np.asarray(fit.predict()) - np.asarray(p.theta)) / q
    return float(np.sum(np.asarray(p.weight) ** power * r * r) * 12.0)


def one(hdid, gen, sbc, design_name, seed):
    design = gen.RICH_DESIGN if design_name == "rich" else gen.PAPER_DESIGN
    truth, df, _, _ = sbc.draw_log(gen, design_name, seed)
    q = 2 * np.pi / gen.COUNTS_PER_REV
    row = {"design": design_name, "seed": seed, "truth": {n: truth[n] for n in PHYSICAL}}
    t0 = time.perf_counter()
    for tag, log, extra in (("Q", df, {}),
                            ("Z", gen.make_log(truth, **{**design, "seed": seed,
                                                         "quantize": False}),
                             {"resolution": q})):
        free = hdid.fit(log, inertia=truth["inertia"], **extra)
        held = hdid.fit(log, inertia=truth["inertia"], fix={n: truth[n] for n in PHYSICAL},
                        **extra)
        row[tag] = _chi2(held, q, 2) - _chi2(free, q, 2)
        if tag == "Q":
            row["Q_w1"] = _chi2(held, q, 1) - _chi2(free, q, 1)
    row["fit_s"] = time.perf_counter() - t0
    row["load"] = _common.load_text()
    return row


def render(res):
    rows = res["rows"]
    L = [f"# Δχ² of the truth under hdid's likelihood ({res['meta']['date']}, "
         f"{res['meta']['cpu']}, load {res['meta']['load']} → {res['meta'].get('load_end')})", "",
         "Δχ² = data χ² (q²/12 units) with the 7 physical parameters held at the truth minus "
         f"the free fit's; a consistent truth gives χ²₇ (mean 7, 95 % point {CHI2_7_95}). "
         "`Q`: quantized log, the fit's weights (weight²); `Q_w1`: the retired metric "
         "(weight, a hold of n readings counted √n times); `Z`: unrounded noise-free log.", "",
         "| design | n | Q mean | Q > 14.07 | Q < 0 | Q_w1 mean | Q_w1 > 14.07 | max abs Z |",
         "|---|---|---|---|---|---|---|---|"]
    for d in ("paper", "rich"):
        r = [x for x in rows if x["design"] == d]
        if not r:
            continue
        Q = np.array([x["Q"] for x in r])
        W = np.array([x["Q_w1"] for x in r])
        Z = np.array([x["Z"] for x in r])
        L.append(f"| {d} | {len(r)} | {Q.mean():.1f} | {(Q > CHI2_7_95).sum()} "
                 f"(expected {0.05 * len(r):.1f}) | {(Q < 0).sum()} | {W.mean():.1f} | "
                 f"{(W > CHI2_7_95).sum()} | {np.abs(Z).max():.2f} |")
    L += ["", "| design | seed | Q | Q_w1 | Z | truth v_s | truth δ | s | load |",
          "|---|---|---|---|---|---|---|---|---|"]
    for x in rows:
        L.append(f"| {x['design']} | {x['seed']} | {x['Q']:.1f} | {x['Q_w1']:.1f} | "
                 f"{x['Z']:.2f} | {x['truth']['v_s']:.3g} | {x['truth']['delta']:.2f} | "
                 f"{x['fit_s']:.0f} | {x['load']} |")
    L += ["", "![Δχ² of the truth against χ²₇](truth_chi2.png)", ""]
    L += _common.interpretation_section(res)
    _figure(res)
    return "\n".join(L) + "\n"


def _figure(res):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy import stats

    fig, ax = plt.subplots(figsize=(6, 4.5))
    for key, label, m in (("Q_w1", "retired metric (weight)", "x"),
                          ("Q", "the fit's likelihood (weight²)", "o"),
                          ("Z", "unrounded, noise-free (dynamics only)", "^")):
        for d, c in (("rich", "C0"), ("paper", "C1")):
            v = np.sort([x[key] for x in res["rows"] if x["design"] == d])
            if v.size:
                e = stats.chi2(7).ppf((np.arange(v.size) + 0.5) / v.size)
                ax.plot(e, v, m, color=c, mfc="none" if m != "x" else None,
                        label=f"{d}: {label}")
    lim = ax.get_xlim()
    ax.plot(lim, lim, "k:", lw=1, label="χ²₇")
    ax.axhline(CHI2_7_95, color="grey", lw=0.8, ls="--")
    ax.set_xlabel("χ²₇ quantile")
    ax.set_ylabel("Δχ² of the truth [q²/12 units]")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(_common.RESULTS / f"{NAME}.png", dpi=110)
    plt.close(fig)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rich", type=int, default=20)
    ap.add_argument("--paper", type=int, default=10)
    ap.add_argument("--seed0", type=int, default=10600, help="rich seeds; paper: seed0 − 1000")
    args = _common.parse_or_render(ap, argv, NAME, render)
    if args is None:
        return
    import hdid

    hdid.configure()
    from hdid.reference import logs as gen

    import posterior_sbc as sbc

    res = {"meta": _common.run_meta(), "rows": []}
    sched = ([("rich", args.seed0 + i) for i in range(args.rich)]
             + [("paper", args.seed0 - 1000 + i) for i in range(args.paper)])
    for d, s in sched:
        res["rows"].append(one(hdid, gen, sbc, d, s))
        r = res["rows"][-1]
        print(d, s, f"Q {r['Q']:.1f}  Q_w1 {r['Q_w1']:.1f}  Z {r['Z']:.2f}", flush=True)
        _common.write_result(NAME, res, render)
    res["meta"]["load_end"] = _common.load_text()
    _common.write_result(NAME, res, render)


if __name__ == "__main__":
    main()
