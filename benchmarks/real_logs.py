"""hdid out of the box on logs it was never tuned for: every scenario of
``tests/independent.py`` (an event-driven numpy/scipy generator sharing no code with hdid).

    python benchmarks/real_logs.py            # ≈ 10 fits, each compiling its own program
    python benchmarks/real_logs.py --render   # results/real_logs.md from its JSON
    python benchmarks/real_logs.py --measured # + the measured logs of ../shared/data/real
    python benchmarks/real_logs.py --sts [EFFECT ...]  # the STS3215 drops, base model and + each effect
    python benchmarks/real_logs.py --sts reading_age   # + the readings' age (clock scanned, then held)
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time

from _common import ROOT, interpretation_section, parse_or_render, run_meta, stored, write_result

sys.path.insert(0, str(ROOT / "tests"))

import hdid  # noqa: E402
import independent as ind  # noqa: E402
from hdid.effects import library  # noqa: E402
from hdid._fitting._reading_age import fit_with_age  # noqa: E402

RATES = {"csf32_flywheel": 250.0, "csf32": 250.0, "csf20": 250.0, "csf14": 250.0,
         "csf8": 250.0, "csf8_ratio50": 1000.0, "csf14_ratio30": 4000.0}


def scenarios():
    for ratio in (1.0, 50.0):
        log, truth = ind.pendulum_drop(ratio=ratio, frequency_hz=1.0)
        model = hdid.Model.default(inertia=truth["inertia"], ratio=ratio).without("stiffness")
        yield f"pendulum drop, ratio {ratio:g}", log, truth, model.with_effect(library({})["gravity"]), "mgl"
    log, truth = ind.ring_down(frequency_hz=5.0)
    yield ("ring-down in motion, analog", log, truth,
           hdid.Model.default(inertia=truth["inertia"], ratio=1.0).without("stribeck"), "k1")
    for gear, rate in RATES.items():
        log, truth = ind.paper_design(gear, rate=rate)
        yield (f"paper design {gear} ({truth['natural_frequency_hz']:.0f} Hz, {rate:g} Hz)", log, truth,
               hdid.Model.default(inertia=truth["inertia"], ratio=truth["ratio"]), "k1")


def measured():
    """UR10e joints 1-4 (driven; published model) and the STS3215 drops (m·g·l of the point
    mass), with only what a user knows: ratio 1, the offset, gravity, the lab's inertia."""
    real = ROOT.parent / "shared" / "data" / "real"
    for j, r in json.loads((real / "ur10e_hd/reference.json").read_text())["joints"].items():
        g, p = r["derived_from_published_rigid_body_params"], r["published"]
        ref = dict(inertia=g["effective_inertia_M_jj_kgm2"], c_v=p["Fv_Nms_per_rad"],
                   tau_c=p["Fc_Nm"], mgl=g["gravity_A_Nm"], theta_g=g["gravity_theta0_rad"])
        yield (f"UR10e {j}", real / "ur10e_hd" / r["file"], ["--add", "torque_offset"]
               + ["--add", "gravity"] * bool(ref["mgl"]), {k: v for k, v in ref.items() if v})
    for k, v in json.loads((real / "sts3215_drop/reference.json").read_text())["setups"].items():
        yield (f"STS3215 {k}", real / "sts3215_drop" / v["csv"], ["--remove", "stiffness", "--add", "gravity",
               "--inertia", repr(v["bam_m6_total_inertia_kgm2"])], {"mgl": v["mgl_point_mass_Nm"]})


def judge(result, truth):
    rows = []
    for name, est in ((n, e) for n, e in result.parameters.items() if not e.fixed):
        tv = truth["inertia"] if name == "inertia" else truth["params"][name]
        z = (est.value - tv) / est.std if est.std and math.isfinite(est.std) else math.nan
        flagged = any(name in w for w in result.warnings)
        rows.append(dict(name=name, fit=est.value, std=est.std, truth=tv, z=z, flagged=flagged,
                         ok=bool(flagged or (math.isfinite(z) and abs(z) <= 3))))
    return rows


def sts_rows(add: tuple[str, ...]):
    """The eight STS3215 set-ups fitted with only what a user knows (``--remove stiffness --add gravity --inertia I``,
    I = the lab's armature + m·l²) plus the effects ``add``: RMS/floor, its sample-to-sample part (residual minus its
    5-sample running mean, scaled by √(5/4): what no smooth model can follow — the servo's readings are its own
    samples, taken up to one of its cycles before the host's timestamp) and the armature the fit implies,
    ``m·g·l·I/mgl_fit − m·l²`` (one constant across set-ups if the model is right). With ``reading_age`` the
    fit without it is a row too (the clock is scanned on its residuals)."""
    real = ROOT.parent / "shared" / "data" / "real" / "sts3215_drop"
    for k, v in json.loads((real / "reference.json").read_text())["setups"].items():
        model = (hdid.Model.default(inertia=v["bam_m6_total_inertia_kgm2"], ratio=1.0).without("stiffness")
                 .with_effect(library({})["gravity"]))
        for key in (a for a in add if a != "reading_age"):
            model = model.with_effect(library({"mgl": v["mgl_point_mass_Nm"]})[key])
        fits = []
        load, t0 = os.getloadavg()[0], time.perf_counter()
        res, age = hdid.fit(real / v["csv"], model), {}
        if "reading_age" in add:  # the clock is scanned on the fit without it, then held
            fits.append((tuple(a for a in add if a != "reading_age"), res, {},
                         time.perf_counter() - t0, load))
            load, t0 = os.getloadavg()[0], time.perf_counter()
            res = fit_with_age(real / v["csv"], model, base=res)
            scan = res.reading_age_scans[-1]
            age = dict(sample_period=scan.period, run_periods=list(scan.run_periods),
                       scan_gain=1 - scan.sse / scan.sse_none)
        fits.append((add, res, age, time.perf_counter() - t0, load))
        yield from (_sts_row(k, v, *f) for f in fits)


