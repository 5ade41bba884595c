"""Why the posterior chain of the 4-run paper log mixes slowly: measurements, not guesses.

Run (≈ 2–4 min on 2 busy cores)::

    python benchmarks/posterior_geometry.py [--gauss-steps 20000] [--steps 3000]

Three measurements on ``data/synthetic/csf8_paper.csv`` (D = 18 sampled unknowns):

1. **The moves on an ideal target.** emcee on an 18-D *Gaussian* with this log's
   least-squares covariance (plus one unit-variance noise dimension), started from the
   Gaussian itself, ``--gauss-steps`` steps: the integrated autocorrelation time τ of the
   stretch move (emcee's default) against differential evolution (DE) mixtures. This is the
   best each move can do here; the real posterior can only be slower.
2. **How non-quadratic the likelihood is.** The least-squares cost
   (``Σ r²``, residuals in σ_q = q/√12 units, so ``−log L = cost/2``) along the
   eigen-directions of its Gauss–Newton covariance ``(JᵀJ)⁻¹``: a quadratic likelihood
   rises by exactly ``t²`` at ``t`` standard deviations; the measured rise says how far the
   posterior departs from the Laplace approximation in its weakest directions.
3. **Which parameters make the real posterior hard.** ``sample_posterior``'s sampler
   (DE moves, Laplace start, 400 burn-in steps, Widrow-Gaussian likelihood so that the
   noise does not matter) run ``--steps`` steps with all unknowns free, and with the
   Stribeck shape (``v_s``, ``delta``) or the release instants held at their least-squares
   values: acceptance and τ at equal chain length.

4. **A second, deeper minimum.** The profile cost along ``k1`` (``k1`` fixed at the fit's
   value ± 1, 2 least-squares sd, every other unknown re-optimised by Levenberg–Marquardt),
   and a free re-optimisation started from the ``+2 sd`` profile point: if it ends at a
   lower cost than ``hdid.fit``'s optimum, the likelihood has another mode.

Writes ``benchmarks/results/posterior_geometry.md`` and ``.json``; load averages recorded.
"""

from __future__ import annotations

import _common  # noqa: E402,F401  (benchmarks/ is on sys.path when run as a script)
import argparse
import datetime as _dt
import json
import math
import os
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
LOG = ROOT / "data" / "synthetic" / "csf8_paper.csv"
RESULTS = ROOT / "benchmarks" / "results"


def _load():
    return [round(x, 2) for x in os.getloadavg()]


def gaussian_moves(cov, steps, seed=0):
    import emcee

    from hdid._posterior import default_moves

    D = cov.shape[0] + 1
    C = np.eye(D)
    C[:-1, :-1] = cov
    Ci = np.linalg.inv(C)

    def f(X):
        return -0.5 * np.einsum("ij,jk,ik->i", X, Ci, X)

    rng = np.random.default_rng(seed)
    cases = [
        ("stretch (emcee default)", 36, None),
        ("stretch (emcee default)", 72, None),
        ("DE 0.8 + DE-snooker 0.2", 36, lambda: [(emcee.moves.DEMove(), 0.8),
                                               (emcee.moves.DESnookerMove(), 0.2)]),
        ("hdid default_moves()", 36, default_moves),
    ]
    out = []
    for name, W, mv in cases:
        P0 = rng.multivariate_normal(np.zeros(D), C, size=W)
        s = emcee.EnsembleSampler(W, D, f, vectorize=True, moves=None if mv is None else mv())
        t = time.perf_counter()
        s.run_mcmc(P0, steps)
        tau = s.get_autocorr_time(tol=0)
        out.append({"moves": name, "walkers": W, "steps": steps, "tau_max": float(tau.max()),
                    "tau_median": float(np.median(tau)),
                    "acceptance": float(s.acceptance_fraction.mean()),
                    "wall_s": time.perf_counter() - t, "load": _load()})
        print(out[-1], flush=True)
    return out


