"""False-alarm rate of ``hdid diagnose`` on clean logs, and its time per log.

Per design (the paper's ±0.157 rad at 250 Hz, and a rich one: four amplitudes at 1 kHz):
a log with nothing hidden is made with the independent generator
(``hdid.reference.logs.make_log``) and fitted with the base model; then ``N`` clean logs
are simulated *from that fitted model* with hdid's own simulator (``hdid.simulate``'s
``synthesize``: the same release angles, rate and length, a random sub-sample release
instant per run, rounded to the same 4000-count encoder) and diagnosed with every
candidate. The base model is then exactly right, so every verdict other than
``adequate`` and every candidate with ΔBIC < −10 is a false alarm. The rate is reported
with its exact (Clopper–Pearson) 95 % binomial interval.

Run: ``python calibration/diagnose_rates.py [N] [paper|rich ...]``; writes
``calibration/results/diagnose_rates.{json,md}``; ``--measured`` then regenerates the
``MEASURED`` block of ``src/hdid/_diagnosis/_rates.py`` from that file (nothing run).
"""

from __future__ import annotations

import json
import os
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))  # _common
from _common import ROOT, load_text, run_meta  # noqa: E402

from hdid.reference import logs  # noqa: E402

OUT = ROOT / "calibration" / "results"
NAME = "diagnose_rates"
RICH = dict(amplitudes=[0.157, -0.157, 0.12, -0.12, 0.08, -0.08, 0.05, -0.05], fs=1000.0,
            duration=0.3, hold=0.04, offsets_by_setup={"A": 0.005})


def clopper_pearson(k: int, n: int, level: float = 0.95) -> tuple[float, float]:
    """Exact binomial interval (the same as :func:`hdid._diagnosis._rates.clopper_pearson`,
    which reads the module this script generates)."""
    from scipy.stats import beta

    a = 1 - level
    lo = 0.0 if k == 0 else float(beta.ppf(a / 2, k, n - k + 1))
    hi = 1.0 if k == n else float(beta.ppf(1 - a / 2, k + 1, n - k))
    return lo, hi


