"""The vanishing ends of value-flat parameters: limit fits, their optima, the warning.

A parameter whose default prior is flat in its value (``flat_in_value``: ``k2``,
``tau_c``, ``c_v``) is the coefficient of a term that may vanish. Where the data cannot
exclude that end — the shipped paper log's Coulomb limit of the Stribeck law: along laws
with v_s ≈ 17–24 rad/s, −2 log p rises by only 3 from the best optimum down to tau_c
0.5 mN m and by 4.4 at 6 µN m (docs/decisions/friction-coordinates.md, tau-c-flat-in-value.md) — an
ensemble started at the least-squares optimum may never go down the curved ridge.

The *limit fit* of such a parameter is the least-squares fit with it held at
``LIMIT_FRACTION`` of its least-squares value (a strong prior row on the fit's own
Levenberg–Marquardt program: no compile of its own) and every other unknown refitted,
reached by continuation along ``LIMIT_PATH``. Its uses:

- further optima for the walkers and the t-mixture's independence move
  (:func:`~hdid._posterior.modes.seek_limits`): the end and the continuation's first
  point (``exp(−0.75)``, a first step down the ridge), kept when their least-squares cost
  is within ``MODE_DCHI2_MAX`` of the best, as any optimum is (beyond, the mass is
  < 1e-13 of the best's); never merged into another optimum (the ridge joins them to the
  fit's optimum: merged, they would be dropped); marked ``kind="limit:NAME"``. Those
  within ``LIMIT_DCHI2`` keep at least ``LIMIT_PROPOSAL_WEIGHT`` of the independence
  proposal, frozen through the burn-in's refits (:func:`limit_proposal_weights`);
- the warning (:func:`limit_warnings`), from the profile along the path:
  ``Δ = 2·(log p(best optimum) − log p(point))`` with ``p`` the posterior density less the
  value-flat priors (constant in the value), each at its best noise level. A point below
  the chain's 95 % interval with ``Δ ≤ LIMIT_DCHI2`` (3.84, the 95 % point of χ²₁: inside
  the data's 95 % profile interval) means the chain's lower end is not the data's; a
  chain that does come down to the end (``LIMIT_REACH``) when the end is within reach is
  told that its lower end is the prior's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: A limit fit holds its parameter at this fraction of the least-squares value: e⁻⁶ ≈
#: 0.25 %, inside the ±7 (log) prior box and far enough below the value for the term to
#: be absent at the log's precision (the shipped log's Coulomb ridge reaches < 10 µN m,
#: 0.4 % of the fit's 2.2 mN m).
LIMIT_FRACTION = math.exp(-6.0)
#: No limit fit for a parameter the least-squares fit measures to better than this
#: (relative standard error, the sd of its log): its vanishing end is then ≥ 5 linearised
#: sd away (Δχ² ≥ 25), far beyond ``LIMIT_DCHI2``; each limit fit costs five LM
#: calls (0.3–1 s on a paper log since the limit fits became cheap, ~5 s before). The shipped log's tau_c, c_v and k2 are at 106 %, 236 %, 34 %.
LIMIT_SCREEN_REL_SD = 0.2
#: The continuation that reaches it: held at ``exp(−s)`` of the least-squares value for
#: each ``s`` (``LIMIT_FRACTION`` is the last). The first step is short: in steps of 1.5
#: from the shipped log's optimum the tau_c path ended at Δχ² 16 instead of 1.2.
LIMIT_PATH = (0.75, 1.5, 3.0, 4.5, 6.0)
#: sd in log of the row that holds it there (the others are refitted around it).
LIMIT_PIN_SD = 1e-3
#: The data allow the term to vanish when the limit fit is within this of the optimum in
#: −2 log p: the 95 % point of χ² with one degree of freedom.
LIMIT_DCHI2 = 3.84
#: A chain "reaches" the vanishing end when the lower end of its 95 % interval is below
#: this fraction of the least-squares value (a posterior flat in the value over [0, T] has
#: its 2.5 % point at 0.025 T; one the data hold away from zero ends far above 0.1 T).
LIMIT_REACH = 0.1


#: Share of the independence proposal each limit optimum within the data's reach
#: (least-squares cost ≤ ``LIMIT_DCHI2`` above the best) keeps through the burn-in's
#: refits (frozen there): its Laplace weight is a poor guess of a flat ridge's mass (the
#: shipped log's Coulomb limit: 0.000 at the end), and refitted to burn-in draws that
#: have not reached it, it fades (weight halved per stage) or is pulled onto the main
#: optimum. Any weight keeps the move exact.
LIMIT_PROPOSAL_WEIGHT = 0.05


def limit_proposal_weights(found) -> tuple[np.ndarray, np.ndarray]:
    """``(weights, frozen)`` of the independence proposal's components, one per optimum of
    ``found``: the Laplace weights, raised to ``LIMIT_PROPOSAL_WEIGHT`` for limit optima
    within reach (which are frozen), the optima's scaled to keep the sum 1."""
    w = np.array([m.weight for m in found], dtype=float)
    best = min((m.cost for m in found if m.kind == "optimum"), default=min(m.cost for m in found))
    frozen = np.array([m.kind != "optimum" and m.cost - best <= LIMIT_DCHI2 for m in found])
    if frozen.any():
        w = np.where(frozen, np.maximum(w, LIMIT_PROPOSAL_WEIGHT), w)
        rest = max(1.0 - w[frozen].sum(), 0.05)
        free = w[~frozen].sum()
        w = np.where(frozen, w, w * rest / (free if free > 0 else 1.0))
    return w / w.sum(), frozen