def cost_profile(fit):
    import equinox as eqx
    import jax
    import jax.numpy as jnp

    p = fit.problem
    u = np.asarray(fit.u)
    cost = eqx.filter_jit(jax.vmap(lambda v: jnp.sum(p.data_residuals(v) ** 2)))
    _, J = p.data_residuals_and_jacobian(jnp.asarray(u))
    J = np.asarray(J)
    H = J.T @ J
    w, V = np.linalg.eigh(np.linalg.pinv(H))
    c0 = float(cost(jnp.asarray(u[None]))[0])
    labels = list(p.free) + [f"u[{i}]" for i in range(len(p.free), u.size)]
    t = np.array([-2.0, -1.0, -0.5, 0.5, 1.0, 2.0])
    rows = []
    for k in (-1, -2, -3, -4, -5, 0):
        v = V[:, k] * math.sqrt(max(w[k], 0.0))
        dc = np.asarray(cost(jnp.asarray(u + t[:, None] * v))) - c0
        top = np.argsort(-np.abs(V[:, k]))[:3]
        rows.append({"eigen_rank": "weakest" if k == -1 else ("strongest" if k == 0 else f"{-k}th weakest"),
                     "sd": float(math.sqrt(max(w[k], 0.0))),
                     "loadings": {labels[i]: round(float(V[i, k]), 2) for i in top},
                     "t": t.tolist(), "delta_cost": dc.tolist()})
        print(rows[-1], flush=True)
    return rows


def fixed_subsets(fit, steps, seed=0):
    import emcee
    import jax.numpy as jnp

    from hdid._posterior import LogPosterior, _laplace_start, default_moves

    p = fit.problem
    q = float(p.step)
    lp = LogPosterior(problem=p, centre=jnp.asarray(fit.u), temper=jnp.asarray(1.0),
                      quant_var=q * q / 12)
    x0 = np.append(np.asarray(fit.u), math.log(0.2 * q))
    names = list(p.free)
    P = len(names)
    R = p.n_runs
    sets = {"none (all 18 free)": [],
            "v_s, delta": [names.index("v_s"), names.index("delta")],
            "release instants": list(range(P, P + R))}
    out = []
    for label, fixed in sets.items():
        free = [i for i in range(x0.size) if i not in fixed]

        def f(X, free=free):
            Y = np.tile(x0, (len(X), 1))
            Y[:, free] = X
            return np.asarray(lp.batch(jnp.asarray(Y)))

        rng = np.random.default_rng(seed)
        D = len(free)
        W = max(32, 2 * D)
        P0, _ = _laplace_start(fit, x0, lambda X: np.asarray(lp.batch(jnp.asarray(X))), W, rng,
                               math.log(0.05 * q), math.log(0.3 * q))
        P0 = P0[:, free]
        s = emcee.EnsembleSampler(W, D, f, vectorize=True, moves=default_moves())
        st = s.run_mcmc(emcee.State(P0, log_prob=f(P0),
                                    random_state=np.random.RandomState(seed).get_state()),
                        400, skip_initial_state_check=True)
        s.reset()
        t = time.perf_counter()
        s.run_mcmc(st, steps, skip_initial_state_check=True)
        tau = s.get_autocorr_time(tol=0)
        out.append({"fixed": label, "D": D, "walkers": W, "steps": steps,
                    "acceptance": float(s.acceptance_fraction.mean()),
                    "tau_max": float(tau.max()), "tau_median": float(np.median(tau)),
                    "wall_s": time.perf_counter() - t, "load": _load()})
        print(out[-1], flush=True)
    return out


