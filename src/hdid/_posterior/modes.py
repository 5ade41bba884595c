"""Local optima of the least-squares cost near the fit, and their Laplace masses."""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np

from .._problems._problem import Problem
from .density import PRIOR_HALF_WIDTH
from .lanes import MODE_LANES, _solve_in_lanes, solve_fresh  # noqa: F401 (re-exported)
from .optima import (  # noqa: F401 (re-exported: the optima's record and its Laplace mass)
    _BOX_PRECISION, MODE_BARRIER, Mode, _laplace, _Moved, _path_costs, _PriorFit, _rj,
    _same_optimum)

#: Local optima more than this far above the best (χ² in the fit's q/√12 units) carry
#: a posterior mass ``exp(−Δχ²/2) < 1e-13`` of the best one's: ignored.
MODE_DCHI2_MAX = 60.0


def _restart_candidates(fit, rng, n_random: int) -> np.ndarray:
    """Starting vectors around ``fit``: the fit's own starts, Stribeck-shape variants, a
    k1 shift of ±2 sd, and draws from the widened Laplace approximation."""
    prob: Problem = fit.problem
    u0 = np.asarray(fit.u, dtype=float)
    free = list(prob.free)
    specs = prob.base.parameter_specs()
    from .._models._transforms import to_unconstrained

    def with_values(vals):
        u = u0.copy()
        for n, v in vals.items():
            if n in free and np.isfinite(v) and v > 0:
                u[free.index(n)] = float(to_unconstrained(specs[n], v))
        return u

    cands = [u0]
    st = fit.starts
    for i in range(len(st.costs)):
        if np.isfinite(st.costs[i]) and st.costs[i] - st.costs[st.best] < 1e3 and i != st.best:
            cands.append(with_values({n: float(v[i]) for n, v in st.values.items()}))
    vals = fit.values
    for fs, fv, fk in ((1.6, 0.2, 1.0), (1.6, 0.2, 0.1), (1.6, 1.0, 1.0), (0.75, 4.0, 1.0),
                       (1.0, 4.0, 1.5), (1.0, 0.2, 1.0), (1.3, 0.5, 0.3)):
        v = {}
        if "tau_s" in vals and "tau_c" in vals:
            v["tau_s"] = max(fs * vals["tau_s"], 1.05 * vals["tau_c"])
        if "v_s" in vals:
            v["v_s"] = fv * vals["v_s"]
        if "k2" in vals:
            v["k2"] = fk * vals["k2"]
        cands.append(with_values(v))
    if "k1" in free:
        j = free.index("k1")
        sd = math.sqrt(max(float(fit.covariance[j, j]), 0.0))
        if np.isfinite(sd) and sd > 0:
            for t in (-2.0, 2.0):
                u = u0.copy()
                u[j] += t * sd
                cands.append(u)
    if n_random:
        _, cov, _ = _laplace(prob, u0)
        P = prob.n_physical
        L = np.linalg.cholesky(cov + 1e-12 * np.eye(cov.shape[0]))
        z = rng.standard_normal((n_random, u0.size))
        U = u0 + 1.5 * z @ L.T
        U[:, P:] = u0[P:]  # nuisances stay; the physical part explores
        lim = u0[:P] + np.clip(U[:, :P] - u0[:P], -3.0, 3.0)
        U[:, :P] = lim
        cands += list(U)
    return np.array(cands)


#: Restarts drawn from the widened Laplace approximation in :func:`find_modes`: 30 found
#: more optima but not more coverage (14 paper logs: 86 % vs 84 %), ≈ 8 s more a call
#: (docs/decisions/mode-search-starts.md).
N_RANDOM_RESTARTS = 6