@dataclass
class LimitFit:
    """The least-squares fit with ``name`` held near zero, the rest refitted."""

    name: str
    u: np.ndarray        # unknowns at the limit fit
    value: float         # the held value of ``name``
    lsq_value: float     # ``name``'s least-squares value
    dchi2_lsq: float     # its least-squares cost above the best optimum's (fit units)
    dchi2: float = math.nan  # Δ(−2 log p) of the posterior (see the module docstring)
    #: the continuation's fits before it: ``(u, dchi2_lsq)`` along ``LIMIT_PATH``
    path: list = field(default_factory=list)
    #: ``(value, Δ(−2 log p))`` along the path and at the end (:func:`assess_limits`)
    profile: list = field(default_factory=list)

    def to_dict(self) -> dict:
        return {"name": self.name, "held_value": self.value, "lsq_value": self.lsq_value,
                "dchi2_lsq": self.dchi2_lsq, "dchi2": self.dchi2,
                "within_reach": bool(np.isfinite(self.dchi2) and self.dchi2 <= LIMIT_DCHI2),
                "profile": [{"value": v, "dchi2": d} for v, d in self.profile]}


def limit_names(problem, lin, covariance=None) -> list[str]:
    """Free physical parameters whose prior (as sampled) is flat in their value and, given
    the least-squares ``covariance`` (of the log-transformed unknowns), whose relative
    standard error is at least ``LIMIT_SCREEN_REL_SD``."""
    free = list(problem.free)
    names = [free[i] for i in np.flatnonzero(np.asarray(lin) > 0)]
    if covariance is None:
        return names
    C = np.asarray(covariance, dtype=float)
    return [n for n in names
            if not (np.isfinite(C[free.index(n), free.index(n)])
                    and C[free.index(n), free.index(n)] < LIMIT_SCREEN_REL_SD**2)]


def limit_fits(fit, names, best_cost: float, lanes: int,
               stop: float = math.inf) -> list[LimitFit]:
    """One limit fit per parameter of ``names``, from the fit's optimum (``fit`` may be the
    mode search's view under a user prior), reached by continuation: the parameter held
    at ``exp(−s)`` of its least-squares value for each ``s`` of ``LIMIT_PATH``, every fit
    started from the one before (from the optimum at once, the shipped log's LM stopped at
    Δχ² 3·10⁵), each a call of the fit's Levenberg–Marquardt program at its lane count
    ``lanes`` (one lane active: the program the fit compiled). A path whose cost rises
    more than ``stop`` above ``best_cost`` ends there (the data exclude that end)."""
    prob = fit.problem
    key = (np.asarray(fit.u, dtype=float).tobytes(), tuple(names), int(lanes)) + tuple(
        np.asarray(a).tobytes() for a in (prob.prior_mean, prob.prior_sd, prob.prior_on))
    if key not in _CACHE:
        if len(_CACHE) >= _CACHE_SIZE:
            _CACHE.pop(next(iter(_CACHE)))
        _CACHE[key] = _limit_paths(fit, names, lanes)
    lsq = prob.values_np(np.asarray(fit.u, dtype=float))
    out = []
    for name, pts in _CACHE[key]:
        path = []
        for u, cost in pts:  # the path ends at the first point beyond ``stop``
            path.append((u.copy(), float(cost) - float(best_cost)))
            if path[-1][1] > stop:
                break
        if path:
            u, c = path[-1]
            out.append(LimitFit(name=name, u=u, value=float(prob.values_np(u)[name]),
                                lsq_value=float(lsq[name]), dchi2_lsq=c, path=path[:-1]))
    return out