def _second_setup(path: Path) -> None:
    """The paper design's second set-up: runs of the second half re-labelled ``B`` with
    their readings shifted by a whole number of encoder steps (−17: a different offset,
    rounded exactly as if the encoder had read it, since round(x + k) = round(x) + k)."""
    import numpy as np
    import pandas as pd

    df = pd.read_csv(path)
    runs = sorted(df["run"].unique())
    late = df["run"].isin(runs[len(runs) // 2:])
    step = 2 * np.pi / 4000
    df["setup"] = np.where(late, "B", "A")
    df.loc[late, "theta"] = df.loc[late, "theta"] - 17 * step
    df.to_csv(path, index=False)


def run_design(name: str, n: int, gen, records: list, meta: dict | None = None,
               first: int = 0) -> None:
    import hdid
    from hdid._problems import _programs
    from hdid._simulation._synthetic import synthesize

    design = dict(RICH if name == "rich" else gen.PAPER_DESIGN)
    truth = {k: v for k, v in gen.TRUTH_CSF8.items() if k != "ratio"}
    seed_log = gen.make_log(truth, **{**design, "seed": 9001})
    fitted = hdid.fit(seed_log)
    amps = list(design["amplitudes"])
    with tempfile.TemporaryDirectory() as tmp:
        for i in range(first, n):
            path = Path(tmp) / f"{name}_{i}.csv"
            synthesize(path, amplitudes=amps, rate=design["fs"], duration=design["duration"],
                       hold=design["hold"], offset=0.005, model=fitted.model, seed=1000 + i)
            if len(design["offsets_by_setup"]) > 1:
                _second_setup(path)
            t0, c0 = time.perf_counter(), time.process_time()
            load = os.getloadavg()[0]
            try:
                d = hdid.diagnose(path)
            except Exception as exc:  # recorded: failures are results too
                records.append({"design": name, "i": i, "error": repr(exc)})
                print(f"{name} {i} FAILED {exc!r}", flush=True)
                continue
            best = d.best
            rec = {
                "design": name, "i": i, "verdict": d.verdict,
                "best": best.key if best else None,
                "best_dbic": best.delta_bic if best else None,
                "strong": [c.key for c in d.candidates if c.error is None and c.delta_bic < -10],
                "candidates": [(c.label, c.delta_bic) for c in d.candidates if c.error is None],
                "warnings": d.warnings,
                "rms_before_floor": d.base.rms_residual_rad / d.floor_rad,
                "wall_s": time.perf_counter() - t0, "cpu_s": time.process_time() - c0,
                "compile_s": d.timing.get("compile_s"), "load1": load,
                "load1_after": os.getloadavg()[0],
                # the process's memory mappings and how often hdid dropped its compiled
                # programs to bound them (one process diagnoses every log: issue 19)
                "maps": _programs._maps(), "releases": _programs.RELEASES,
                "date": (meta or {}).get("date"), "src": (meta or {}).get("src"),
            }
            records.append(rec)
            if meta is not None:  # results so far, in case the run is stopped
                write(records, meta)
            print(f"{name} {i:3d} {d.verdict:15s} best {rec['best']} {rec['best_dbic']:.1f} "
                  f"RMS {rec['rms_before_floor']:.2f} {rec['wall_s']:.0f}s (load {load:.1f}) "
                  f"maps {rec['maps']} releases {rec['releases']}",
                  flush=True)


def write(records: list, meta: dict) -> None:
    OUT.mkdir(exist_ok=True)
    (OUT / f"{NAME}.json").write_text(
        json.dumps({"meta": meta, "records": records}, indent=2) + "\n")
    lines = [
        "# `diagnose` false alarms on clean logs simulated from a fitted model",
        "",
        f"Run {meta['date']} on {meta['cpu']} ({meta['cores']} cores, shared; pinned to one "
        f"core), load at start {meta['load']}"
        + (f", at end {meta['load_end']}" if meta.get("load_end") else "")
        + f"; src {meta['src']}. `{meta.get('cmd', 'python calibration/diagnose_rates.py')}`. "
        "Paper design: 4 runs at 250 Hz, two set-ups (the second half's readings shifted by "
        "17 whole encoder steps); rich: 8 runs (±0.157/0.12/0.08/0.05 rad) at 1 kHz.",
        "",
        "A false alarm is any verdict other than `adequate`; `strong` counts logs where some "
        "candidate had ΔBIC < −10. 95 % intervals are exact binomial (Clopper–Pearson).",
        "",
        "| design | logs | false alarms (verdict) | rate, 95 % interval | one-sided 95 % upper bound | logs with a strong candidate | median s (wall) | median s (CPU) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    for design in ("paper", "rich"):
        rows = [r for r in records if r["design"] == design and "error" not in r]
        if not rows:
            continue
        k = sum(r["verdict"] != "adequate" for r in rows)
        s = sum(bool(r["strong"]) for r in rows)
        lo, hi = clopper_pearson(k, len(rows))
        wall = sorted(r["wall_s"] for r in rows)[len(rows) // 2]
        cpu = sorted(r["cpu_s"] for r in rows)[len(rows) // 2]
        from scipy.stats import beta

        up = 1.0 if k >= len(rows) else float(beta.ppf(0.95, k + 1, len(rows) - k))
        lines.append(f"| {design} | {len(rows)} | {k} | {k / len(rows):.1%} [{lo:.1%}, {hi:.1%}] "
                     f"| {up:.2%} | {s} | {wall:.0f} | {cpu:.0f} |")
    fails = [r for r in records if "error" in r]
    if fails:
        lines += ["", f"{len(fails)} diagnose call(s) failed: "
                  + "; ".join(f"{r['design']} {r['i']}: {r['error']}" for r in fails)]
    lines += ["", "`hdid._diagnosis._rates.MEASURED` is generated from this file's JSON "
              "(`python calibration/diagnose_rates.py --measured` writes "
              "its block in `src/hdid/_diagnosis/_rates.py`):", "", "```python"]
    lines += [_design_rate_line(t) for t in measured_table(records)]
    lines += ["```", "", "Per log:", "",
              "| design | # | verdict | best (ΔBIC) | RMS before / floor | s | load before → after |",
              "|---|---|---|---|---|---|---|"]
    for r in records:
        if "error" in r:
            continue
        lines.append(f"| {r['design']} | {r['i']} | {r['verdict']} | {r['best']} "
                     f"({r['best_dbic']:.1f}) | {r['rms_before_floor']:.2f} | {r['wall_s']:.0f} "
                     f"| {r['load1']:.1f} → {r.get('load1_after', float('nan')):.1f} |")
    (OUT / f"{NAME}.md").write_text("\n".join(lines) + "\n")


#: The designs' sample rate [Hz] and number of runs (what ``false_alarm`` matches a log to).
DESIGN_SHAPE = {"paper": (250.0, 4), "rich": (1000.0, 8)}
MEASURED_MODULE = ROOT / "src" / "hdid" / "_diagnosis" / "_rates.py"


def measured_table(records: list) -> list[dict]:
    """Per design: false alarms, clean logs, the 95 % interval and where it was measured
    (the dates and source fingerprints of its records)."""
    out = []
    for design, (rate, runs) in DESIGN_SHAPE.items():
        rows = [r for r in records if r["design"] == design and "error" not in r]
        if not rows:
            continue
        k = sum(r["verdict"] != "adequate" for r in rows)
        lo, hi = clopper_pearson(k, len(rows))
        where = sorted({f"{(r.get('date') or '?')[:10]}, src {r.get('src') or '?'}"
                        for r in rows})
        out.append({"design": design, "rate_hz": rate, "runs": runs, "alarms": k,
                    "logs": len(rows), "lo": round(lo, 4), "hi": round(hi, 4),
                    "measured": "measured " + "; ".join(where)})
    return out


def _design_rate_line(t: dict) -> str:
    return "{" + ", ".join(f"{k!r}: {v!r}" for k, v in t.items()) + "},"


def write_measured(records: list) -> str:
    """The generated block of ``src/hdid/_diagnosis/_rates.py`` (between its ``BEGIN`` and
    ``END GENERATED`` markers) from the records: never typed by hand."""
    body = "\n".join("    " + _design_rate_line(t) for t in measured_table(records))
    block = "ROWS = (\n" + body + "\n)\n"
    text = MEASURED_MODULE.read_text()
    a, b = "# BEGIN GENERATED\n", "# END GENERATED\n"
    i, j = text.index(a) + len(a), text.index(b)
    MEASURED_MODULE.write_text(text[:i] + block + text[j:])
    return block


def _stamp(records: list, meta: dict) -> None:
    """Where records without provenance were measured: the designs this file's last run
    names, at its date and source; the others at the run before it."""
    ran = [d for d in DESIGN_SHAPE if d in (meta.get("cmd") or "")]
    earlier = meta.get("earlier") or {}
    for r in records:
        src = meta if r["design"] in ran else earlier
        r.setdefault("date", src.get("date"))
        r.setdefault("src", src.get("src"))


def _arguments(argv: list[str]):
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("words", nargs="*", metavar="[N] [paper|rich ...]",
                    help="logs per design (default 10) and the designs (default both)")
    ap.add_argument("--measured", action="store_true",
                    help="regenerate _diagnosis/_rates.py's MEASURED block from the results")
    ap.add_argument("--from", dest="first", type=int, default=0, metavar="K",
                    help="logs K … N−1 only, added to the design's earlier records")
    ap.add_argument("--fresh", action="store_true", help="drop the other designs' records")
    a = ap.parse_args(argv)
    bad = [w for w in a.words if not w.isdigit() and w not in ("paper", "rich")]
    if bad:
        ap.error(f"unknown argument(s) {bad}: give N and the designs paper, rich")
    return a


def main(argv: list[str]) -> None:
    args = _arguments(argv)
    if args.measured:  # the module from the committed results, nothing run
        prev = json.loads((OUT / f"{NAME}.json").read_text())
        _stamp(prev["records"], prev["meta"])
        write(prev["records"], prev["meta"])
        print(write_measured(prev["records"]))
        return
    n = next((int(w) for w in args.words if w.isdigit()), 10)
    designs = [w for w in args.words if w in ("paper", "rich")] or ["paper", "rich"]
    gen = logs
    meta = run_meta(n_per_design=n, cmd="taskset -c 0 python calibration/diagnose_rates.py "
                    + " ".join(argv))
    records: list = []
    old = OUT / f"{NAME}.json"
    # --from K: logs K … N−1 only, adding to this design's earlier records (seeds 1000+i)
    first = args.first
    if old.exists() and not args.fresh:  # keep the other designs' records
        prev = json.loads(old.read_text())
        records = [r for r in prev["records"] if r["design"] not in designs
                   or (first and r["i"] < first)]
        for r in records:  # records of earlier runs keep where they were measured
            r.setdefault("date", prev["meta"].get("date"))
            r.setdefault("src", prev["meta"].get("src"))
        meta["earlier"] = {k: prev["meta"].get(k) for k in ("date", "load", "load_end", "src")}
    for design in designs:  # written after each design: a stopped run keeps what it measured
        run_design(design, n, gen, records, meta, first)
        write(records, meta)
    meta["load_end"] = load_text()
    write(records, meta)

if __name__ == "__main__":
    main(sys.argv[1:])
