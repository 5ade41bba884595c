"""Diagnosis suite: hide each library effect in turn (and none, one outside the library) in
the shipped plant and see what ``diagnose`` names; ``--removed``: base pieces switched off.

    python benchmarks/diagnose_suite.py [rich|paper ...]   # about 20–40 min on 2 cores
    python benchmarks/diagnose_suite.py --removed          # then: the base pieces' rows
    python benchmarks/diagnose_suite.py --render
"""

from __future__ import annotations

import argparse
import json

from _common import RESULTS, Clock, parse_or_render, run_designs, run_meta, write_result

from hdid.reference import logs

NAME = "diagnose_suite"
#: The richer design: four release amplitudes at 1 kHz, one set-up. Smallest amplitude
#: 0.07 rad, not the committed rich log's 0.05: with a hidden 0.02 rad dead zone (or
#: load-dependent friction) a 0.05 rad release cannot overcome static friction and the
#: run shows no motion at all.
RICH = dict(amplitudes=[0.157, -0.157, 0.13, -0.13, 0.10, -0.10, 0.07, -0.07], fs=1000.0,
            duration=0.3, hold=0.04, offsets_by_setup={"A": 0.005})


#: Base pieces switched off: the log has nothing hidden, the *model* lacks the piece.
REMOVED = ("viscous", "stribeck", "stiffness")


def _model_without(piece: str):
    import hdid
    from hdid.effects import LinearStiffness

    m = hdid.Model.default()
    if piece == "stiffness":  # the cubic term off: a linear spring
        return m.with_effect(LinearStiffness(k1=940.0))
    return m.without(piece)


def run_design(design_name: str, gen, hid, records: list, seed0: int, removed: bool = False) -> None:
    from hdid._diagnosis._diagnose import diagnose

    design = dict(RICH if design_name == "rich" else gen.PAPER_DESIGN)
    truth = {k: v for k, v in gen.TRUTH_CSF8.items() if k != "ratio"}
    names = [f"removed:{p}" for p in REMOVED] if removed else ["none", *hid.HIDDEN]
    for i, name in enumerate(names):
        design["seed"] = seed0 + i
        hidden = hid.reference_kwargs(name, truth) if name in hid.HIDDEN else None
        df = gen.make_log(truth, **design, hidden=hidden)
        try:
            with Clock() as clock:
                d = diagnose(df, _model_without(name.split(":")[1]) if removed else None)
        except Exception as exc:  # record and go on: the suite reports failures too
            records.append({"design": design_name, "hidden": name, "error": repr(exc)})
            print(f"{design_name:5s} {name:20s} FAILED {exc!r}", flush=True)
            continue
        top = d.best
        rec = {
            "design": design_name, "hidden": name,
            "expected": ("none" if name == "none" else name.split(":")[1] if removed
                         else hid.HIDDEN[name]["library"]),
            "verdict": d.verdict,
            "top": top.key if top is not None and top.delta_bic < -10 else "none",
            "top_any": top.key if top is not None else None,
            "floor_rad": d.floor_rad, "rms_before_floor": d.base.rms_residual_rad / d.floor_rad,
            "whiteness_before": {k: v for k, v in d.whiteness_before.to_dict().items()
                                 if k in ("p_value", "rms_ratio", "white", "at_floor", "adequate")},
            "candidates": [{"effect": c.key, "variant": c.label, "rms_after_floor": c.rms_after_rad / d.floor_rad,
                            "delta_bic": c.delta_bic, "adequate_after": c.adequate_after, "error": c.error}
                           for c in d.candidates],
            "notes": d.notes, "seconds": clock.wall,
        }
        records.append(rec)
        cands = ", ".join(f"{c['effect']} {c['delta_bic']:.0f}" for c in rec["candidates"][:3])
        after = rec["candidates"][0]["rms_after_floor"] if rec["candidates"] else float("nan")
        print(f"{design_name:5s} {name:20s} verdict {d.verdict:15s} top {rec['top']:20s} RMS "
              f"{rec['rms_before_floor']:.2f}→{after:.2f} [{cands}] {clock.wall:.0f}s", flush=True)


def write(records: list, meta: dict) -> None:
    write_result(NAME, {"meta": meta, "records": records}, render)