def find_modes(fit, *, n_random: int = N_RANDOM_RESTARTS, seed: int = 0, max_steps: int = 150,
               dchi2_max: float = MODE_DCHI2_MAX, extra_starts=None) -> list[Mode]:
    """Distinct local optima of the fit's cost near ``fit`` and their Laplace masses.

    Local Levenberg–Marquardt fits (hdid's own, vmapped) are started from the fit's
    optimum, the other starts of the fit's multi-start, Stribeck-shape variants (static
    friction ×0.75–1.6, Stribeck velocity ×0.2–4, k2 ×0.1–1.5), k1 ± 2 sd and
    ``n_random`` draws from the widened Laplace approximation. Optima within
    ``dchi2_max`` of the best are merged when a straight path between them rises less
    than ``MODE_BARRIER``, and each remaining one is weighted by its Laplace evidence.
    Sorted by weight, largest first.
    """
    from .._fitting._lm import PHASE1_STEPS, PHASE2_CHUNK

    prob: Problem = fit.problem
    rng = np.random.default_rng(seed)
    U0 = _restart_candidates(fit, rng, n_random)
    if extra_starts is not None:
        U0 = np.concatenate([U0, np.atleast_2d(np.asarray(extra_starts, dtype=float))])
    U, costs, ok = _solve_in_lanes(solve_fresh, prob, U0, np.ones(len(U0), dtype=bool),
                                   PHASE1_STEPS)
    costs[~np.isfinite(costs)] = np.inf
    active = (costs - np.min(costs) < 10 * dchi2_max) & ~ok
    used = PHASE1_STEPS
    while active.any() and used < max_steps:
        U2, c2, d2 = _solve_in_lanes(solve_fresh, prob, U, active, PHASE2_CHUNK)
        U[active], costs[active] = U2[active], np.where(np.isfinite(c2[active]), c2[active], np.inf)
        used += PHASE2_CHUNK
        active = active & ~d2 & (costs - np.min(costs) < dchi2_max)
    # the fit's own optimum is always a candidate at its own cost
    keep = np.flatnonzero(costs - np.min(costs) < dchi2_max)
    keep = keep[np.argsort(costs[keep])]
    modes: list[Mode] = []
    for i in keep:
        u = U[i]
        cost, cov, logz = _laplace(prob, u)
        merged = False
        for m in modes:
            path = m.u + np.linspace(0.0, 1.0, 9)[:, None] * (u - m.u)
            pc = np.asarray(_path_costs(prob, path))
            if np.all(np.isfinite(pc)) and np.max(pc) - max(cost, m.cost) < MODE_BARRIER:
                merged = True
                break
        if not merged:
            modes.append(Mode(u=u, cost=cost, cov=cov, log_evidence=logz,
                              values=prob.values_np(u)))
    lz = np.array([m.log_evidence for m in modes])
    w = np.exp(lz - lz.max())
    w /= w.sum()
    for m, wi in zip(modes, w):
        m.weight = float(wi)
    return sorted(modes, key=lambda m: -m.weight)


def _fit_mode(fit) -> Mode:
    """The fit's own optimum as the only mode (``modes="fit"``)."""
    cost, cov, logz = _laplace(fit.problem, np.asarray(fit.u, dtype=float))
    # a writable copy (``fit.u`` may be a JAX array: its NumPy view is read-only, and
    # :func:`sampled_modes` moves an out-of-order start inside the order in place)
    return Mode(u=np.array(fit.u, dtype=float), cost=cost, cov=cov, log_evidence=logz,
                weight=1.0, values=fit.problem.values_np(fit.u))


#: Starts drawn from a user prior for the mode search (besides its centre): on paper log
#: 7203 with the catalog prior the search from the fit's neighbourhood missed an optimum
#: near the truth that holds 28 % of the posterior (docs/decisions/mode-search-starts.md).
N_PRIOR_STARTS = 8


def with_user_prior(fit, gauss_prior, seed: int = 0, n_prior_draws: int = N_PRIOR_STARTS):
    """``(fit or a view of it, extra starts)``: with Gaussian priors ``(3, P)`` (mean, sd,
    on in the transformed space; :func:`~hdid._posterior.density.gaussian_prior`) the
    problem's prior rows become those priors where they are on, and — for the user's own
    (on = 2) — the fit's optimum with those parameters at the prior's centre, and at
    ``n_prior_draws`` draws from it, are more starts."""
    if gauss_prior is None:
        return fit, None
    import equinox as eqx

    G = np.asarray(gauss_prior, dtype=float)
    on = G[2] > 0
    prob = fit.problem
    mean = np.where(on, G[0], np.asarray(prob.prior_mean, dtype=float))
    sd = np.where(on, G[1], np.asarray(prob.prior_sd, dtype=float))
    on_all = on | np.asarray(prob.prior_on, dtype=bool)
    prob2 = eqx.tree_at(lambda p: (p.prior_mean, p.prior_sd, p.prior_on), prob,
                        (jnp.asarray(mean), jnp.asarray(sd), jnp.asarray(on_all)))
    # more starts only from the user's priors (on = 2): the defaults (on = 1) are wide
    # (a factor 10 either way) and the fit's optimum already lies well inside them
    user = G[2] > 1.5
    if not user.any():
        return _PriorFit(fit, prob2), None
    u0 = np.asarray(fit.u, dtype=float).copy()
    u0[: len(on)] = np.where(user, G[0], u0[: len(on)])
    starts = np.tile(u0, (1 + n_prior_draws, 1))
    z = np.random.default_rng(seed).standard_normal((n_prior_draws, len(on)))
    starts[1:, : len(on)] = np.where(user, G[0] + G[1] * z, u0[: len(on)])
    return _PriorFit(fit, prob2), starts


