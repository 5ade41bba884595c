"""hdid out of the box on logs it was never tuned for: every scenario of
``tests/independent.py`` (an event-driven numpy/scipy generator sharing no code with hdid).

    python benchmarks/real_logs.py            # ≈ 10 fits, each compiling its own program
    python benchmarks/real_logs.py --render   # results/real_logs.md from its JSON
    python benchmarks/real_logs.py --measured # + the measured logs of ../shared/data/real
    python benchmarks/real_logs.py --sts [EFFECT ...]  # the STS3215 drops, base model and + each effect
    python benchmarks/real_logs.py --sts reading_age   # + the readings' age (clock scanned, then held)
    python benchmarks/real_logs.py --sts back_emf@clamp  # + back_emf, w_e held at the supply's clamp speed
    python benchmarks/real_logs.py --energy  # STS3215: friction laws by energy per half-swing (no fit)
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
        fix = {"w_e": clamp_speed(real)} if "back_emf@clamp" in add else {}
        for key in (a.removesuffix("@clamp") for a in add if a != "reading_age"):
            model = model.with_effect(library({"mgl": v["mgl_point_mass_Nm"], **fix})[key])
        fits = []
        load, t0 = os.getloadavg()[0], time.perf_counter()
        res, age = hdid.fit(real / v["csv"], model, fix=fix or None), {}
        if "reading_age" in add:  # the clock is scanned on the fit without it, then held
            fits.append((tuple(a for a in add if a != "reading_age"), res, {},
                         time.perf_counter() - t0, load))
            load, t0 = os.getloadavg()[0], time.perf_counter()
            res = fit_with_age(real / v["csv"], model, base=res, **({"fix": fix} if fix else {}))
            scan = res.reading_age_scans[-1]
            age = dict(sample_period=scan.period, run_periods=list(scan.run_periods),
                       scan_gain=1 - scan.sse / scan.sse_none)
        fits.append((add, res, age, time.perf_counter() - t0, load))
        yield from (_sts_row(k, v, *f) for f in fits)


def clamp_speed(real) -> float:
    """``back_emf@clamp``'s threshold [rad/s]: the speed at which the coasting motor's back-EMF
    passes the 12 V supply plus two silicon diode drops (0.7 V each), over the lab's own back-EMF
    constant (k_e = k_t in SI units, K-Scale's fitted kt, referred to the output)."""
    kt = json.loads((real / "reference.json").read_text())["bam_fits_published"]["m1"]["kt"]
    return (12.0 + 2 * 0.7) / kt


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
    ap.add_argument("--energy", action="store_true", help="STS3215: friction laws judged by the "
                    "energy lost per half-swing (model-free, seconds)")
    if (args := parse_or_render(ap, argv, "real_logs", render, indent=1)) is None:
        return
    if args.energy:
        res = stored("real_logs")
        fits = [r for r in res.get("sts", []) if not r["add"]]
        return write_result("real_logs", {**res, "sts_energy": sts_energy(fits)}, render, indent=1)
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
    if res.get("sts_energy"):
        lines += energy_section(res["sts_energy"])
    if res.get("sts_rotor_md"):  # retired experiment: its tables as last rendered
        lines += ["", res["sts_rotor_md"]]
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


LAWS = {"Coulomb": ["coul"], "+ viscous": ["coul", "visc"], "+ viscous + ω² drag": ["coul", "visc", "drag"],
        "+ viscous + gear efficiency": ["coul", "visc", "gear"],
        "+ viscous + bearing load": ["coul", "visc", "bearing"],
        "+ viscous + back-EMF (w_e scanned)": ["coul", "visc", "emf"]}
EMF_W = [1.0 + 0.25 * i for i in range(25)]  # back-EMF threshold speeds scanned [rad/s]


def half_swings(t, th, m, l, mgl, inertia):
    """The half-swings of one run after its release, each with the energy it lost
    ``mgl·(cos θ_b − cos θ_a)`` [J] (zero speed at both ends: no kinetic energy, the inertia
    drops out) and the work per unit coefficient of each friction law along the measured path
    (speed from a Savitzky-Golay derivative on a 5 ms grid of 4-reading means): Coulomb ``|Δθ|``; viscous ∫ω²dt;
    ω² drag ∫|ω|³dt; gear efficiency ∫(mgl/I)|sin θ||ω|dt (the rotor's share of the gravity
    torque the gear transmits; coefficient (1 − η)·J_rotor [kg m²]); bearing load
    ∫m·|(g cos θ + lω², g sin θ·(1 − ml²/I))||ω|dt (the output bearing's reaction force;
    coefficient μ·r [m]); back-EMF ∫max(|ω| − w_e, 0)|ω|dt; and the zero's offset
    ``mgl·(sin θ_a − sin θ_b)`` (coefficient the hanging angle θ_g, free in sign)."""
    import numpy as np
    from scipy.signal import savgol_filter

    dt, g, box = 0.005, 9.81, np.ones(4) / 4
    # a 4-reading mean first: the servo's 8 ms encoder clock against the 100 Hz polls ages the
    # readings in a 4-poll sawtooth (±1.5 rad/s on a raw derivative at 6 rad/s); the mean nulls
    # it and its harmonics and passes the < 1 Hz swing (0.3 % at 1 Hz)
    t, th = np.convolve(t, box, "valid"), np.convolve(th, box, "valid")
    grid = np.arange(t[0], t[-1], dt)
    y = savgol_filter(np.interp(grid, t, th), 9, 3)
    w = savgol_filter(np.interp(grid, t, th), 9, 3, deriv=1, delta=dt)
    moving = np.flatnonzero(np.abs(w) > 0.05)  # 0.05 rad/s: above the readings' noise at rest
    if not len(moving):
        return []
    ends, sign = [0], np.sign(w[moving[0]])
    for i in moving:
        if np.sign(w[i]) != sign:  # a turning point: the extreme angle since the last one
            seg = y[ends[-1]:i]
            ends.append(ends[-1] + int(np.argmax(seg) if sign > 0 else np.argmin(seg)))
            sign = np.sign(w[i])
    ends.append(min(moving[-1] + 10, len(y) - 1))  # the rest after the last motion
    out = []
    for a, b in zip(ends[:-1], ends[1:]):
        th_, aw = y[a:b + 1], np.abs(w[a:b + 1])
        if abs(y[b] - y[a]) < 0.05:  # a flicker, not a swing
            continue
        load = m * np.hypot(g * np.cos(th_) + l * w[a:b + 1] ** 2, g * np.sin(th_) * (1 - m * l * l / inertia))
        out.append(dict(loss=mgl * (np.cos(y[b]) - np.cos(y[a])), coul=abs(y[b] - y[a]), visc=dt * np.sum(aw**2),
                        drag=dt * np.sum(aw**3), gear=dt * np.sum(mgl / inertia * np.abs(np.sin(th_)) * aw),
                        bearing=dt * np.sum(load * aw), off=mgl * (np.sin(y[a]) - np.sin(y[b])),
                        emf=[dt * np.sum(np.maximum(aw - we, 0) * aw) for we in EMF_W], speed=aw))
    return out


def sts_energy(fits: list[dict]) -> dict:
    """Each friction law of :data:`LAWS` judged on the STS3215 drops by the energy each
    half-swing lost, without a trajectory fit: least squares (coefficients ≥ 0, each set-up's
    θ_g free) per set-up (``own``) and with one set of constants for all eight (``pooled``: one
    servo, one law), against the scatter of the same half-swing over a set-up's repeated runs.
    ``fits``: the stored base fits (``--sts``), whose own Stribeck + viscous law is judged the
    same way (its friction scaled by m·g·l/mgl: the trajectory fixes friction/mgl)."""
    import numpy as np
    import pandas as pd
    from scipy.optimize import lsq_linear

    real = ROOT.parent / "shared" / "data" / "real" / "sts3215_drop"
    rows = []
    for k, v in json.loads((real / "reference.json").read_text())["setups"].items():
        d = pd.read_csv(real / v["csv"])
        for run, r in d.groupby("run", sort=False):
            r = r[r.time >= v["runs"][run]["release_time_in_csv_s"] - 1e-9]
            hs = half_swings(r.time.to_numpy(), r.theta.to_numpy(), v["mass_kg"], v["length_m"],
                             v["mgl_point_mass_Nm"], v["bam_m6_total_inertia_kgm2"])
            rows += [dict(h, setup=k, kp=run.split("_")[0], n=n) for n, h in enumerate(hs)]
    hs = pd.DataFrame(rows)
    setups = list(dict.fromkeys(hs.setup))
    rep = hs.groupby(["setup", "kp", "n"]).loss
    scatter = float(np.sqrt(((hs.loss - rep.transform("mean")) ** 2).sum() / (len(hs) - rep.ngroups)))

    def solve(d, cols, iw):
        base = np.column_stack([np.asarray([e[iw] for e in d.emf]) if c == "emf" else d[c] for c in cols])
        offs = np.column_stack([np.where(d.setup == s, d.off, 0.0) for s in dict.fromkeys(d.setup)])
        a = np.hstack([base, offs])
        x = lsq_linear(a, d.loss.to_numpy(), bounds=([0] * len(cols) + [-np.inf] * offs.shape[1], np.inf)).x
        return x[:len(cols)], d.loss.to_numpy() - a @ x

    laws = []
    for name, cols in LAWS.items():
        iws = range(len(EMF_W)) if "emf" in cols else [0]
        own = {s: min((solve(hs[hs.setup == s], cols, i) + (EMF_W[i],) for i in iws),
                      key=lambda f: np.sum(f[1] ** 2)) for s in setups}
        coef, res, we = min((solve(hs, cols, i) + (EMF_W[i],) for i in iws), key=lambda f: np.sum(f[1] ** 2))
        laws.append(dict(law=name, cols=cols, own_rms={s: float(np.sqrt(np.mean(f[1] ** 2))) for s, f in own.items()},
                         own_coef={s: [float(c) for c in f[0]] + [f[2]] * ("emf" in cols) for s, f in own.items()},
                         pooled_rms=float(np.sqrt(np.mean(res**2))),
                         pooled_coef=[float(c) for c in coef] + [we] * ("emf" in cols)))
    own = {}
    for f in fits:  # the base fits' friction, τ_c + (τ_s − τ_c)·exp(−|ω/v_s|^δ) + c_v·|ω|
        p, d = f["parameters"], hs[hs.setup == f["setup"]]
        work = [0.005 * np.sum((p["tau_c"] + (p["tau_s"] - p["tau_c"]) * np.exp(-(w / p["v_s"]) ** p["delta"])
                                + p["c_v"] * w) * w) * f["mgl_point"] / p["mgl"] for w in d.speed]
        x = lsq_linear(d.off.to_numpy()[:, None], d.loss.to_numpy() - work).x  # its θ_g
        own[f["setup"]] = float(np.sqrt(np.mean((d.loss.to_numpy() - work - x[0] * d.off.to_numpy()) ** 2)))
    if own:
        laws.append(dict(law="the base trajectory fit's own law", cols=[], own_rms=own, own_coef={},
                         pooled_rms=None, pooled_coef=[]))
    return dict(half_swings=len(hs), scatter=scatter, laws=laws, meta=run_meta())


def _g(x: float) -> str:
    """A coefficient at its bound (below 1e-6 of any unit used here) as 0, else 3 digits."""
    return "0" if abs(x) < 1e-6 else f"{x:.3g}"


def energy_section(e: dict) -> list[str]:
    """The friction laws by energy per half-swing (:func:`sts_energy`) as a table."""
    import statistics

    out = ["", "## STS3215: friction laws by the energy lost per half-swing (`--energy`, no fit)", "",
           f"{e['half_swings']} half-swings of the 64 runs; loss = m·g·l·(cos θ_b − cos θ_a) between turning points "
           "(the inertia drops out) against each law's work along the measured path; each set-up's θ_g free. "
           f"Repeated runs of a set-up lose the same energy per half-swing within {1e3 * e['scatter']:.1f} mJ "
           "(RMS): a law that holds for the servo fits every set-up, with one set of constants, near that.", "",
           "| law | own fit per set-up: RMS [mJ] median (max) | coefficients per set-up (min … max) | one set for "
           "all eight: RMS [mJ] | its constants |", "|---|---|---|---|---|"]
    for law in e["laws"]:
        own = list(law["own_rms"].values())
        names = law["cols"] + ["w_e"] * ("emf" in law["cols"])
        per = [[c[i] for c in law["own_coef"].values()] for i in range(len(names))]
        pooled = "—" if law["pooled_rms"] is None else f"{1e3 * law['pooled_rms']:.1f}"
        out.append(f"| {law['law']} | {1e3 * statistics.median(own):.1f} ({1e3 * max(own):.1f}) | "
                   + (", ".join(f"{n} {_g(min(p))} … {_g(max(p))}" for n, p in zip(names, per)) or "(its fit's)")
                   + f" | {pooled} | "
                   + ", ".join(f"{n} {_g(c)}" for n, c in zip(names, law["pooled_coef"])) + " |")
    return out


if __name__ == "__main__":
    main()
