"""The optimum inside the prior's support when the fit's own lies outside it.

The posterior gives zero density where an order an effect declares is broken
(``tau_s ≥ tau_c``: breakaway at least the sliding friction; :func:`~.density.ordered_pairs`).
Least squares knows no such order, and a fit may end on the other side: on the SBC's paper
log 36009 ``hdid.fit``'s Coulomb-limit restart ended on an inverted Stribeck law (tau_s 1.11 <
tau_c 3.67 mN m, c_v 4e-10: friction rising with speed stands in for the viscous loss). The
fit's optimum, merely moved just inside, was no optimum: every emcee walker stranded in the
burn-in and the chain ended 8770 in log p above it.

:func:`inside_optimum` refits inside the support, with the fit's own Levenberg–Marquardt
program on the cost the mode search weighs optima by (data χ² plus the sampled priors' rows):

- starts: the fit's optimum projected on each broken pair's boundary (either member moved to
  the other's value), and, for a Stribeck pair with ``v_s`` free, the *Coulomb limit*:
  ``v_s`` held at ``COULOMB_V_S`` × the log's peak speed by a strong prior row (the Stribeck
  factor is then 1 at every logged speed: friction is ``tau_s`` sliding and holding), from the
  fit's levels and ``c_v`` at the fit's and at its prior's centre (out of a ``c_v → 0``
  corner);
- each end is put on the boundary (the pair equal to ``BOUNDARY_GAP``: the Stribeck term
  ``(tau_s − tau_c)·exp(…)`` vanishes, and ``v_s``, ``delta`` act on nothing: they are set to
  their prior's centre) — the constrained optimum when the data want the law inverted — and
  also released: full-model refits from Stribeck shapes just off that boundary, kept where
  they end inside (an interior optimum).

The lowest cost inside wins; with ``modes="auto"`` the mode search then restarts around it
(:func:`~.modes.sampled_modes`): on SBC paper log 36009 (``--noise none``) that reached cost
60.7 (data χ² 55.7 against the inverted fit's 85.2; tau_c 0.92 mN m, truth 0.94), the local
optimum started from the truth, where the point moved inside had log p −192 against 470. The result names the broken order and both χ² in one line
(the sampler's warnings); if nothing inside has a finite cost, one line says so before any
sampling (as the WRONG BASIN statement does).
"""

from __future__ import annotations

import numpy as np

#: log gap ``u_j − u_i`` of a pair put on its boundary (``tau_s = tau_c·(1 + 1e-6)``): on
#: the allowed side after the sampled coordinates' exp/log round trip, and a Stribeck rise of
#: 1e-6 × the sliding level — nothing the readings see.
BOUNDARY_GAP = 1e-6
#: Stribeck shapes of the released refits: ``v_s`` as a fraction of the peak speed and
#: ``delta`` (as ``_fitting._limits.COULOMB_RESTART_SHAPES``), with ``tau_s`` at
#: ``RELEASE_RISE`` × ``tau_c``.
RELEASE_SHAPES = tuple((f, d) for f in (0.01, 0.05, 0.15, 0.4) for d in (1.0, 2.5))
RELEASE_RISE = 1.5
#: Levenberg–Marquardt steps at most per refit (the mode search's own budget).
MAX_STEPS = 150


def broken_pairs(problem, u) -> list[tuple[int, int]]:
    """The ordered pairs ``(i, j)`` (``u_i ≤ u_j`` imposed) that ``u`` breaks."""
    from .density import ordered_pairs

    pairs = ordered_pairs(problem)
    u = np.asarray(u, dtype=float)
    return [] if pairs is None else [(int(i), int(j)) for i, j in pairs if u[j] < u[i]]


def in_support(pairs, u) -> bool:
    """Whether ``u`` keeps every order of ``pairs`` (``None``: no order)."""
    return pairs is None or bool(np.all(np.asarray(u)[pairs[:, 1]] >= np.asarray(u)[pairs[:, 0]]))