def seek_limits(fit, lin, best_cost: float, dchi2_max: float = MODE_DCHI2_MAX) -> list[Mode]:
    """The limit fits (:mod:`.limits`) of the parameters ``lin`` marks (prior flat in
    value), and their continuation's first point, whose least-squares cost is within
    ``dchi2_max`` of the best, as optima of ``kind="limit:NAME"`` (the end carrying its
    :class:`~hdid._posterior.limits.LimitFit`; never merged: the plateau they stand for is
    one ridge with the fit's optimum)."""
    from .limits import limit_fits, limit_names

    prob: Problem = fit.problem
    out = []
    names = limit_names(prob, lin, getattr(fit, "covariance", None))
    for lim in limit_fits(fit, names, best_cost, MODE_LANES, dchi2_max):
        # the end, and the continuation's first point (half-way down the ridge in value)
        for u, c, end in [(lim.u, lim.dchi2_lsq, lim)] + [(u, c, None) for u, c in lim.path[:1]]:
            if c < dchi2_max:
                cost, cov, logz = _laplace(prob, u)
                out.append(Mode(u=u, cost=cost, cov=cov, log_evidence=logz,
                                values=prob.values_np(u), kind=f"limit:{lim.name}", limit=end))
    return out


def ridge_names(problem, lin, covariance=None) -> list[str]:
    """Free log-transformed parameters declared ``flat_in_value`` (the coefficient of a
    term that may vanish: ``k2``, ``tau_c``, ``c_v``) whose prior as sampled is *not* flat
    in value (``lin`` 0: the weak default or a user's Gaussian), screened as
    :func:`~hdid._posterior.limits.limit_names` screens (relative sd ≥ 0.2)."""
    from .limits import limit_names

    specs = problem.base.parameter_specs()
    mask = np.array([1.0 if (getattr(specs[n], "flat_in_value", False)
                             and specs[n].transform == "log" and not lin[i] > 0) else 0.0
                     for i, n in enumerate(problem.free)])
    return limit_names(problem, mask, covariance) if mask.any() else []


#: Ridge points kept as starts: within this of the best optimum in −2 log p (χ²₂'s 99 %
#: point). All 15 within MODE_DCHI2_MAX took half the walkers on the shipped paper log,
#: and its SMC no longer converged.
RIDGE_DCHI2 = 9.21
#: The samplers given the ridge starts: SMC reweights them away if of little mass; emcee's
#: walkers started down the Coulomb ridge stall there (shipped paper log: R-hat 1.058 → 1.116).
RIDGE_SAMPLERS = ("smc",)
#: Share of the walkers, of SMC's reference and of the independence proposal that the
#: ridge points hold together at most: their Laplace weights (at points that are not
#: optima) are not their mass; they are starts, and the samplers weigh them.
RIDGE_SHARE = 0.1


