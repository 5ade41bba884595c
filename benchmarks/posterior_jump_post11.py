"""The affine mode-jump move (issue 17, ``post11``) against the default emcee moves, side
by side in one process on one fit (same optima and limit fits: ``sampled_modes`` is
seeded by the run's seed), seeds alternating which variant goes first.

Run (pinned to one core)::

    PYTHONPATH=src taskset -c 0 python benchmarks/posterior_jump_post11.py \
        --log shipped --seeds 1 2 3 4 --max-steps 10000 [--variants default jump:0.1]

``default``: ``hdid.sample_posterior(fit, seed=s, max_steps=N)`` as on main (``default_t``:
the same chain, its independence move counting its region crossings; ``walkers:W``: the
default with ``W`` walkers and the step cap scaled by 36/W, the same density calls);
``jump:W``: the same with ``moves=`` a factory returning ``default_moves(proposal)`` scaled to
``1 − W`` plus :class:`~hdid._posterior.jump.ModeJumpMove` on the driver's mixture
(``_Adaptive``) at weight ``W`` (``jump_w:W`` weights the assignment by the mixture
weights; ``jumpm:W`` jumps among the modes proper only — the optima and the limit fits'
ends, not the continuations' first points: :func:`mode_components`). ``--log 9100`` /
``9101``: the independent-simulator paper logs of
``posterior_nautilus.make_log`` (with their catalogue priors). Records per run: R-hat
max (and of which quantity), τ_max, bulk/tail ESS min, tau_c's / k2's / the band's 95 %
intervals, the kept chain's shares below tau_c 1 mN m and with k2 < 0.1 × the fit's, the
moves' acceptances, the jump's proposals that passed the assignment check and its
accepted jumps per pair of components (named by the modes' kinds), wall per stage and the
1-min load before/after; appends to ``results/posterior_jump_post11.json`` and rewrites
the ``.md``.

The jump variants need ``src/hdid/_posterior/jump.py`` (``ModeJumpMove``), retired by
these measurements (benchmarks/README.md, ``post11``): it and its test are last in commit
24ba95c — run the script on that tree (``git archive 24ba95c``) for them; ``default``,
``default_t``, ``walkers:W`` and ``--affine-check`` run on any tree since.
"""

from __future__ import annotations

import _common  # noqa: F401,E402
import argparse
import datetime as _dt
import json
import os
from pathlib import Path

import numpy as np

import hdid

ROOT = Path(__file__).resolve().parent.parent
RESULTS = ROOT / "benchmarks" / "results"
NAME = "posterior_jump_post11"
BAND = "stick_band_halfwidth_rad"


def _load():
    return [round(x, 2) for x in os.getloadavg()]


def mode_components(fit, prior, seed: int) -> list[int]:
    """Indices of the mixture's components that are modes proper: the optima and the limit
    fits' ends (not the continuations' first points, which sit beside the fit's optimum).
    The driver's mixture has one component per ``sampled_modes`` entry, in its order; this
    repeats the driver's call (same density, same seed: same optima)."""
    from hdid._posterior.density import posterior_density
    from hdid._posterior.modes import sampled_modes

    dens = posterior_density(fit, prior=prior)
    found = sampled_modes(fit, "auto", seed, dens.u_fit, dens.lin, dens.lp.gauss_prior)
    return [k for k, m in enumerate(found) if m.kind == "optimum" or m.limit is not None]


def _regions(fit, lp):
    """``region(X)``: (k2 < 0.1 × the fit's, tau_c < 1 mN m) of sampled coordinates."""
    free = list(fit.problem.free)
    ik2, itc = free.index("k2"), free.index("tau_c")
    k2_fit = fit.values["k2"]

    def region(X):
        U = lp.from_sampled_np(np.asarray(X))
        return np.exp(U[:, ik2]) < 0.1 * k2_fit, np.exp(U[:, itc]) < 1e-3

    return region


