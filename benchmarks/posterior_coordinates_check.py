"""Step 1 of issue 17's data-coordinates idea (branch ``post6``): is the posterior nearer
Gaussian when the friction law is written as its torque at the log's own speeds?

Run (pinned to one core)::

    taskset -c 1 python benchmarks/posterior_coordinates_check.py chain LOG STEPS [plain|friction]
    taskset -c 1 python benchmarks/posterior_coordinates_check.py analyse LOG
    taskset -c 1 python benchmarks/posterior_coordinates_check.py profile
    taskset -c 1 python benchmarks/posterior_coordinates_check.py tail shipped _friction

``chain``: today's default sampler (plain coordinates; ``friction`` as a 4th argument), ``n_steps=STEPS`` fixed, seed 1,
on LOG (``shipped`` or a seed of the independent simulator, drawn as in
``posterior_coordinates.py``); the chain, the fit's trajectory speeds and τ are saved to
``/tmp/post6/chain_LOG.npz`` (not committed: ~100 MB). ``analyse``: the last 80 % of the
chain (every 7th step) in the sampler's plain coordinates (k1, k2, tau_c, c_v in value;
v_s, tau_s in log; delta in logit) and in candidate data coordinates — the friction
torque ``F(ω)`` at two or three speeds (quantiles of the fit's sliding speeds |ω| over
time, or fractions of the peak) replacing (tau_c, c_v) or (tau_c, c_v, v_s). Reported per
coordinate: the residual variance of a linear regression on the others divided by that of
a quadratic one (1: the dependence is linear, which differential-evolution moves undo;
large: a curved ridge), skewness and excess kurtosis; and the correlation matrix's
condition number (irrelevant to affine-invariant moves, shown for reference).
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import json
import os
import sys
import time

import numpy as np

OUT = "/tmp/post6"


def chain(name, steps, coordinates="plain"):
    import hdid
    from hdid._posterior.density import posterior_density
    from hdid._posterior.modes import sampled_modes
    from posterior_coordinates import load_fit

    os.makedirs(OUT, exist_ok=True)
    t0 = time.perf_counter()
    fit, prior, truth = load_fit(name)
    print(name, "fit", time.perf_counter() - t0, os.getloadavg(), flush=True)
    prob = fit.problem
    theta, omega, stuck = map(np.asarray, prob.simulate(np.asarray(fit.u), prob.times,
                                                       full_output=True))
    dens = posterior_density(fit, prior=prior)
    found = sampled_modes(fit, "auto", 1, dens.u_fit, dens.lin, dens.lp.gauss_prior)
    t = time.perf_counter()
    post = hdid.sample_posterior(fit, modes=found, seed=1, prior=prior, n_steps=steps,
                                 coordinates=coordinates)
    print(name, "sample", time.perf_counter() - t, os.getloadavg(), flush=True)
    print(post.convergence.worst, np.max(post.tau))
    tag = "" if coordinates == "plain" else f"_{coordinates}"
    free = list(prob.free)
    tc = np.exp(post.chain[:, :, free.index("tau_c")])
    for b in range(0, steps, steps // 6):
        print(f"steps {b}–{b + steps // 6}: tau_c 0.5/2.5/50 % "
              f"{np.round(np.percentile(tc[b:b + steps // 6], [0.5, 2.5, 50]) * 1e3, 3).tolist()} mN m")
    s = post.summary()
    print({q: s[q]["ci95"] for q in ("tau_c", "c_v", "v_s", "delta", "tau_s", "stick_band_halfwidth_rad")})
    np.savez(f"{OUT}/chain_{name}{tag}.npz", chain=post.chain, free=np.array(prob.free),
             omega=omega, stuck=stuck, lengths=np.asarray([len(x) for x in prob.times]),
             tau=post.tau, labels=np.array(post.labels), truth=json.dumps(truth or {}))


def analyse(name):
    from scipy import stats

    d = np.load(f"{OUT}/chain_{name}.npz")
    ch = d["chain"]
    free = list(d["free"])
    S, W, D = ch.shape
    X = ch[S // 5:].reshape(-1, D)[::7]
    v = {n: (0.3 + 3.7 / (1 + np.exp(-X[:, i])) if n == "delta" else np.exp(X[:, i]))
         for i, n in enumerate(free)}
    om, st, L = d["omega"], d["stuck"], d["lengths"]
    sp = np.concatenate([np.abs(om[r, :L[r]][(~st[r, :L[r]]) & (np.abs(om[r, :L[r]]) > 0)])
                         for r in range(om.shape[0])])
    peak = sp.max()
    qs = np.percentile(sp, [10, 25, 50, 75, 90])
    print(f"{name}: {X.shape[0]} draws; sliding speed quantiles 10/25/50/75/90 % = "
          f"{np.round(qs / peak, 3).tolist()} × peak {peak:.1f} rad/s; τ_max {np.nanmax(d['tau']):.0f}")

    def F(w):
        e = np.exp(-(w / v["v_s"]) ** v["delta"])
        return v["tau_c"] + (v["tau_s"] - v["tau_c"]) * e + v["c_v"] * w

    def report(label, names, cols):
        Z = np.column_stack(cols)
        Zs = (Z - Z.mean(0)) / Z.std(0)
        ev = np.linalg.eigvalsh(np.corrcoef(Zs.T))
        cells = []
        for j in range(Z.shape[1]):
            y, O = Zs[:, j], np.delete(Zs, j, axis=1)
            A1 = np.column_stack([np.ones(len(y)), O])
            r1 = np.var(y - A1 @ np.linalg.lstsq(A1, y, rcond=None)[0])
            A2 = np.column_stack([A1] + [O[:, a] * O[:, b] for a in range(O.shape[1])
                                         for b in range(a, O.shape[1])])
            r2 = np.var(y - A2 @ np.linalg.lstsq(A2, y, rcond=None)[0])
            cells.append(f"{names[j]} {r1 / r2:.1f} ({stats.skew(y):+.1f}, {stats.kurtosis(y):+.1f})")
        worst = max(float(c.split()[1]) for c in cells)
        print(f"| {name} | {label} | **{worst:.1f}** | {'; '.join(cells)} | {ev.max() / ev.min():.0f} |")

    lg, i = np.log, free.index
    base = [v["k1"], v["k2"]]
    report("plain (tau_c, c_v, v_s, delta, tau_s)", ["k1", "k2", "tau_c", "c_v", "v_s", "delta", "tau_s"],
           base + [v["tau_c"], v["c_v"], lg(v["v_s"]), X[:, i("delta")], lg(v["tau_s"])])
    for lab, ws in [("q25, q75", [qs[1], qs[3]]), ("q10, q90", [qs[0], qs[4]]),
                    ("0.25, 1 × peak", [0.25 * peak, peak]), ("q50, peak", [qs[2], peak])]:
        report(f"F at {lab} + v_s, delta, tau_s", ["k1", "k2", "F1", "F2", "v_s", "delta", "tau_s"],
               base + [F(w) for w in ws] + [lg(v["v_s"]), X[:, i("delta")], lg(v["tau_s"])])
    for lab, ws in [("q10, q50, q90", [qs[0], qs[2], qs[4]]), ("q25, q50, q90", [qs[1], qs[2], qs[4]]),
                    ("0.25, 0.5, 1 × peak", [0.25 * peak, 0.5 * peak, peak])]:
        report(f"F at {lab} + delta, tau_s", ["k1", "k2", "F1", "F2", "F3", "delta", "tau_s"],
               base + [F(w) for w in ws] + [X[:, i("delta")], lg(v["tau_s"])])


def profile():
    """Least-squares cost of the shipped log with tau_c fixed below its optimum (the other
    parameters refitted): how flat the likelihood is along the Coulomb-limit ridge."""
    import hdid

    p = str(_common.ROOT / "data" / "synthetic" / "csf8_paper.csv")
    f0 = hdid.fit(p)
    c0 = f0.starts.costs[f0.starts.best]
    keys = ("v_s", "c_v", "delta", "tau_s")
    print(f"free: tau_c {f0.parameters['tau_c'].value:.4g}, χ² {c0:.2f}, "
          + ", ".join(f"{k} {f0.parameters[k].value:.4g}" for k in keys))
    for tc in (1.5e-3, 1e-3, 5e-4, 2e-4, 5e-5):
        f = hdid.fit(p, fix={"tau_c": tc})
        c = f.starts.costs[f.starts.best]
        print(f"tau_c {tc:.1e}: Δχ² {c - c0:+.2f}, " + ", ".join(
            f"{k} {f.parameters[k].value:.4g}" for k in keys) + f"; load {os.getloadavg()[0]:.2f}")


def tail(name="shipped", tag="_friction"):
    """log p(u) (the posterior density of the fit's unknowns: the same whatever the
    sampler's coordinates) of 36 draws per decade of tau_c from the last half of a saved
    chain: is the Coulomb-limit plateau the chain reached real?"""
    import jax.numpy as jnp

    from hdid._posterior.density import posterior_density
    from posterior_coordinates import load_fit

    fit, prior, _ = load_fit(name)
    lp = posterior_density(fit, prior=prior).lp
    d = np.load(f"{OUT}/chain_{name}{tag}.npz")
    ch, free = d["chain"], list(d["free"])
    U = ch[ch.shape[0] // 2:].reshape(-1, ch.shape[2])
    tc = np.exp(U[:, free.index("tau_c")])
    rng = np.random.default_rng(0)
    for lo, hi in [(2e-3, 3e-3), (1e-3, 2e-3), (1e-4, 1e-3), (1e-5, 1e-4), (0, 1e-5)]:
        m = np.flatnonzero((tc >= lo) & (tc < hi))
        if m.size == 0:
            continue
        pick = rng.choice(m, size=min(36, m.size), replace=False)
        X = lp.to_sampled_np(U[pick])
        v = np.asarray(lp.batch(jnp.asarray(X))) - np.array(
            [float(lp.to_u(jnp.asarray(x))[1]) for x in X])
        med = {n: float(f"{np.median(np.exp(U[pick, free.index(n)])):.3g}") for n in ("v_s", "c_v", "tau_s")}
        print(f"| [{lo:.0e}, {hi:.0e}) | {m.size / tc.size:.3f} | {v.max():.1f} | {np.median(v):.1f} | {med} |")


if __name__ == "__main__":
    if sys.argv[1] == "tail":
        tail(*sys.argv[2:4])
    elif sys.argv[1] == "profile":
        profile()
    elif sys.argv[1] == "chain":
        chain(sys.argv[2], int(sys.argv[3]), *sys.argv[4:5])
    else:
        analyse(sys.argv[2])