def seek_ridges(fit, lin, best_cost: float) -> list[Mode]:
    """Starts down the ridge on which a vanishing term trades off against the others
    (Coulomb against viscous friction and the Stribeck shape: ``tau_c`` down, ``c_v``,
    ``v_s`` up, ``delta`` down), for the parameters :func:`ridge_names` gives: the points
    of the limit continuation (:func:`~hdid._posterior.limits.limit_fits`, the parameter
    held at ``exp(−s)`` of its least-squares value, the rest refitted) whose cost under
    the sampled priors is within ``RIDGE_DCHI2`` of the best, as ``kind="ridge:NAME"``
    (never merged, no limit warning: the prior is not flat in value; together at most
    ``RIDGE_SHARE`` of the weight, :func:`sampled_modes`); a point more than
    ``MODE_BARRIER`` *below* the best is a better basin: refitted from there, it is an
    optimum.

    Under the weak log-normal priors (issue 34) the limit fits were no longer sought, and
    the optima of the mode search all lay on the fit's side of the ridge.
    """
    from .._fitting._lm import PHASE1_STEPS, PHASE2_CHUNK
    from .basin import BASIN_FACTOR, rms_over_floor
    from .limits import limit_fits

    prob: Problem = fit.problem
    # above the floor (a poorer basin suspected) every continuation is a cheap restart: on
    # SBC log 36001 (2.3× the floor) the tau_c one reached a cost 350 lower than the optima
    # of the mode search, where the screen (tau_c measured to < 20 %) had skipped it
    at_floor = rms_over_floor(fit) <= BASIN_FACTOR
    names = ridge_names(prob, lin, getattr(fit, "covariance", None) if at_floor else None)
    out, better = [], []
    for lim in limit_fits(fit, names, best_cost, MODE_LANES, RIDGE_DCHI2):
        for u, c in lim.path + [(lim.u, lim.dchi2_lsq)]:
            if c < -MODE_BARRIER:
                better.append(u)
            elif c < RIDGE_DCHI2:
                cost, cov, logz = _laplace(prob, u)
                out.append(Mode(u=u, cost=cost, cov=cov, log_evidence=logz,
                                values=prob.values_np(u), kind=f"ridge:{lim.name}"))
    if better:
        U, costs, ok = _solve_in_lanes(solve_fresh, prob, np.array(better),
                                       np.ones(len(better), dtype=bool), PHASE1_STEPS)
        for _ in range(8):
            act = ~ok & np.isfinite(costs)
            if not act.any():
                break
            U2, c2, d2 = _solve_in_lanes(solve_fresh, prob, U, act, PHASE2_CHUNK)
            U[act], costs[act], ok[act] = U2[act], c2[act], d2[act]
        if np.isfinite(costs).any():
            i = int(np.nanargmin(np.where(np.isfinite(costs), costs, np.nan)))
            cost, cov, logz = _laplace(prob, U[i])
            out.append(Mode(u=U[i], cost=cost, cov=cov, log_evidence=logz,
                            values=prob.values_np(U[i])))
    return out


def found_limits(fit, found, modes, lin, gauss_prior=None, seed: int = 0) -> list:
    """The limit fits (:class:`~hdid._posterior.limits.LimitFit`) behind ``found``'s limit
    optima; with ``modes="fit"`` (no limit optima to start from) sought here, for the
    warning only."""
    limits = [m.limit for m in found if m.limit is not None]
    if isinstance(modes, str) and modes == "fit" and np.any(np.asarray(lin) > 0):
        from .limits import limit_fits, limit_names

        view = with_user_prior(fit, gauss_prior, seed)[0]
        names = limit_names(fit.problem, lin, getattr(fit, "covariance", None))
        limits = limit_fits(view, names, found[0].cost, MODE_LANES)
    return limits