def render(res: dict) -> str:
    records, meta = res["records"], res["meta"]
    lines = [
        "# Diagnosis suite: hidden effect × top-ranked candidate",
        "",
        f"Run {meta['date']} on {meta['cpu']} ({meta['cores']} cores, load {meta['load']}), "
        f"src {meta['src']}. `python benchmarks/diagnose_suite.py`.",
        "",
        "`top` is the best candidate if its ΔBIC < −10 (strong evidence), else `none`. "
        "RMS in units of the quantization floor (step/√12). `fixes` = the residual after "
        "adding the top candidate is white (Ljung–Box p ≥ 0.01) and at the floor (≤ 1.3×). "
        "`ambiguous` = the runner-up is also strong and within ΔBIC 10 of the top: "
        "`diagnose` then says the data cannot tell the two apart.",
        "",
    ]
    for design in ("rich", "paper"):
        rows = [r for r in records if r["design"] == design]
        if not rows:
            continue
        lines += [f"## {design} design", "",
                  "| hidden | expected | verdict | top (ΔBIC<−10) | ΔBIC top | runner-up | RMS before | RMS after top | fixes | ambiguous | s |",
                  "|---|---|---|---|---|---|---|---|---|---|---|"]
        for r in rows:
            if "error" in r:
                lines.append(f"| {r['hidden']} | | FAILED: {r['error']} | | | | | | | |")
                continue
            c = r["candidates"]
            c0 = c[0] if c else {}
            c1 = f"{c[1]['effect']} ({c[1]['delta_bic']:.0f})" if len(c) > 1 else ""
            amb = (len(c) > 1 and c0.get("delta_bic", 0) < -10 and c[1]["delta_bic"] < -10
                   and c[1]["delta_bic"] - c0["delta_bic"] < 10)
            lines.append(
                f"| {r['hidden']} | {r['expected']} | {r['verdict']} | {r['top']} | "
                f"{c0.get('delta_bic', float('nan')):.1f} | {c1} | {r['rms_before_floor']:.2f} | "
                f"{c0.get('rms_after_floor', float('nan')):.2f} | {c0.get('adequate_after')} | "
                f"{'yes' if amb else ''} | {r['seconds']:.0f} |"
            )
        ok = [r for r in rows if "error" not in r]
        lib = [r for r in ok if r["expected"] not in ("none", None) and not r["hidden"].startswith("removed:")]
        removed = [r for r in ok if r["hidden"].startswith("removed:")]
        clean = [r for r in ok if r["hidden"] == "none"]
        outside = [r for r in ok if r["expected"] is None]
        fixed = [r for r in lib if r["top"] == r["expected"]
                 and r["candidates"][0]["rms_after_floor"] <= 1.3]
        lines += [
            "",
            f"- hidden library effect ranked first: {sum(r['top'] == r['expected'] for r in lib)}/{len(lib)}"
            f"; ranked first *and* RMS after ≤ 1.3× floor: {len(fixed)}/{len(lib)}",
            f"- nothing hidden, verdict `adequate` (no false alarm): "
            f"{sum(r['verdict'] == 'adequate' for r in clean)}/{len(clean)}",
            "- outside the library: " + ", ".join(
                f"{r['hidden']} → {r['verdict']}"
                + (f" ({r['top']}, RMS after {r['candidates'][0]['rms_after_floor']:.2f}× floor)"
                   if r["verdict"] == "missing_effect" else "") for r in outside),
        ]
        if removed:
            lines.append(f"- base piece switched off in the model, found again: "
                         f"{sum(r['top'] == r['expected'] for r in removed)}/{len(removed)}")
        lines.append("")
    return "\n".join(lines) + "\n"


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("designs", nargs="*", metavar="rich|paper", help="default: both")
    ap.add_argument("--removed", action="store_true",
                    help="the base-piece rows, added to the suite's records")
    args = parse_or_render(ap, argv, NAME, render)
    if args is None:
        return
    designs = args.designs or ["rich", "paper"]
    gen = hid = logs  # the generators and the hidden effects
    records: list = []
    if args.removed and (RESULTS / f"{NAME}.json").exists():
        old = json.loads((RESULTS / f"{NAME}.json").read_text())["records"]
        records = [r for r in old if not (str(r.get("hidden", "")).startswith("removed:")
                                          and r["design"] in designs)]

    def run(k, design):
        # Compiled programs of the previous design are not needed again; a long process
        # that keeps them all ran out of memory mappings (LLVM "Cannot allocate memory").
        import jax

        jax.clear_caches()
        run_design(design, gen, hid, records, seed0=(7500 if args.removed else 7100) + 100 * k,
                   removed=args.removed)

    run_designs(designs, run, write, records, run_meta())


if __name__ == "__main__":
    main()
