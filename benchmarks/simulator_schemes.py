"""Accuracy and cost of the JAX simulator against the number of RK4 substeps per sample.

Run by hand (takes ~1.5–3 min on 2 cores)::

    python benchmarks/simulator_schemes.py

For substeps ∈ {2, 4, 8, 16, 32} at 250 Hz and 1 kHz it measures

* the max |θ_jax − θ_ref| at the samples over a set of releases (±0.157, ±0.12, ±0.08,
  0.06 rad, each at 5 sub-sample release instants), θ_ref from the event-driven
  reference :func:`hdid.reference.simulate_reference` (DOP853, rtol 1e-11);
* forward run time (jitted, warm, median of many calls) of one 0.5 s record;
* ``jax.jacfwd`` time for the 7 parameters (k1, k2, tau_c, tau_s, c_v, t_release, theta0);
* compile time of both (persistent compilation cache disabled);
* the relative error of d(rest position)/d(parameter) by jacfwd vs central finite
  differences of the *reference* (max over k1, k2, tau_c, tau_s, c_v, theta0 and the
  releases ±0.157, ±0.08), and the spurious d(rest)/d(t_release) (physically 0).

A second table shows the error when the release lies far before the first sample (the
first interval is then long and integrated with the same number of substeps); a third the
accuracy of a candidate fix of the crossing step (see ``_substep_restep``).

Writes ``benchmarks/results/simulator_schemes.md``.
"""

from __future__ import annotations

import os

os.environ.setdefault("HDID_NO_CACHE", "1")  # measure real compile times

import math
import platform
import statistics
import time
from pathlib import Path

import hdid._config  # noqa: F401,E402  (float64)
import jax  # noqa: E402
import numpy as np  # noqa: E402

from hdid._model import Model  # noqa: E402
from hdid._simulate import DEFAULT_MAX_SUBSTEP, simulate, substeps_for  # noqa: E402
from hdid.reference import reference_trajectory, simulate_reference  # noqa: E402

INERTIA = 7.0e-7
CSF8 = dict(k1=940.0, k2=6.5e7, tau_c=3.0e-3, tau_s=4.5e-3, v_s=3.0, delta=1.0, c_v=2.0e-5)
MODEL = Model.default(inertia=INERTIA, **CSF8)
SUBSTEPS = (2, 4, 8, 16, 32)
RATES = (250.0, 1000.0)
RECORD = 0.5  # s
AMPLITUDES = (0.157, -0.157, 0.12, -0.12, 0.08, -0.08, 0.06)
PHASES = (0.07, 0.29, 0.5, 0.71, 0.93)  # release instant, fraction of a sample interval
GRAD_RELEASES = ((0.157, None), (-0.157, None), (0.08, None), (-0.08, None))  # (θ0, unused)
PNAMES = ("k1", "k2", "tau_c", "tau_s", "c_v", "t_release", "theta0")
OMEGA_N = math.sqrt(CSF8["k1"] / 100.0**2 / INERTIA)
QUANT_SIGMA = 4.5e-4

OUT = Path(__file__).resolve().parent / "results" / "simulator_schemes.md"