def sampled_modes(fit, modes, seed: int, u_fit: np.ndarray, lin: np.ndarray,
                  gauss_prior=None, ridges: bool = True) -> list[Mode]:
    """The optima a sampler starts from: ``modes`` ``"auto"`` (:func:`find_modes`, and the
    limit fits of the parameters whose prior is flat in value, :mod:`.limits`),
    ``"fit"`` or a list of :class:`Mode` (copied: their weights are re-set), kept inside
    the prior box around the fit (±``PRIOR_HALF_WIDTH``) and on the allowed side of the
    orders the prior imposes (``tau_s ≥ tau_c``), else they cannot be sampled; a fit whose
    own optimum breaks such an order is refitted inside it (:mod:`.inside`; with ``"auto"``
    the mode search runs again around that optimum) and its best optimum there carries the
    one-line ``CONSTRAINED OPTIMUM`` note (the fit's own, moved inside, only when nothing
    inside is found: then the ``NO OPTIMUM INSIDE`` line, printed at once), with Laplace weights under the sampled prior (the fit's cost
    has the log-flat one; ``lin`` marks the parameters whose prior is flat in value).
    ``ridges=False`` leaves out the starts down the ridges (:func:`seek_ridges`; emcee's:
    ``RIDGE_SAMPLERS``)."""
    from dataclasses import replace

    if isinstance(modes, str):
        if modes not in ("auto", "fit"):
            from .errors import PosteriorError

            raise PosteriorError(f"modes must be 'auto', 'fit' or a list of Mode, not {modes!r}")
        # with a prior of the user's the optima sought are the posterior's: the fit's
        # optima sit where the default weak priors put them (paper log 7203 with the
        # catalog prior: delta 1.6–2.4 against the prior's 1 ± 10 %, and the draws never
        # reached a region of higher density near the truth; docs/decisions/mode-search-starts.md)
        view, extra = with_user_prior(fit, gauss_prior, seed)
        if modes == "auto":  # starts also at the aliases of the fit's swing (:mod:`.aliases`)
            from .aliases import alias_fits

            aliases = alias_fits(view, view.problem, _laplace(view.problem, fit.u)[0],
                                 MODE_DCHI2_MAX)
            extra = np.concatenate([e for e in (extra, aliases.U) if e is not None and len(e)]
                                   or [np.empty((0, len(fit.u)))])
        found = (find_modes(view, seed=seed, extra_starts=extra if len(extra) else None)
                 if modes == "auto" else [_fit_mode(view)])
        if modes == "auto":
            from .aliases import inside_alias_modes

            found += inside_alias_modes(view, found, gauss_prior)
            best = min(m.cost for m in found)
            found += seek_limits(view, lin, best) + (seek_ridges(view, lin, best) if ridges else [])
    else:
        view = with_user_prior(fit, gauss_prior, seed)[0]
        found = [replace(m) for m in modes if ridges or not m.kind.startswith("ridge:")]
        found = found or [replace(m) for m in modes]
    from .density import ordered_pairs
    from .inside import constrained_note, in_support, inside_optimum

    P = fit.problem.n_physical
    pairs = ordered_pairs(fit.problem)
    # the fit's optimum outside the prior's support (tau_s < tau_c): refitted inside it
    inside = inside_optimum(fit, view, gauss_prior)
    note = None
    if inside is not None:
        u_in, _, note = inside
        if u_in is None:
            import sys

            print(f"hdid: {note}", file=sys.stderr, flush=True)
        else:
            if isinstance(modes, str) and modes == "auto":
                # the mode search again, around the optimum inside (its Stribeck shapes,
                # k1 ± 2 sd, Laplace draws): SBC paper log 36009 (--noise none) went from
                # cost 101 (tau_c 0.33 mN m) to 60.7 (0.92; truth 0.94, and the local optimum
                # from the truth 60.7)
                more = find_modes(_Moved(view, u_in), seed=seed)
                more = [m for m in more if in_support(pairs, m.u)]
                if more and min(m.cost for m in more) < _laplace(view.problem, u_in)[0]:
                    best = min(more, key=lambda m: m.cost)
                    u_in, note = best.u, constrained_note(fit, view.problem, best.u, best.cost)
                found += more
            if not any(_same_optimum(view.problem, m, u_in) for m in found
                       if in_support(pairs, m.u)):
                cost, cov, logz = _laplace(view.problem, u_in)
                found.append(Mode(u=u_in, cost=cost, cov=cov, log_evidence=logz,
                                  values=view.problem.values_np(u_in), note=note))

    def in_order(u):
        return pairs is None or bool(np.all(u[pairs[:, 1]] >= u[pairs[:, 0]]))

    # the box is the prior of the parameters without a Gaussian one only: a better basin
    # far from the fit (SBC log 36001: k2 ×10⁶ the fit's) is inside a log-normal prior
    boxed = (np.ones(P, dtype=bool) if gauss_prior is None
             else np.asarray(gauss_prior, dtype=float)[2] <= 0)
    found = [m for m in found if in_order(m.u)
             and np.all(np.abs(m.u[:P] - u_fit[:P])[boxed] < PRIOR_HALF_WIDTH)]
    if not found:
        # every optimum breaks an order the prior imposes (e.g. tau_s < tau_c): start from
        # the fit's, each such pair put just inside the allowed side
        m = _fit_mode(fit)
        if pairs is not None:
            for i, j in pairs:
                m.u[j] = max(m.u[j], m.u[i] + 0.02)
        found = [m]
    if note is not None and not any(m.note for m in found):
        found[0].note = note  # the statement travels with the sampled optimum
    lz = np.array([m.log_evidence + float(lin @ (m.u[:P] - u_fit[:P])) for m in found])
    wz = np.exp(lz - lz.max())
    wz /= wz.sum()
    ridge = np.array([m.kind.startswith("ridge:") for m in found])
    if ridge.any() and (~ridge).any() and wz[ridge].sum() > RIDGE_SHARE:
        wz = np.where(ridge, wz * RIDGE_SHARE / wz[ridge].sum(),
                      wz * (1 - RIDGE_SHARE) / wz[~ridge].sum())
    for m, wi in zip(found, wz):
        m.weight = float(wi)
    if isinstance(modes, str) and modes == "auto":
        found[0].aliases = aliases
    return found