#: Continuations already made (``[(name, [(u, cost), ...]), ...]``, whole paths), by the
#: fit's unknowns, the names, the lanes and the problem's prior rows (a user prior's view
#: differs): the emcee and SMC calls and ``modes="fit"`` on one fit do not redo them.
_CACHE: dict = {}
_CACHE_SIZE = 16


def _limit_paths(fit, names, lanes) -> list:
    """Every parameter's whole continuation: ``(name, [(u, cost), ...])``, the cost under
    the fit's own prior rows; a path ends early only where the cost is not finite."""
    import equinox as eqx
    import jax.numpy as jnp

    from .._fitting._lm import PHASE1_STEPS, PHASE2_CHUNK
    from .lanes import _solve_in_lanes, solve_fresh

    prob = fit.problem
    free = list(prob.free)
    u0 = np.asarray(fit.u, dtype=float)
    active = jnp.asarray(np.arange(lanes) == 0)
    out = []
    for name in names:
        i = free.index(name)
        u, path = u0.copy(), []
        for s in LIMIT_PATH:
            mean = np.asarray(prob.prior_mean, dtype=float).copy()
            sd = np.asarray(prob.prior_sd, dtype=float).copy()
            on = np.asarray(prob.prior_on, dtype=bool).copy()
            mean[i], sd[i], on[i] = u0[i] - s, LIMIT_PIN_SD, True
            pinned = eqx.tree_at(lambda p: (p.prior_mean, p.prior_sd, p.prior_on), prob,
                                 (jnp.asarray(mean), jnp.asarray(sd), jnp.asarray(on)))
            start = u.copy()
            start[i] = u0[i] - s
            U, steps = jnp.asarray(np.tile(start, (lanes, 1))), PHASE1_STEPS
            for _ in range(8):
                U, cost, done, _ = solve_fresh(pinned, U, active, steps)
                if bool(done[0]) or not np.isfinite(float(cost[0])):
                    break
                steps = PHASE2_CHUNK
            u = np.asarray(U[0], dtype=float)
            # its cost under the fit's own prior rows: the LM program with no step
            # (``Problem.cost``, not jitted, traces the simulation: ~1 s a call)
            c = float(_solve_in_lanes(solve_fresh, prob, u[None], [True], 0, lanes)[1][0])
            if not np.isfinite(c):
                break
            path.append((u, c))
        out.append((name, path))
    return out


def profile_logp(lp, lin, U, log_sigma_grid, log_prob) -> np.ndarray:
    """For each row of unknowns ``U``: max over ``log_sigma_grid`` of the log-posterior
    density of the unknowns less the value-flat priors (``lin``) — likelihood and the
    other priors, the quantity whose drop :func:`limit_warnings` compares with χ²₁."""
    U = np.atleast_2d(np.asarray(U, dtype=float))
    P = len(lin)
    centre = np.asarray(lp.centre, dtype=float)
    samp = (np.zeros(P) if lp.sample_linear is None else np.asarray(lp.sample_linear))
    out = []
    for u in U:
        X = np.column_stack([np.tile(u, (len(log_sigma_grid), 1)), log_sigma_grid])
        lps = np.asarray(log_prob(lp.to_sampled_np(X)), dtype=float)
        d = u[:P] - centre[:P]
        # sampled in value: log p_y = log p_u − (u − centre); flat in value: log p_u ∋ u − centre
        out.append(float(np.max(lps)) + float(samp @ d) - float(np.asarray(lin) @ d))
    return np.array(out)