def second_minimum(fit):
    import equinox as eqx
    import jax.numpy as jnp
    from scipy.optimize import least_squares

    p = fit.problem
    u0 = np.asarray(fit.u)
    rj = eqx.filter_jit(lambda v: p.residuals_and_jacobian(v))

    def cost(v):
        return float(np.sum(np.asarray(rj(jnp.asarray(v))[0]) ** 2))

    c0 = cost(u0)
    sd = np.sqrt(np.diag(np.asarray(fit.covariance)))
    j = list(p.free).index("k1")
    free = [i for i in range(u0.size) if i != j]
    prof = {}
    start = None
    for t in (-2.0, -1.0, 1.0, 2.0):
        def full(x, t=t):
            v = u0.copy()
            v[free] = x
            v[j] = u0[j] + t * sd[j]
            return v

        sol = least_squares(lambda x: np.asarray(rj(jnp.asarray(full(x)))[0]), u0[free],
                            jac=lambda x: np.asarray(rj(jnp.asarray(full(x)))[1])[:, free],
                            method="lm", max_nfev=200)
        prof[t] = float(np.sum(sol.fun ** 2)) - c0
        if t == 2.0:
            start = full(sol.x)
    sol = least_squares(lambda x: np.asarray(rj(jnp.asarray(x))[0]), start,
                        jac=lambda x: np.asarray(rj(jnp.asarray(x))[1]), method="lm",
                        max_nfev=300)
    names = ["k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v"]
    a, b = p.values_np(u0), p.values_np(sol.x)
    out = {"fit_cost": c0, "profile_k1_delta_cost": {str(k): v for k, v in prof.items()},
           "second_cost": float(np.sum(sol.fun ** 2)),
           "fit_values": {n: a[n] for n in names if n in a},
           "second_values": {n: b[n] for n in names if n in b},
           "shift_in_lsq_sd": ((sol.x - u0) / sd).tolist()}
    print(out, flush=True)
    return out