def _substep_restep(model, inertia, carry, h):
    """Candidate scheme (not in hdid): like ``hdid._simulate._substep`` but the position at
    the velocity zero comes from an RK4 step of length α·h from the start of the substep
    (which stays on the smooth side of the Stribeck kink at ω = 0) plus one Newton step in
    time, instead of a Hermite interpolation of the step that crossed the kink."""
    import jax.numpy as jnp

    from hdid import _simulate as S
    from hdid.effects import Motion

    theta, omega, direction, states = carry
    theta1, omega1, acc0 = S._rk4(model, inertia, theta, omega, direction, states, h)
    sliding = direction != 0
    crossed = sliding & (direction * omega1 <= 0) & (omega1 != omega)
    alpha_lin = jnp.clip(S._safe_div(omega, omega - omega1, crossed), 0.0, 1.0)
    b = acc0 * h
    c = omega1 - omega - b
    v_at = omega + b * alpha_lin + c * alpha_lin**2
    dv = b + 2.0 * c * alpha_lin
    newton_ok = crossed & (jnp.abs(dv) > 0)
    alpha_nt = alpha_lin - S._safe_div(v_at, dv, newton_ok)
    alpha = jnp.where(newton_ok & (alpha_nt >= 0) & (alpha_nt <= 1), alpha_nt, alpha_lin)
    alpha = jnp.where(crossed, alpha, 0.0)
    th_a, om_a, _ = S._rk4(model, inertia, theta, omega, direction, states, alpha * h)
    acc_a = model.torque(Motion(theta=th_a, omega=om_a, direction=direction,
                                ratio=model.ratio), states) / inertia
    dt = S._safe_div(-om_a, acc_a, crossed & (acc_a != 0))
    theta_c = jnp.where(crossed, th_a + om_a * dt + 0.5 * acc_a * dt**2, theta)
    alpha = jnp.clip(alpha + dt / h, 0.0, 1.0)
    event = crossed | ~sliding
    rest = Motion(theta=theta_c, omega=jnp.zeros(()), direction=jnp.zeros(()),
                  ratio=model.ratio)
    net = model.torque(rest, states)
    stick = jnp.abs(net) <= model.holding_torque(rest, states)
    new_direction = jnp.sign(net)
    theta2, omega2, _ = S._rk4(model, inertia, theta_c, jnp.zeros(()), new_direction, states,
                               (1.0 - alpha) * h)
    theta_n = jnp.where(event, jnp.where(stick, theta_c, theta2), theta1)
    omega_n = jnp.where(event, jnp.where(stick, 0.0, omega2), omega1)
    direction_n = jnp.where(event, jnp.where(stick, 0.0, new_direction), direction)
    return theta_n, omega_n, direction_n, model.update_state(states, theta, theta_n)


def median_time(fn, *args, min_calls=30, budget=1.0):
    jax.block_until_ready(fn(*args))
    times = []
    t_start = time.perf_counter()
    while len(times) < min_calls or time.perf_counter() - t_start < budget:
        t0 = time.perf_counter()
        jax.block_until_ready(fn(*args))
        times.append(time.perf_counter() - t0)
        if len(times) >= 2000:
            break
    return statistics.median(times)


def ref_rest(p):
    traj = reference_trajectory(
        2.0, theta0=p[6], t_release=p[5], k1=p[0], k2=p[1], tau_c=p[2], tau_s=p[3],
        v_s=CSF8["v_s"], delta=CSF8["delta"], c_v=p[4], inertia=INERTIA, rtol=1e-12,
        atol=1e-15,
    )
    return traj.theta_rest, traj.n_events


def ref_rest_fd(p0):
    """Central FD of the reference rest point (relative step 1e-4, t_release skipped)."""
    out = {}
    for j, name in enumerate(PNAMES):
        if name == "t_release":
            continue
        step = 1e-4 * abs(p0[j])
        e = np.zeros(7)
        e[j] = step
        (rp, n_p), (rm, n_m) = ref_rest(p0 + e), ref_rest(p0 - e)
        if n_p != n_m:
            raise RuntimeError(f"{name}: reversal count changed inside the FD step")
        out[name] = (rp - rm) / (2 * step)
    return out