def limit_warnings(limits, samples: dict, lsq_values: dict, shares: dict | None = None) -> list[str]:
    """Warnings for the value-flat parameters whose limit path the data allow below the
    chain's 95 % interval: a point of :attr:`LimitFit.profile` under the interval's lower
    end with ``Δ(−2 log p) ≤ LIMIT_DCHI2`` ("LOWER END NOT MEASURED": the profile of the
    data and the chain disagree — the walkers have not gone down the ridge, or the
    posterior's volume there is small; either way the lower end is not the data's). A
    chain whose interval does come down to the vanishing end (``LIMIT_REACH``) while the
    end is within reach is told that its lower end is the prior's ("BOUNDED ABOVE ONLY").
    ``shares`` (``{name: (Laplace mass, share of the draws)}`` of the limit optima,
    :func:`limit_shares`) is quoted in the first."""
    out = []
    for lim in limits:
        if lim.name not in samples or not lim.profile:
            continue
        x = np.asarray(samples[lim.name], dtype=float)
        lo, hi = np.percentile(x, [2.5, 97.5])
        ref = float(lsq_values.get(lim.name, lim.lsq_value))
        reached = lo <= LIMIT_REACH * ref  # the chain came down to the vanishing end
        below = [(v, d) for v, d in lim.profile
                 if np.isfinite(d) and d <= LIMIT_DCHI2 and v < lo and not reached]
        if below:
            v, d = below[-1]
            end = ("" if v == lim.value else
                   f"; at its vanishing end ({lim.value:.3g}) Δ = {lim.dchi2:.2f}")
            expected, observed = (shares or {}).get(lim.name, (math.nan, math.nan))
            seen = ("" if not np.isfinite(expected) else
                    f"; the limit fits' optima hold {expected:.1%} of the Laplace mass and "
                    f"{observed:.1%} of the draws")
            out.append(
                f"LOWER END NOT MEASURED: {lim.name} — the data allow values below the chain's "
                f"95 % interval [{lo:.4g}, {hi:.4g}]: the least-squares fit with {lim.name} "
                f"held at {v:.3g} (the rest refitted) is only Δ(−2 log p) = {d:.2f} below the "
                f"best optimum (≤ {LIMIT_DCHI2}, the 95 % point of χ²₁){end}, yet "
                f"{np.mean(x < v):.1%} of the draws lie below it{seen}. Either the sampler "
                "has not gone down that ridge (run longer: max_steps, or more particles with "
                "method='smc') or the posterior's volume there is small; read the lower end as not bounded by the data, or "
                f"supply prior={{'{lim.name}': (value, sd)}} from a datasheet")
        elif np.isfinite(lim.dchi2) and lim.dchi2 <= LIMIT_DCHI2 and reached:
            out.append(
                f"BOUNDED ABOVE ONLY: the data do not bound {lim.name} below — the least-squares "
                f"fit with {lim.name} held at {lim.value:.3g} (the rest refitted) is only "
                f"Δ(−2 log p) = {lim.dchi2:.2f} below the best optimum (≤ {LIMIT_DCHI2}); its "
                f"95 % interval [{lo:.4g}, {hi:.4g}] reaches down to that end, and its lower end "
                "is the prior's (flat in the value), not a measurement; supply "
                f"prior={{'{lim.name}': (value, sd)}} from a datasheet to bound it")
    return out


def assess_limits(limits, lp, lin, optima_u, log_prob, sigma_range, samples,
                  lsq_values, shares=None) -> list[str]:
    """Set each limit fit's ``dchi2`` and ``profile`` — ``Δ = 2·(log p(best optimum) −
    log p(point))`` along its path and at its end, the value-flat priors left out
    (:func:`profile_logp`), each at its best noise level on a grid over ``sigma_range``
    (log σ_n) — and return :func:`limit_warnings` for ``samples``."""
    if not limits:
        return []
    lo, hi = sigma_range
    grid = np.linspace(lo, max(hi, lo + math.log(2.0)) + 1.0, 25)
    top = float(np.max(profile_logp(lp, lin, optima_u, grid, log_prob)))
    for lim in limits:
        pts = [u for u, _ in lim.path] + [lim.u]
        d = np.maximum(2.0 * (top - profile_logp(lp, lin, pts, grid, log_prob)), 0.0)
        lim.dchi2 = float(d[-1])
        vals = [float(v) for v in _values_of(lp.problem, pts, lim.name)]
        lim.profile = [(v, float(x)) for v, x in zip(vals, d)]
    return limit_warnings(limits, samples, lsq_values, shares)


def _values_of(problem, U, name):
    return [problem.values_np(u)[name] for u in U]


def limit_shares(found, share) -> dict:
    """``{name: (Laplace mass, share of the draws)}`` of each parameter's limit optima in
    ``found`` (``share``: the draws' share nearest each optimum)."""
    out: dict = {}
    for m, sh in zip(found, share):
        if m.kind.startswith("limit:"):
            e, o = out.get(m.kind[6:], (0.0, 0.0))
            out[m.kind[6:]] = (e + float(m.weight), o + float(sh))
    return out