def render(res):
    L = ["# Posterior geometry of the 4-run paper log: why the chain mixes slowly\n",
         f"Generated by `python benchmarks/posterior_geometry.py` on {res['generated']} "
         f"({res['total_s']:.0f} s; load average 1/5/15 min at start {res['load_start']}, "
         f"end {res['load_end']}; 2 shared cores). Log `data/synthetic/csf8_paper.csv`, "
         f"D = 18 sampled unknowns.\n",
         "## 1. The moves on an ideal 18-D Gaussian (this log's least-squares covariance)\n",
         "| moves | walkers | steps | acceptance | τ max | τ median | 50 τ_max in steps |",
         "|---|---|---|---|---|---|---|"]
    for r in res["gaussian"]:
        L.append(f"| {r['moves']} | {r['walkers']} | {r['steps']} | {r['acceptance']:.2f} | "
                 f"{r['tau_max']:.0f} | {r['tau_median']:.0f} | {50 * r['tau_max']:.0f} |")
    L.append("\nEven on a Gaussian, the stretch move needs ≈ 50 × 250–290 ≈ 13 000–15 000 steps "
             "for 50 τ in 18 dimensions — at ≈ 6 ms per step (36 walkers, see "
             "`posterior_speed.md`) that alone is 80–90 s. Differential evolution is ≈ 4× "
             "better on this target.\n")
    L.append("## 2. The likelihood along the Laplace approximation's eigen-directions\n")
    L.append("Rise of the least-squares cost (Σ r², r in q/√12 units) from the optimum at t "
             "standard deviations of `(JᵀJ)⁻¹` along each eigen-direction; a quadratic "
             "(Gaussian) likelihood gives t² = 4, 1, 0.25, 0.25, 1, 4.\n")
    L.append("| direction | sd | top loadings | Δcost at t = −2, −1, −½, ½, 1, 2 |\n|---|---|---|---|")
    for r in res["cost_profile"]:
        L.append(f"| {r['eigen_rank']} | {r['sd']:.3g} | "
                 + ", ".join(f"{k} {v:+.2f}" for k, v in r["loadings"].items()) + " | "
                 + ", ".join(f"{x:.3g}" for x in r["delta_cost"]) + " |")
    L.append("\nIn its strongest directions the likelihood is quadratic; in the weakest "
             "(Stribeck shape `delta`, `v_s`, and `k2`/`c_v`) it rises 10–10⁴× faster than the "
             "Laplace approximation says, and asymmetrically: the posterior is a thin, "
             "curved ridge there, not an ellipsoid. Affine-invariant moves (stretch, DE) only "
             "undo *linear* correlations, so on a curved ridge they must take small steps.\n")
    L.append("## 3. Which unknowns make the real posterior slow (Widrow-Gaussian likelihood)\n")
    L.append("| held at the LSQ value | D | walkers | steps | acceptance | τ max | τ median |\n"
             "|---|---|---|---|---|---|---|")
    for r in res["fixed"]:
        L.append(f"| {r['fixed']} | {r['D']} | {r['walkers']} | {r['steps']} | "
                 f"{r['acceptance']:.2f} | {r['tau_max']:.0f} | {r['tau_median']:.0f} |")
    L.append("\nτ from chains this short is a lower bound (it grows with the chain while the "
             "chain is < 50 τ), so compare rows at equal length only. Holding the Stribeck "
             "shape fixed is a diagnosis, not a remedy: it would hide real uncertainty.\n")
    m = res.get("second_minimum")
    if m:
        L.append("\n## 4. A second, deeper minimum of the least-squares cost\n")
        L.append("Profile cost along k1 (every other unknown re-optimised), relative to "
                 f"`hdid.fit`'s optimum (cost {m['fit_cost']:.2f}): "
                 + ", ".join(f"{float(k):+.0f} sd: {v:+.2f}"
                             for k, v in m["profile_k1_delta_cost"].items())
                 + ". A Gaussian likelihood would rise smoothly by ≈ t²/s² at t sd.\n")
        L.append(f"Re-optimising everything from the +2 sd profile point ends at cost "
                 f"**{m['second_cost']:.2f}** (vs {m['fit_cost']:.2f}: its log-likelihood is "
                 f"{(m['fit_cost'] - m['second_cost']) / 2:+.1f} higher, Gaussian q/√12 "
                 f"noise). The shipped log's truth is `TRUTH_CSF8` (k1 940, k2 6.5e7, tau_c "
                 f"2.5e-3, tau_s 4.5e-3, v_s 5, delta 1, c_v 1.8e-5): the deeper minimum is the "
                 f"*farther* one. The likelihood is multimodal; an ensemble started at the fit's "
                 f"optimum leaks walkers slowly towards the other mode, so τ keeps growing with "
                 f"the chain and intervals from a local chain under-cover.\n")
        L.append("| parameter | fit's optimum | second minimum |\n|---|---|---|")
        for n, v in m["fit_values"].items():
            L.append(f"| {n} | {v:.4g} | {m['second_values'][n]:.4g} |")
        L.append("")
    return "\n".join(L) + "\n"


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--gauss-steps", type=int, default=20000)
    ap.add_argument("--steps", type=int, default=3000)
    ap.add_argument("--out-dir", type=Path, default=RESULTS)
    ap.add_argument("--add-minimum", type=Path,
                    help="add section 4 to the results in this JSON and re-render")
    args = ap.parse_args(argv)
    import hdid

    if args.add_minimum:
        res = json.loads(args.add_minimum.read_text())
        t0 = time.perf_counter()
        res["second_minimum"] = second_minimum(hdid.fit(LOG))
        res["second_minimum"]["wall_s"] = time.perf_counter() - t0
        res["second_minimum"]["load"] = _load()
        args.add_minimum.write_text(json.dumps(res, indent=2) + "\n")
        (args.add_minimum.parent / "posterior_geometry.md").write_text(render(res))
        print(render(res))
        return 0

    t0 = time.perf_counter()
    res = {"generated": _dt.datetime.now().isoformat(timespec="seconds"), "load_start": _load()}
    fit = hdid.fit(LOG)
    res["gaussian"] = gaussian_moves(np.asarray(fit.covariance), args.gauss_steps)
    res["cost_profile"] = cost_profile(fit)
    res["fixed"] = fixed_subsets(fit, args.steps)
    res["second_minimum"] = second_minimum(fit)
    res["load_end"] = _load()
    res["total_s"] = time.perf_counter() - t0
    args.out_dir.mkdir(parents=True, exist_ok=True)
    (args.out_dir / "posterior_geometry.json").write_text(json.dumps(res, indent=2) + "\n")
    (args.out_dir / "posterior_geometry.md").write_text(render(res))
    print(render(res))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