def _sts_row(k, v, add, res, age, wall, load):
    """One row of :func:`sts_rows` from a fit ``res`` of set-up ``k`` (``v``: its reference)."""
    import numpy as np

    fr, floor = res.residuals(), res.quantization_floor_rad
    fast = np.concatenate([(r := d.residual_rad.to_numpy()) - np.convolve(r, np.ones(5) / 5, "same")
                           for _, d in fr.groupby("run", sort=False)])
    w = np.concatenate([d.weight.to_numpy() for _, d in fr.groupby("run", sort=False)])
    mgl = res.parameters["mgl"].value
    m_l2 = v["mass_kg"] * v["length_m"] ** 2
    row = dict(setup=k, add=list(add), rms=res.rms_residual_rad / floor,
               fast=float(np.sqrt(1.25 * np.sum(w * fast**2) / np.sum(w)) / floor),
               mgl=mgl, mgl_point=v["mgl_point_mass_Nm"], m_l2=m_l2,
               armature=v["mgl_point_mass_Nm"] * v["bam_m6_total_inertia_kgm2"] / mgl - m_l2,
               parameters={n: e.value for n, e in res.parameters.items()}
               | ({"P_ms": 1e3 * age["sample_period"]} if age else {}),
               warnings=res.warnings, wall_s=wall, load=load, **age)
    print(k, add, f"rms {res.rms_residual_rad / floor:.1f}x, mgl {mgl:.4g}, {wall:.0f} s", flush=True)
    return row


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--measured", action="store_true", help="fit the measured logs instead")
    ap.add_argument("--sts", nargs="*", metavar="EFFECT",
                    help="fit the STS3215 drops with the base model plus these effects (none: the base)")
    if (args := parse_or_render(ap, argv, "real_logs", render, indent=1)) is None:
        return
    if args.sts is not None:  # one variant's rows replace that variant's in the stored result
        res, add = stored("real_logs"), tuple(args.sts)
        rows, replaced = list(res.get("sts", [])), set()
        for row in sts_rows(add):  # (with reading_age: the fit without it too)
            if (key := tuple(row["add"])) not in replaced:
                rows, _ = [r for r in rows if tuple(r["add"]) != key], replaced.add(key)
            rows.append({**row, "meta": run_meta()})
            write_result("real_logs", {**res, "sts": rows}, render, indent=1)
        return
    if args.measured:  # rows added to the stored result, one fit (a CLI process) each
        res = {**stored("real_logs"), "measured": []}
        for label, path, opts, ref in measured():
            load, t0, out = os.getloadavg()[0], time.perf_counter(), tempfile.mktemp(".json")
            subprocess.run(["hdid", "fit", str(path), "--ratio", "1", *opts, "--json", out, "-q"])
            d, wall = json.loads(open(out).read()), time.perf_counter() - t0
            rms = (d["rms"]["wg_rad"] / d["rms"]["wg_floor_rad"] if "rms" in d
                   else d["rms_residual_rad"] / d["quantization_floor_rad"])
            res["measured"].append(dict(log=label, options=opts, wall_s=wall, load=load, rms=rms,
                                        vs={k: (d["parameters"][k]["value"], v) for k, v in ref.items()},
                                        warnings=d["warnings"], meta=run_meta()))
            write_result("real_logs", res, render, indent=1)
        return
    out = []
    for label, log, truth, model, key in scenarios():
        load, t0, res, err = os.getloadavg()[0], time.perf_counter(), None, None
        try:
            res = hdid.fit(log, model)
        except hdid.HdidError as exc:
            err = str(exc)
        row = dict(scenario=label, key=key, wall_s=(wall := time.perf_counter() - t0), load=load, error=err)
        if res is not None:
            row.update(parameters=judge(res, truth), warnings=res.warnings,
                       rms_over_floor=res.rms_residual_rad / res.quantization_floor_rad)
        out.append(row)
        print(label, f"{wall:.0f} s", "error: " + err if err else ", ".join(
            f"{p['name']} z={p['z']:+.1f}{'*' if p['flagged'] else ''}" for p in row["parameters"]), flush=True)
    write_result("real_logs", {"meta": run_meta(), "rows": out, "measured": stored("real_logs").get("measured", [])},
                 render, indent=1)