class _TrackRegions:
    """Mixin for an emcee move: counts its accepted proposals that move a walker into or
    out of the two regions (reset by ``burn_in_update``). Draws no random numbers."""

    def propose(self, model, state):
        before = self.region_of(state.coords)
        new, acc = super().propose(model, state)
        after = self.region_of(new.coords)
        for name, b, a in zip(("k2", "tau_c"), before, after):
            self.region[name + "_in"] += int(np.sum(acc & ~b & a))
            self.region[name + "_out"] += int(np.sum(acc & b & ~a))
        return new, acc

    def burn_in_update(self, acceptance, draws):
        if hasattr(super(), "burn_in_update"):
            super().burn_in_update(acceptance, draws)
        self.region = dict.fromkeys(("k2_in", "k2_out", "tau_c_in", "tau_c_out"), 0)


def _default_tracked(fit, keep: list):
    """``moves=`` factory: the default moves, the independence move counting its region
    crossings (same random numbers: the chain is the default's)."""
    import emcee

    from hdid._posterior.moves import default_moves

    class TrackedMH(_TrackRegions, emcee.moves.MHMove):
        pass

    def make(lp, proposal):
        out = []
        for m, w in default_moves(proposal):
            if isinstance(m, emcee.moves.MHMove):
                m = TrackedMH(proposal)
                m.region_of = _regions(fit, lp)
                m.burn_in_update(None, None)
                keep.append(m)
            out.append((m, w))
        return out

    return make


def _factory(fit, weight: float, use_weights: bool, keep: list, components=None):
    """``moves=`` factory: the default moves and a :class:`ModeJumpMove` that also counts its
    accepted jumps into and out of the two regions (k2 < 0.1 × the fit's: the k2 → 0
    optimum; tau_c < 1 mN m: down the Coulomb ridge), whatever components they join."""
    from hdid._posterior.jump import ModeJumpMove, mode_jump_moves
    from hdid._posterior.moves import default_moves

    free = list(fit.problem.free)
    ik2, itc = free.index("k2"), free.index("tau_c")
    k2_fit = fit.values["k2"]

    def make(lp, proposal):
        def region(X):
            U = lp.from_sampled_np(np.asarray(X))
            return np.exp(U[:, ik2]) < 0.1 * k2_fit, np.exp(U[:, itc]) < 1e-3

        class Tracked(ModeJumpMove):
            def propose(self, model, state):
                before = region(state.coords)
                new, acc = super().propose(model, state)
                after = region(new.coords)
                for name, b, a in zip(("k2", "tau_c"), before, after):
                    self.region[name + "_in"] += int(np.sum(acc & ~b & a))
                    self.region[name + "_out"] += int(np.sum(acc & b & ~a))
                return new, acc

            def burn_in_update(self, acceptance, draws):
                super().burn_in_update(acceptance, draws)
                self.region = dict.fromkeys(("k2_in", "k2_out", "tau_c_in", "tau_c_out"), 0)

        moves = mode_jump_moves(default_moves(proposal), proposal, weight,
                                use_weights=use_weights, components=components)
        out = []
        for m, w in moves:
            if isinstance(m, ModeJumpMove):
                m = Tracked(proposal, use_weights=use_weights, components=components)
                m.burn_in_update(None, None)
                keep.append(m)
            out.append((m, w))
        return out

    return make


def _jumps(move, kinds) -> dict:
    """The jump's counts on the kept chain (the burn-in resets them), per pair of kinds."""
    V, A = move.valid, move.accepted_pairs
    opt = [i for i, k in enumerate(kinds) if k == "optimum"]
    lim = [i for i, k in enumerate(kinds) if k != "optimum"]
    k2 = [i for i, k in enumerate(kinds) if k == "limit:k2"]

    def between(M, a, b):
        return int(M[np.ix_(a, b)].sum()) if a and b else 0

    return {"proposed": int(move.proposed), "passed_check": int(V.sum()),
            "accepted": int(A.sum()),
            "accepted_optimum_to_limit": between(A, opt, lim),
            "accepted_limit_to_optimum": between(A, lim, opt),
            "accepted_optimum_to_k2": between(A, opt, k2),
            "accepted_k2_to_optimum": between(A, k2, opt),
            "accepted_optimum_to_optimum": between(A, opt, opt),
            "accepted_limit_to_limit": between(A, lim, lim),
            "region": dict(move.region), "kinds": list(kinds), "passed_matrix": V.tolist(), "accepted_matrix": A.tolist()}