def main():
    t_begin = time.perf_counter()
    rows = []
    # Reference data, shared by all substep counts.
    refs = {}
    for fs in RATES:
        times = np.arange(int(round(RECORD * fs))) / fs
        for a in AMPLITUDES:
            for ph in PHASES:
                tr = 0.008 + ph / fs
                refs[fs, a, ph] = (times, tr, simulate_reference(
                    times, theta0=a, t_release=tr, inertia=INERTIA, **CSF8))
    grad_fd = {}
    for a, _ in GRAD_RELEASES:
        p0 = np.array([CSF8["k1"], CSF8["k2"], CSF8["tau_c"], CSF8["tau_s"], CSF8["c_v"],
                       0.0123, a])
        grad_fd[a] = (p0, ref_rest_fd(p0))

    for fs in RATES:
        times = np.arange(int(round(RECORD * fs))) / fs
        for ss in SUBSTEPS:
            fwd = jax.jit(lambda th0, tr, ss=ss, times=times: simulate(
                MODEL, times, th0, tr, substeps=ss))

            def unpack_sim(p, ss=ss, times=times):
                m = MODEL.replace(k1=p[0], k2=p[1], tau_c=p[2], tau_s=p[3], c_v=p[4])
                return simulate(m, times, p[6], p[5], substeps=ss)

            jac = jax.jit(jax.jacfwd(unpack_sim))

            t0 = time.perf_counter()
            jax.block_until_ready(fwd(0.157, 0.0123))
            compile_fwd = time.perf_counter() - t0
            p_first = grad_fd[0.157][0]
            t0 = time.perf_counter()
            jax.block_until_ready(jac(p_first))
            compile_jac = time.perf_counter() - t0

            err = 0.0
            for a in AMPLITUDES:
                for ph in PHASES:
                    _, tr, ref = refs[fs, a, ph]
                    err = max(err, float(np.max(np.abs(np.asarray(fwd(a, tr)) - ref))))

            t_fwd = median_time(fwd, 0.157, 0.0123)
            t_jac = median_time(jac, p_first)

            g_err, g_tr = 0.0, 0.0
            for a, _ in GRAD_RELEASES:
                p0, fd = grad_fd[a]
                ad = np.asarray(jac(p0))[-1]
                for j, name in enumerate(PNAMES):
                    if name == "t_release":
                        g_tr = max(g_tr, abs(float(ad[j])))
                    else:
                        g_err = max(g_err, abs(ad[j] - fd[name]) / abs(fd[name]))
            h = 1.0 / fs / ss
            rows.append(dict(fs=fs, ss=ss, h=h, wh=OMEGA_N * h, err=err, t_fwd=t_fwd,
                             t_jac=t_jac, c_fwd=compile_fwd, c_jac=compile_jac, g_err=g_err,
                             g_tr=g_tr))
            print(f"{fs:6.0f} Hz  substeps {ss:2d}  err {err:.2e}  fwd {t_fwd*1e3:.3f} ms  "
                  f"jac {t_jac*1e3:.3f} ms  compile {compile_fwd:.2f}/{compile_jac:.2f} s  "
                  f"grad err {g_err:.1e}  d/dt_r {g_tr:.1e}", flush=True)

    # Release long before the first sample (default substeps of `simulate`).
    lead_rows = []
    times = np.arange(int(round(RECORD * 250))) / 250.0
    fwd16 = jax.jit(lambda th0, tr: simulate(MODEL, times, th0, tr))
    for lead in (0.002, 0.004, 0.01, 0.03, 0.1):
        ref = simulate_reference(times, theta0=0.157, t_release=-lead, inertia=INERTIA, **CSF8)
        y = np.asarray(fwd16(0.157, -lead))
        lead_rows.append((lead, float(np.max(np.abs(y - ref)))))
        print(f"lead {lead:.3f} s  err {lead_rows[-1][1]:.2e}", flush=True)

    # Candidate scheme, accuracy and forward cost only (monkeypatched while tracing).
    from hdid import _simulate as S

    cand_rows = []
    original = S._substep
    S._substep = _substep_restep
    try:
        for fs in RATES:
            times = np.arange(int(round(RECORD * fs))) / fs
            for ss in (4, 8, 16):
                fwd = jax.jit(lambda th0, tr, ss=ss, times=times: simulate(
                    MODEL, times, th0, tr, substeps=ss))
                err = 0.0
                for a in AMPLITUDES:
                    for ph in PHASES:
                        _, tr, ref = refs[fs, a, ph]
                        err = max(err, float(np.max(np.abs(np.asarray(fwd(a, tr)) - ref))))
                t_fwd = median_time(fwd, 0.157, 0.0123)
                cand_rows.append((fs, ss, err, t_fwd))
                print(f"restep {fs:6.0f} Hz substeps {ss:2d} err {err:.2e} "
                      f"fwd {t_fwd*1e3:.3f} ms", flush=True)
    finally:
        S._substep = original

    write_report(rows, lead_rows, cand_rows, time.perf_counter() - t_begin)