def _local(problem, U0, max_steps: int = MAX_STEPS):
    """Local LM refits of every row of ``U0`` (the mode search's loop): ``(U, costs)``."""
    from .._fitting._lm import PHASE1_STEPS, PHASE2_CHUNK
    from .lanes import _solve_in_lanes, solve_fresh

    U0 = np.atleast_2d(np.asarray(U0, dtype=float))
    U, costs, ok = _solve_in_lanes(solve_fresh, problem, U0, np.ones(len(U0), dtype=bool),
                                   PHASE1_STEPS)
    used = PHASE1_STEPS
    while used < max_steps:
        act = ~ok & np.isfinite(costs)
        if not act.any():
            break
        U2, c2, d2 = _solve_in_lanes(solve_fresh, problem, U, act, PHASE2_CHUNK)
        U[act], costs[act], ok[act] = U2[act], c2[act], d2[act]
        used += PHASE2_CHUNK
    return U, np.where(np.isfinite(costs), costs, np.inf)


def _costs(problem, U):
    """The cost of every row of ``U``: the LM program with no iteration (its start's)."""
    from .lanes import _solve_in_lanes, solve_fresh

    U = np.atleast_2d(np.asarray(U, dtype=float))
    c = _solve_in_lanes(solve_fresh, problem, U, np.ones(len(U), dtype=bool), 0)[1]
    return np.where(np.isfinite(c), c, np.inf)


def _on_boundary(U, broken, centres):
    """Rows of ``U`` with each broken pair put on its boundary (``u_j = u_i + gap`` where
    ``u_j < u_i``) and the parameters in ``centres`` (index → value) set there."""
    U = np.array(U, dtype=float, ndmin=2)
    for i, j in broken:
        low = U[:, j] < U[:, i] + BOUNDARY_GAP
        for k, c in centres.items():
            U[low, k] = c
        U[low, j] = U[low, i] + BOUNDARY_GAP
    return U


def _starts(fit, problem, broken, centre):
    """``(starts of the plain refits, starts of the Coulomb-limit fit, pinned problem)``."""
    from .._fitting._unknowns import pinned
    from .priors import prior_scales

    u = np.asarray(fit.u, dtype=float)
    free = list(problem.free)
    plain = []
    for i, j in broken:
        a, b = u.copy(), u.copy()
        a[j] = a[i] + BOUNDARY_GAP          # the upper member raised to the lower
        b[i] = b[j] - BOUNDARY_GAP          # the lower member lowered to the upper
        plain += [a, b]
    coul, pin = [], None
    stribeck = any(free[i] == "tau_c" and free[j] == "tau_s" for i, j in broken)
    if stribeck and "v_s" in free:
        speed = float(prior_scales(problem).speed)
        pin = pinned(problem, problem.base, {"v_s": 1e3 * speed})  # COULOMB_V_S
        i, j, s = free.index("tau_c"), free.index("tau_s"), free.index("v_s")
        for level in (u[i], u[j], 0.5 * (u[i] + u[j])):
            for c_v in ((None,) + ((centre.get(free.index("c_v")),) if "c_v" in free else ())):
                row = u.copy()
                row[j], row[i] = level, level - np.log(1.02)
                row[s] = np.asarray(pin.prior_mean)[s]
                if c_v is not None:
                    row[free.index("c_v")] = c_v
                coul.append(row)
    return plain, coul, pin