def run(fit, prior, variant: str, seed: int, max_steps: int, log: str) -> dict:
    keep: list = []
    moves = None
    if variant == "default_t":
        moves = _default_tracked(fit, keep)
    if variant.startswith("jump"):
        import importlib

        try:
            importlib.import_module("hdid._posterior.jump")
        except ImportError:
            raise SystemExit("the jump variants need src/hdid/_posterior/jump.py, retired "
                             "from the library (benchmarks/README.md, post11): run this "
                             "script on the tree of commit 24ba95c") from None
        tag, w = variant.split(":")
        comps = mode_components(fit, prior, seed) if tag == "jumpm" else None
        moves = _factory(fit, float(w), tag == "jump_w", keep, comps)
    kw = {}
    if variant.startswith("walkers:"):  # the default moves, W walkers at the same cost
        W = int(variant.split(":")[1])
        kw["n_walkers"], max_steps = W, max_steps * 36 // W
    la0 = _load()
    post = hdid.sample_posterior(fit, seed=seed, max_steps=max_steps, progress=False,
                                 moves=moves, prior=prior, **kw)
    la1 = _load()
    d = post.to_dict()
    diag = d["posterior_diagnostics"]
    conv = diag["convergence"] or {}
    per = conv.get("per_quantity") or {}
    tc = np.exp(post.chain[..., post.labels.index("tau_c")])
    k2 = np.exp(post.chain[..., post.labels.index("k2")])
    tau = dict(diag["tau"])
    kinds = [m["kind"] for m in diag["modes"]]
    rhat = {k: v["rhat"] for k, v in per.items()}
    return {
        "log": log, "variant": variant, "seed": seed, "max_steps": max_steps,
        "date_utc": _dt.datetime.now(_dt.timezone.utc).isoformat(timespec="seconds"),
        "src": _common.src_fingerprint(), "load_start": la0, "load_end": la1,
        "tau_c_ci95": d["posterior"]["tau_c"]["ci95"], "band_ci95": d["posterior"][BAND]["ci95"],
        "k2_ci95": d["posterior"]["k2"]["ci95"],
        "share_tau_c_below_1mNm": float(np.mean(tc < 1e-3)),
        "share_k2_below_0.1_fit": float(np.mean(k2 < 0.1 * fit.values["k2"])),
        "converged": diag["converged"], "rhat_max": conv.get("rhat_max"),
        "rhat_max_of": max(rhat, key=lambda k: rhat[k]) if rhat else None,
        "ess_bulk_min": conv.get("ess_bulk_min"), "ess_tail_min": conv.get("ess_tail_min"),
        "rhat": rhat, "tau_max": diag["tau_max"], "tau_max_of": max(tau, key=lambda k: tau[k]),
        "steps": diag["n_steps"], "n_components": len(kinds),
        "move_acceptance": diag["move_acceptance"], "wall_s": diag["wall_time_s"],
        "stage_s": diag["stage_s"], "warnings": diag["warnings"],
        "jump": _jumps(keep[0], kinds) if keep and variant.startswith("jump") else None,
        "independence_regions": dict(keep[0].region) if variant == "default_t" else None,
        "jump_components": (None if not keep or getattr(keep[0], "components", None) is None
                            else keep[0].components.tolist()),
        "modes": [{"kind": m["kind"], "weight": m["weight"], "cost": m["cost"],
                   "share": m.get("share_of_draws")} for m in diag["modes"]],
    }


