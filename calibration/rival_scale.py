"""Is the rival test's ``2·ln LR`` calibrated? Logs drawn from each of two *fitted* forms,
diagnosed (issue 19; :mod:`hdid._diagnosis._rival`; the decision:
``docs/decisions/rival-scale.md``).

    taskset -c 1 python calibration/rival_scale.py N|J0:J1 \
        rich:8905:ripple,kinematic_error rich:8805:ripple,kinematic_error \
        rich:8901:backlash,kinematic_error paper:9905:ripple,asymmetric_friction

``DESIGN:SEED:A,B``: the independent suite's log of that seed
(``benchmarks/diagnose_independent.py``: the same plant, design, hidden effect and ``make_log`` seed)
is diagnosed once; the two candidates ``A`` and ``B`` fitted there are the two *forms*
(every parameter at its fitted value, the scanned order included). ``N`` logs are then
drawn from each form with hdid's own simulator (``simulate``: the design's release
angles, rate, length and hold, a random sub-sample release instant per run, each set-up's
offset the design's plus a uniform fraction of an encoder step, seeds ``SEED·1000 + j`` (form ``A``) and ``SEED·1000 + 500 + j`` (form ``B``),
rounded to the 4000-count encoder) and diagnosed with every candidate. The truth is then
exactly one of the two forms. Per log it records the verdict, the candidates' order and
ΔBIC, both forms' χ² and ``n − k`` and, whether or not the rule ran (it runs only where
both fits are below ``n − k``), the rule's statistics for the pair recomputed from the
two fits (:func:`~hdid._diagnosis._rival.cross_evidence`): the observed ``D = χ²_B −
χ²_A``, its claimed mean and sd under each form, ``2·ln LR``, and the z-score of ``D``
under the *true* form — which must be about N(0, 1) if the rounding-phase scale is right.
Logs are interleaved (A, B, A, B, … per seed) so a stopped run is balanced. Writes
``calibration/results/rival_scale.json`` (``HDID_RIVAL_OUT``: another name) after every
log; ``--report [FILES]`` prints its table (``calibration/results/rival_scale.md``).
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
import diagnose_independent as di  # noqa: E402
from _common import run_meta  # noqa: E402

from hdid.reference import logs  # noqa: E402

RESULTS = Path(__file__).resolve().parent / "results"
OUT = RESULTS / (os.environ.get("HDID_RIVAL_OUT", "rival_scale") + ".json")
#: a folder for both forms' linearised fits per log (``HDID_RIVAL_SAVE``; none if unset)
SAVE = os.environ.get("HDID_RIVAL_SAVE")
STEP = 2 * math.pi / 4000


def suite_log(design: str, seed: int):
    """The independent suite's log of ``seed`` (hidden effect by the seed's position)."""
    gen = hid = logs  # the generators and the hidden effects
    name = di.HIDDEN[(seed % 100) % len(di.HIDDEN)]
    truth, des = di.draw(design, seed)
    rng = np.random.default_rng(seed + 10_000)
    hp = di.hidden_params(name, truth, des, rng) if name != "none" else {}
    kw = hid.reference_kwargs(name, truth, **hp) if name != "none" else None
    mk = {k: v for k, v in des.items() if k != "gear_factor"}
    return name, des, gen.make_log(truth, **mk, seed=seed, hidden=kw)


def form_model(sf):
    """The model of a candidate refit with every parameter at its fitted value."""
    vals = sf.values()
    names = set(sf.model.float_values())
    return sf.model.replace(**{k: v for k, v in vals.items() if k in names})


def draw_log(model, des: dict, seed: int):
    """One log from ``model`` on design ``des`` (``make_log``'s layout)."""
    import pandas as pd

    from hdid._simulation._simulate import simulate

    rng = np.random.default_rng(seed)
    fs = float(des["fs"])
    n = int(round(des["duration"] * fs))
    t = np.arange(n) / fs
    names = list(des["offsets_by_setup"])
    amps = [float(a) for a in des["amplitudes"]]
    per = math.ceil(len(amps) / len(names))
    # the encoder's phase on each set-up: the design's offset plus a uniform fraction of a
    # step (the randomness the rule's scale assumes, beside the release instants)
    shift = {s: float(des["offsets_by_setup"][s]) + rng.uniform(0.0, STEP) for s in names}
    frames = []
    for i, a in enumerate(amps):
        setup = names[min(i // per, len(names) - 1)]
        t_r = des["hold"] + rng.uniform(0.0, 1.0) / fs
        th = np.asarray(simulate(model, t, a, t_r, max_substep=min(2.5e-4, 0.25 / fs)))
        reading = np.round((th + shift[setup]) / STEP) * STEP
        frames.append(pd.DataFrame({"run": i + 1, "setup": setup, "time": t, "theta": reading}))
    return pd.concat(frames, ignore_index=True)


def pair_stats(d, a: str, b: str, truth: str, tag: str = "") -> dict:
    """Both forms' fits in diagnosis ``d`` and the rule's statistics recomputed for them."""
    from hdid._diagnosis._rival import _floored, cross_evidence, linear_of

    by = {c.key: c for c in d.candidates if c.error is None}
    out = {}
    for k in (a, b):
        c = by.get(k)
        out[k] = None if c is None else {
            "label": c.label, "delta_bic": c.delta_bic, "chi2": float(c.fit.cost),
            "n_minus_k": float(c.fit.n_effective - c.fit.n_unknowns), "floored": _floored(c),
            "rank": [x.key for x in d.candidates].index(k),
            "floor_gap": getattr(c, "floor_gap", None),
            "floor_evidence": getattr(c, "floor_evidence", None)}
    if by.get(a) is None or by.get(b) is None:
        return out
    la, lb = linear_of(by[a].fit), linear_of(by[b].fit)
    ev = None if la is None or lb is None else cross_evidence(la, lb)
    if ev is not None and SAVE and tag:
        # both linearised fits, for other scales to be judged offline on the same logs
        p = by[a].fit.setup.problem
        np.savez_compressed(
            Path(SAVE) / f"{tag}.npz", shape=np.asarray(np.shape(p.weight)),
            setup_index=np.asarray(p.setup_index), d=ev.d,
            **{f"{k}_{f}": getattr(lin, f) for k, lin in (("a", la), ("b", lb))
               for f in ("r", "U", "rows", "w", "yhat", "sigma", "cost")})
    if ev is not None:
        mt, st = (ev.mean_a, ev.sd_a) if truth == a else (ev.mean_b, ev.sd_b)
        out["evidence"] = {"d": ev.d, "mean_a": ev.mean_a, "sd_a": ev.sd_a,
                           "mean_b": ev.mean_b, "sd_b": ev.sd_b,
                           "two_ln_lr_for_a": ev.two_ln_lr, "z_true": (ev.d - mt) / st}
    return out


def main(argv: list[str]) -> None:
    import hdid

    hdid.configure()
    # N: seeds j = 0 … N−1; "J0:J1": j = J0 … J1−1 (a further batch)
    j0, n = (int(x) for x in argv[0].split(":")) if ":" in argv[0] else (0, int(argv[0]))
    meta = run_meta(cmd="taskset -c 1 python calibration/rival_scale.py "
                    + " ".join(argv))
    records: list[dict] = []
    forms = []
    for spec in argv[1:]:
        design, seed, pair = spec.split(":")
        seed = int(seed)
        a, b = pair.split(",")
        hidden, des, df = suite_log(design, seed)
        d = hdid.diagnose(df)
        by = {c.key: c for c in d.candidates if c.error is None}
        ref = {"design": design, "plant": seed, "hidden": hidden, "a": a, "b": b,
               "verdict": d.verdict, "named": di._named(d),
               "top": [(c.label, round(c.delta_bic, 2)) for c in d.candidates[:4]],
               "pair": pair_stats(d, a, b, a, f"{seed}_ref"), "forms": {}}
        for k in (a, b):
            ref["forms"][k] = {kk: float(v) for kk, v in by[k].fit.values().items()}
            forms.append((design, seed, a, b, k, form_model(by[k].fit), des))
        records.append({"reference": ref})
        print(json.dumps({"reference": {x: ref[x] for x in ("plant", "verdict", "named", "top")}}),
              flush=True)
    for j in range(j0, n):
        for design, seed, a, b, truth, model, des in forms:
            s = seed * 1000 + (0 if truth == a else 500) + j
            df = draw_log(model, des, s)
            load = os.getloadavg()[0]
            t0, c0 = time.perf_counter(), time.process_time()
            try:
                d = hdid.diagnose(df)
            except Exception as exc:  # a failure is a result too
                records.append({"plant": seed, "truth": truth, "seed": s, "error": repr(exc)})
                continue
            rec = {"design": design, "plant": seed, "a": a, "b": b, "truth": truth, "seed": s,
                   "verdict": d.verdict, "named": di._named(d),
                   "top": [(c.label, round(c.delta_bic, 2)) for c in d.candidates[:4]],
                   "pair": pair_stats(d, a, b, truth, f"{seed}_{s}_{truth}"),
                   "rule_notes": [x for x in d.notes if "white floor" in x],
                   "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
                   "load1": load, "load1_after": os.getloadavg()[0]}
            records.append(rec)
            ev = rec["pair"].get("evidence") or {}
            print(json.dumps({k: rec[k] for k in ("plant", "truth", "seed", "verdict", "named")}
                             | {"z": ev.get("z_true"), "lr": ev.get("two_ln_lr_for_a"),
                                "wall": round(rec["wall_s"]), "load": load}), flush=True)
            OUT.write_text(json.dumps({"meta": meta, "records": records}, indent=1) + "\n")
    meta["load_end"] = os.getloadavg()[0]
    OUT.write_text(json.dumps({"meta": meta, "records": records}, indent=1) + "\n")


def report(paths: list[str]) -> str:
    """Markdown of one or more results files: per plant and true form, the verdicts (what
    is named first; ``A|…`` ambiguous) and the z-score of ``D`` under the true form with
    the shipped scale (mean, sd, largest |z|), and ``2·ln LR`` for the truth (median, the
    share of logs where it favours the other form by more than 2)."""
    import collections

    recs = []
    for path in paths:
        recs += [r for r in json.loads(Path(path).read_text())["records"]
                 if "reference" not in r and "error" not in r]
    lines = ["| plant | true form | logs | named first (verdicts) | z of D under the truth: "
             "mean, sd, max abs | 2 ln LR for the truth: median; share < −2 | CPU s median |",
             "|---|---|---|---|---|---|---|"]
    groups = collections.defaultdict(list)
    for r in recs:
        groups[(r["plant"], r["truth"])].append(r)
    for (plant, truth), rows in sorted(groups.items()):
        named = collections.Counter(r["named"].split("|")[0] + (" (ambiguous)" if "|" in
                                                                r["named"] else "")
                                    for r in rows)
        ev = [r["pair"]["evidence"] for r in rows if r["pair"].get("evidence")]
        z = np.array([e["z_true"] for e in ev])
        sign = [1 if truth == r["a"] else -1 for r in rows if r["pair"].get("evidence")]
        lr = np.array([s * e["two_ln_lr_for_a"] for s, e in zip(sign, ev)])
        cpu = sorted(r["cpu_s"] for r in rows)[len(rows) // 2]
        lines.append(
            f"| {plant} | {truth} | {len(rows)} | "
            + ", ".join(f"{k} {v}" for k, v in named.most_common())
            + f" | {z.mean():+.2f}, {z.std(ddof=1):.2f}, {np.abs(z).max():.1f} | "
            f"{np.median(lr):+.1f}; {np.mean(lr < -2):.0%} | {cpu:.0f} |")
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    if sys.argv[1:2] == ["--report"]:
        print(report(sys.argv[2:] or [str(OUT)]))
    else:
        main(sys.argv[1:])