def write_report(rows, lead_rows, cand_rows, elapsed):
    import inspect

    default_ss = inspect.signature(simulate).parameters["substeps"].default
    lines = [
        "# JAX simulator: accuracy and cost against substeps per sample",
        "",
        "Produced by `python benchmarks/simulator_schemes.py` "
        f"({time.strftime('%Y-%m-%d %H:%M')}, {elapsed:.0f} s).",
        "",
        f"- machine: {platform.machine()} {platform.processor() or ''}, "
        f"os.cpu_count() = {os.cpu_count()} (shared with other jobs: timings are noisy), "
        f"{platform.system()} {platform.release()}",
        f"- jax {jax.__version__}, backend {jax.default_backend()}, "
        f"devices {[str(d) for d in jax.devices()]}, python {platform.python_version()}, "
        f"numpy {np.__version__}, float64",
        "- model: CSF-8-like k1 940, k2 6.5e7, tau_c 3e-3, tau_s 4.5e-3, v_s 3, delta 1, "
        f"c_v 2e-5, I 7e-7 (ω_n = {OMEGA_N:.0f} rad/s, {OMEGA_N / 2 / math.pi:.0f} Hz)",
        f"- record {RECORD} s; error: max over θ0 ∈ {list(AMPLITUDES)} × release phases "
        f"{list(PHASES)} of a sample interval, against `simulate_reference` (DOP853, rtol "
        "1e-11). Quantization floor σ_q = 4.5e-4 rad.",
        "- forward and jacfwd (7 parameters) times: jitted, warm, median of ≥ 30 calls, "
        "release +0.157 rad (sticks after ~0.03 s; the loop stops integrating then).",
        "- compile: first call, persistent cache disabled.",
        "- grad err: max relative error of d(rest)/d(k1, k2, tau_c, tau_s, c_v, theta0) by "
        "jacfwd vs central FD (step 1e-4) of the reference, releases ±0.157, ±0.08; "
        "d/dt_r: |d(rest)/d(t_release)| by jacfwd, physically 0 [rad/s] "
        "(compare with the peak speed ~60 rad/s).",
        "",
        "| rate | substeps | h [ms] | ω_n·h | max err [rad] | order | err/σ_q | forward [ms] | "
        "jacfwd [ms] | compile fwd / jac [s] | grad err | d/dt_r [rad/s] |",
        "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    prev = None
    for r in rows:
        order = "" if prev is None or prev["fs"] != r["fs"] else (
            f"{math.log(prev['err'] / r['err'], prev['h'] / r['h']):.1f}")
        prev = r
        lines.append(
            f"| {r['fs']:.0f} Hz | {r['ss']} | {r['h']*1e3:.4g} | {r['wh']:.3f} | "
            f"{r['err']:.1e} | {order} | {r['err']/QUANT_SIGMA:.3f} | {r['t_fwd']*1e3:.3f} | "
            f"{r['t_jac']*1e3:.3f} | {r['c_fwd']:.2f} / {r['c_jac']:.2f} | "
            f"{r['g_err']:.1e} | {r['g_tr']:.1e} |"
        )
    lines += [
        "",
        f"`simulate`'s default is substeps = {default_ss}; `substeps_for(period)` with "
        f"DEFAULT_MAX_SUBSTEP = {DEFAULT_MAX_SUBSTEP} s gives {substeps_for(1 / 250)} at "
        f"250 Hz and {substeps_for(1 / 1000)} at 1 kHz.",
        "",
        "## Release long before the first sample (250 Hz, default substeps)",
        "",
        "The first interval after the release (release → t[0]) spans the whole lead and is "
        "integrated with the same number of substeps.",
        "",
        "| lead before t[0] [s] | max err [rad] |",
        "|---:|---:|",
    ]
    for lead, e in lead_rows:
        lines.append(f"| {lead:g} | {e:.1e} |")
    lines += [
        "",
        "## Candidate: re-step to the velocity zero (not in hdid; `_substep_restep` here)",
        "",
        "`order` above is the observed convergence order log(e₁/e₂)/log(h₁/h₂): about 2, "
        "not RK4's 4. The substep that contains a velocity zero integrates across the kink "
        "of exp(−|ω|/v_s) at ω = 0 (direction frozen) and takes the stop position from a "
        "Hermite interpolation of that step. Re-integrating α·h from the start of the "
        "substep (smooth side) plus one Newton step in time removes the kink from the "
        "stop position:",
        "",
        "| rate | substeps | max err [rad] | forward [ms] |",
        "|---:|---:|---:|---:|",
    ]
    for fs, ss, e, t in cand_rows:
        lines.append(f"| {fs:.0f} Hz | {ss} | {e:.1e} | {t*1e3:.3f} |")
    lines.append("")
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text("\n".join(lines))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