def inside_optimum(fit, view, gauss_prior=None):
    """``(u, cost, note)``: the best point inside the prior's support found by refitting
    (module docstring) on ``view.problem`` (the fit's problem with the sampled priors'
    rows), its cost there, and the one-line warning; ``(None, inf, statement)`` when no
    point inside has a finite cost. ``None`` when the fit's optimum breaks no order."""
    from .density import ordered_pairs

    prob = view.problem
    u_fit = np.asarray(fit.u, dtype=float)
    broken = broken_pairs(prob, u_fit)
    if not broken:
        return None
    free = list(prob.free)
    pairs = ordered_pairs(prob)
    centre = {}
    if gauss_prior is not None:
        G = np.asarray(gauss_prior, dtype=float)
        centre = {k: float(G[0, k]) for k in range(G.shape[1]) if G[2, k] > 0}
    # v_s and delta act on nothing on a Stribeck boundary: their prior's centre there
    flat_there = {k: centre[k] for k in centre if free[k] in ("v_s", "delta")}
    plain, coul, pin = _starts(fit, prob, broken, centre)
    cands = [_on_boundary(np.array(plain), broken, {})]
    U, _ = _local(prob, np.array(plain))
    cands.append(U)
    if coul:
        Uc, _ = _local(pin, np.array(coul))
        # a Coulomb end slides at tau_s: tau_c put there too (the same law, on the boundary)
        edge = np.array(Uc)
        i, j = free.index("tau_c"), free.index("tau_s")
        edge[:, i] = edge[:, j] - BOUNDARY_GAP
        for m, c in flat_there.items():
            edge[:, m] = c
        cands.append(edge)
        # released: the full model from Stribeck shapes just off the Coulomb boundary
        speed_rows = []
        from .priors import prior_scales
        from .._models._transforms import to_unconstrained

        specs = prob.base.parameter_specs()
        speed = float(prior_scales(prob).speed)
        best_edge = edge[int(np.argmin(_costs(prob, edge)))]
        for f, d in RELEASE_SHAPES:
            row = best_edge.copy()
            row[j] = row[i] + np.log(RELEASE_RISE)
            row[free.index("v_s")] = float(to_unconstrained(specs["v_s"], f * speed))
            if "delta" in free:
                row[free.index("delta")] = float(to_unconstrained(specs["delta"], d))
            speed_rows.append(row)
        Ur, _ = _local(prob, np.array(speed_rows))
        cands.append(Ur)
    C = np.concatenate(cands)
    costs = _costs(prob, C)
    ok = np.array([in_support(pairs, c) for c in C]) & np.isfinite(costs)
    names = ", ".join(f"{free[j]} ≥ {free[i]}" for i, j in broken)
    vals = fit.problem.values_np(u_fit)
    shown = ", ".join(f"{free[k]} {vals[free[k]]:.3g}" for i, j in broken for k in (j, i))
    if not ok.any():
        return None, np.inf, (
            f"NO OPTIMUM INSIDE THE PRIOR: the fit's optimum violates the prior's constraint "
            f"{names} ({shown}), where the posterior's density is zero, and no refit inside "
            "that constraint (from the optimum put on the boundary, or the Coulomb limit) "
            "reached a finite density, so the intervals would describe a point that is no "
            "optimum — refit from other starts (--start; start_from_model=True) or give the "
            "parameters a prior of your own (--prior), then sample again")
    k = int(np.flatnonzero(ok)[np.argmin(costs[ok])])
    return C[k], float(costs[k]), constrained_note(fit, prob, C[k], float(costs[k]))


def constrained_note(fit, problem, u_in, cost_in: float) -> str:
    """The one line that says the fit's optimum broke an order and which optimum inside
    it was sampled around (``u_in``, its ``cost_in`` on ``problem``), with both data χ²."""
    from .._fitting._unknowns import data_chi2

    free = list(problem.free)
    u_fit = np.asarray(fit.u, dtype=float)
    broken = broken_pairs(problem, u_fit)
    names = ", ".join(f"{free[j]} ≥ {free[i]}" for i, j in broken)
    vals, v_in = problem.values_np(u_fit), problem.values_np(u_in)
    shown = ", ".join(f"{free[k]} {vals[free[k]]:.3g}" for i, j in broken for k in (j, i))
    now = ", ".join(f"{free[k]} {v_in[free[k]]:.3g}" for i, j in broken for k in (j, i))
    chi2_fit = data_chi2(problem, u_fit, float(_costs(problem, u_fit)[0]))
    return (f"CONSTRAINED OPTIMUM: the fit's optimum violates the prior's constraint {names} "
            f"({shown}), where the posterior's density is zero; sampled around the constrained "
            f"optimum refitted inside it ({now}), chi2 {data_chi2(problem, u_in, cost_in):.4g} "
            f"vs {chi2_fit:.4g} at the fit's optimum")