def affine_check(fit, prior, seed: int, n_steps: int, n_draws: int = 720) -> dict:
    """Why the jumps are rarely accepted: a default chain of ``n_steps``; its draws split
    into the k2 → 0 region, the tau_c < 1 mN m region and the rest (bulk); per region the
    mean and sd against the driver's final mixture component (the k2 limit fit's end,
    the tau_c limit fit's end, the fit's optimum); then the mean acceptance
    ``E min(1, π(x') |det A| / π(x))`` of the affine jump of ``n_draws`` bulk draws into
    each region, with the mixture's components and with Gaussians fitted to the regions'
    own draws (the best an affine jump between two Gaussians could do)."""
    from hdid._posterior.moves import default_moves

    keep = {}

    def fac(lp, proposal):
        keep["lp"], keep["prop"] = lp, proposal
        return default_moves(proposal)

    la0 = _load()
    post = hdid.sample_posterior(fit, seed=seed, n_steps=n_steps, progress=False, moves=fac,
                                 prior=prior)
    lp, mix = keep["lp"], keep["prop"].mix
    kinds = [m.kind for m in post.modes]
    ends = {"k2": next(i for i, m in enumerate(post.modes)
                       if m.kind == "limit:k2" and m.limit is not None),
            "tau_c": next(i for i, m in enumerate(post.modes)
                          if m.kind == "limit:tau_c" and m.limit is not None),
            "bulk": 0}
    U = post.chain.reshape(-1, post.chain.shape[-1])
    X = lp.to_sampled_np(U)
    k2r = np.exp(U[:, post.labels.index("k2")]) < 0.1 * fit.values["k2"]
    tcr = np.exp(U[:, post.labels.index("tau_c")]) < 1e-3
    regions = {"k2": k2r, "tau_c": tcr, "bulk": ~(k2r | tcr)}
    rng = np.random.default_rng(0)
    bulk = X[regions["bulk"]][rng.choice(int(regions["bulk"].sum()), n_draws)]
    W = post.chain.shape[1]

    def acceptance(mu_i, L_i, mu_j, L_j):
        Z = np.linalg.solve(L_i, (bulk - mu_i).T).T
        Xn = mu_j + Z @ L_j.T
        ld = float(np.sum(np.log(np.diag(L_j))) - np.sum(np.log(np.diag(L_i))))
        d = np.concatenate([np.asarray(lp.batch(Xn[a:a + W])) - np.asarray(lp.batch(bulk[a:a + W]))
                            for a in range(0, len(bulk), W)]) + ld
        return float(np.mean(np.exp(np.minimum(0.0, np.where(np.isfinite(d), d, -np.inf))))), ld

    out = {"variant": "affine-check", "log": "shipped", "seed": seed, "n_steps": n_steps,
           "src": _common.src_fingerprint(), "load_start": la0, "kinds": kinds,
           "labels": post.labels, "regions": {}}
    emp = {}
    for name, r in regions.items():
        Xr = X[r]
        k = ends[name]
        row = {"share": float(r.mean()), "component": k,
               "component_weight": float(mix.weights[k])}
        if r.sum() > 2 * X.shape[1]:
            m, sd = Xr.mean(axis=0), Xr.std(axis=0)
            row["mean_offset_in_sd"] = ((m - mix.means[k]) / sd).tolist()
            row["component_sd_over_draws_sd"] = (np.sqrt(np.diag(mix.covs[k])) / sd).tolist()
            emp[name] = (m, np.linalg.cholesky(np.cov(Xr.T) + 1e-12 * np.eye(X.shape[1])))
        out["regions"][name] = row
    for name in ("k2", "tau_c"):
        a, ld = acceptance(mix.means[0], mix.chols[0], mix.means[ends[name]], mix.chols[ends[name]])
        out["regions"][name]["jump_acceptance_mixture"] = a
        out["regions"][name]["log_det_mixture"] = ld
        if name in emp and "bulk" in emp:
            a, ld = acceptance(*emp["bulk"], *emp[name])
            out["regions"][name]["jump_acceptance_fitted_gaussians"] = a
            out["regions"][name]["log_det_fitted_gaussians"] = ld
    out["load_end"] = _load()
    return out