def render(res: dict) -> str:
    lines = ["# hdid on logs from an independent generator (issue 16)", "",
             "`python benchmarks/real_logs.py`; z = (fit − truth)/std; * = named in a warning; ok = |z| ≤ 3 or "
             "flagged. Wall time includes the compile (load average beside it)."
             + (f" {res['meta']['note']}" if res["meta"].get("note") else "")
             + (" Measured {date} on {cpu}, load {load}, src {src}.".format(**res["meta"])
                if "date" in res["meta"] else ""),
             "", "| scenario | key | key fit / truth | all ok | not ok | wall [s] (load) |",
             "|---|---|---|---|---|---|"]
    for r in res["rows"]:
        if r["error"]:
            lines.append(f"| {r['scenario']} | {r['key']} | error: {r['error']} | no | | {r['wall_s']:.0f} "
                         f"({r['load']:.1f}) |")
            continue
        k = {p["name"]: p for p in r["parameters"]}[r["key"]]
        bad = [f"{p['name']} (z {p['z']:+.1f})" for p in r["parameters"] if not p["ok"]]
        lines.append(f"| {r['scenario']} | {r['key']} | {k['fit']:.5g} ± {k['std']:.2g} / {k['truth']:.5g} | "
                     f"{'yes' if not bad else 'no'} | {', '.join(bad)} | {r['wall_s']:.0f} ({r['load']:.1f}) |")
    if res.get("measured"):
        lines += ["", "## Measured logs (`--measured`): fit (fit/reference − 1; theta_g: fit − "
                  "reference)", "", "| log | fit vs reference | RMS/floor | wall [s] (load) |",
                  "|---|---|---|---|"] + [f"| {m['log']} | " + ", ".join(
                      f"{k} {a:.4g} ({a - b:+.3f})" if k == "theta_g" else f"{k} {a:.4g} "
                      f"({a / b - 1:+.0%})" for k, (a, b) in m["vs"].items()) + f" | {m['rms']:.1f}"
                  f" | {m['wall_s']:.0f} ({m['load']:.1f}) |" for m in res["measured"]]
    if res.get("sts"):
        lines += sts_section(res["sts"])
    return "\n".join(lines + [""] + interpretation_section(res)).rstrip("\n") + "\n"


def sts_section(rows: list[dict]) -> list[str]:
    """The STS3215 drops per model variant: RMS/floor and its sample-to-sample part, m·g·l's
    error against the point mass, and the armature each fit implies (its spread across the
    eight set-ups is the test: one gear, one armature)."""
    import statistics

    out = ["", "## STS3215 drops by model (`--sts [EFFECT ...]`)", "",
           "RMS/floor and its sample-to-sample part (the residual minus its 5-sample running mean, "
           "×√(5/4): what no smooth trajectory follows); mgl against m·g·l of the point mass; the "
           "armature the fit implies, m·g·l·I/mgl − m·l² (I the lab's total inertia, fixed in the fit).",
           "", "| set-up | model | RMS/floor | sample-to-sample | mgl (vs m·g·l) | armature [kg m²] | added "
           "| wall [s] (load) |", "|---|---|---|---|---|---|---|---|"]
    variants = []
    for r in rows:
        name = "base" + "".join(f" + {a}" for a in r["add"])
        variants += [name] * (name not in variants)
        added = ", ".join(f"{k} {r['parameters'][k]:.{4 if k == 'P_ms' else 3}g}" for k in r["parameters"]
                          if k not in ("tau_c", "tau_s", "v_s", "delta", "c_v", "mgl", "inertia"))
        if r.get("run_periods"):  # each run's own best period: one clock if the story holds
            rp = sorted(1e3 * p for p in r["run_periods"])
            near = sum(abs(p - 1e3 * r["sample_period"]) < 0.05 for p in rp)
            added += f" (runs: {rp[0]:.3f}–{rp[-1]:.3f} ms, {near}/{len(rp)} within 0.05 ms)"
        out.append(f"| {r['setup']} | {name} | {r['rms']:.1f} | {r['fast']:.1f} | {r['mgl']:.4g} "
                   f"({r['mgl'] / r['mgl_point'] - 1:+.1%}) | {r['armature']:.4f} | {added} | "
                   f"{r['wall_s']:.0f} ({r['load']:.1f}) |")
    out += ["", "| model | set-ups | RMS/floor (median) | mgl error (range) | armature mean ± sd (sd/mean) |",
            "|---|---|---|---|---|"]
    for name in variants:
        sel = [r for r in rows if "base" + "".join(f" + {a}" for a in r["add"]) == name]
        arm = [r["armature"] for r in sel]
        err = [r["mgl"] / r["mgl_point"] - 1 for r in sel]
        sd = statistics.stdev(arm) if len(arm) > 1 else float("nan")
        out.append(f"| {name} | {len(sel)} | {statistics.median(r['rms'] for r in sel):.1f} | {min(err):+.1%} … "
                   f"{max(err):+.1%} | {statistics.mean(arm):.4f} ± {sd:.4f} ({sd / statistics.mean(arm):.1%}) |")
    return out


if __name__ == "__main__":
    main()