def render(records: list[dict]) -> str:
    head = _common.md_head(
        ["log", "variant", "seed", "steps", "R-hat max (of)", "ESS bulk/tail min",
         "τ_max (of)", "share tau_c < 1 mN m", "share k2 → 0", "band 95 % [mrad]",
         "acc. indep. / jump", "jumps passed/proposed / accepted / into, out of k2 → 0 / into, out of tau_c < 1 mN m",
         "wall s", "load start→end"])
    rows, checks = [], []
    for r in records:
        if r["variant"] == "affine-check":
            checks.append(r)
            continue
        c = _common.chain_cells(r, share_digits=3)
        acc = r["move_acceptance"].get("independence (mixture)", float("nan"))
        jac = r["move_acceptance"].get("Tracked", float("nan"))
        j = r.get("jump")
        g = (j or {}).get("region", {})
        jc = "—" if not j else (
            f"{j['passed_check']}/{j['proposed']} / {j['accepted']} / "
            f"{g['k2_in']}, {g['k2_out']} / {g['tau_c_in']}, {g['tau_c_out']}")
        rows.append(
            f"| {r['log']} | {r['variant']} | {r['seed']} | {r['steps']} | "
            f"{c['rhat']} ({r['rhat_max_of']}) | {c['ess']} | {c['tau']} | {c['share']} | "
            f"{r['share_k2_below_0.1_fit']:.3f} | {c['band']} | {acc:.3f} / {jac:.3f} | {jc} "
            f"| {c['wall']} | {c['load']} |")
    return ("# The affine mode-jump move against the default moves (issue 17, post11)\n\n"
            "Written by `benchmarks/posterior_jump_post11.py`; one core (`taskset -c 0`), one "
            "fit per process, variants alternating, the other core busy. Shares: kept chain, "
            "every step and walker. Jump counts: kept chain (the burn-in resets them); "
            "'passed' = proposals whose image the assignment gives to the target component; "
            "into/out of: accepted jumps that moved a walker into or out of the region "
            "(k2 < 0.1 × the fit's; tau_c < 1 mN m). Per pair of components: the JSON."
            "\n\n" + head + "\n".join(rows) + "\n" + "".join(_render_check(r) for r in checks))


def _render_check(r: dict) -> str:
    lines = [f"\n## Affine jumps from the bulk: the best case (`--affine-check`, seed {r['seed']}, "
             f"{r['n_steps']} default steps, load {r['load_start'][0]}→{r['load_end'][0]})\n",
             "| region | share | jump acceptance, mixture components (log det) | "
             "jump acceptance, Gaussians fitted to the region's draws (log det) |",
             "|---|---|---|---|"]
    for name in ("k2", "tau_c"):
        g = r["regions"][name]
        fg = (f"{g['jump_acceptance_fitted_gaussians']:.2e} ({g['log_det_fitted_gaussians']:+.1f})"
              if "jump_acceptance_fitted_gaussians" in g else "—")
        lines.append(f"| {name} | {g['share']:.3f} | {g['jump_acceptance_mixture']:.2e} "
                     f"({g['log_det_mixture']:+.1f}) | {fg} |")
    return "\n".join(lines) + "\n"


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--log", default="shipped")
    ap.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    ap.add_argument("--max-steps", type=int, default=10000)
    ap.add_argument("--variants", nargs="+", default=["default", "jump:0.1"])
    ap.add_argument("--render", action="store_true")
    ap.add_argument("--affine-check", type=int, metavar="STEPS",
                    help="run affine_check (first seed, STEPS default steps) instead")
    a = ap.parse_args(argv)
    path = RESULTS / f"{NAME}.json"
    records = json.loads(path.read_text()) if path.exists() else []
    if a.render:
        (RESULTS / f"{NAME}.md").write_text(render(records))
        return 0
    from posterior_nautilus import make_log

    fit, prior, _ = make_log(a.log)
    if a.affine_check:
        rec = affine_check(fit, prior, a.seeds[0], a.affine_check)
        records.append(rec)
        path.write_text(json.dumps(records, indent=1) + "\n")
        (RESULTS / f"{NAME}.md").write_text(render(records))
        print(json.dumps(rec["regions"], indent=1))
        return 0
    for i, seed in enumerate(a.seeds):
        order = a.variants if i % 2 == 0 else a.variants[::-1]
        for v in order:
            rec = run(fit, prior, v, seed, a.max_steps, a.log)
            records.append(rec)
            path.write_text(json.dumps(records, indent=1) + "\n")
            (RESULTS / f"{NAME}.md").write_text(render(records))
            print({k: rec[k] for k in ("log", "variant", "seed", "rhat_max", "rhat_max_of",
                                       "tau_max", "ess_bulk_min", "share_tau_c_below_1mNm",
                                       "share_k2_below_0.1_fit", "wall_s", "load_start",
                                       "load_end")},
                  {k: v for k, v in (rec["jump"] or {}).items() if "matrix" not in k},
                  flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
