"""Starts of the mode search at the aliases of the fit's swing.

A log sampled at ``fs`` cannot tell a swing at ``f`` from one at ``k·fs ± f``: the readings
are the same at the samples, and only the friction's decay and the rests (which the model
times in seconds, not in swings) differ. Under the weak default priors (k1 a factor ~10
either way of the log's scale) half the paper-design truths swing faster than 2.5
readings a period, and the fit (and the mode search around it) may end on the wrong alias:
SBC paper log 36003 (truth 97 Hz at 250 Hz) was fitted and sampled at the 347 Hz alias,
k1 13× its truth, and every interval but k2's, tau_c's and delta's missed.

:func:`alias_starts` gives the mode search (:func:`~hdid._posterior.modes.find_modes`)
starts at every alias ``k·fs ± f_a`` of the fit's swing (hardened at the log's largest
twist, ``f_a`` its fold below Nyquist) whose ``k1`` lies in the plausible range — the
sampled prior's centre ± :data:`ALIAS_PRIOR_SD` sd where ``k1`` has a Gaussian (log-normal)
prior, else the prior box around the fit — each in the two time stretches of the fit's own
fold-back (:func:`hdid._fitting._cubic_restart.fold_back_rows`: the whole trajectory
stretched, or the decay kept in seconds). :func:`alias_fits` runs them to their optima;
those within the data's χ² margin (``MODE_DCHI2_MAX`` of the best) become starts of the
mode search (kept, merged and weighted by Laplace evidence as every other optimum), the rest
are dropped with a note (:attr:`AliasSearch.notes`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

#: The plausible k1 range where k1 has a log-normal prior: its centre ± this many sd (the
#: default's 95 % spans a factor 10.5 either way, so ± 3 sd a factor ~37: 99.7 % of the
#: truths the calibration draws).
ALIAS_PRIOR_SD = 3.0
#: Two stretches within this of 1 are the fit's own swing (not an alias).
SAME_SWING = 0.02


@dataclass
class AliasSearch:
    """What :func:`alias_fits` found: the optima to add as starts (``U``), and for each alias
    tried its swing [Hz], the k1 it started at, its end k1 and its Δχ² over the best."""

    U: np.ndarray
    tried: list = field(default_factory=list)   # (swing Hz, k1 start, k1 end, Δχ²)
    notes: list = field(default_factory=list)   # one line per dropped alias

    def to_dict(self) -> dict:
        return {"tried": [{"swing_hz": f, "k1_start": a, "k1_end": b, "dchi2": d}
                          for f, a, b, d in self.tried], "notes": list(self.notes)}


def _twist(problem, ratio: float) -> float:
    """The log's largest twist at the spring [rad]: max |hold − rest| over the runs (the
    rest: each run's last weighted reading), over the gear ratio."""
    theta, w, hold = (np.asarray(a, dtype=float) for a in (problem.theta, problem.weight,
                                                            problem.hold))
    amp = 0.0
    for th, wr, h in zip(theta, w, hold):
        on = np.flatnonzero(wr > 0)
        if on.size:
            amp = max(amp, abs(h - th[on[-1]]))
    return amp / ratio if ratio > 0 else math.nan


def _k1_range(problem, u_fit) -> tuple[float, float] | None:
    """The plausible log k1 range (transformed space), or None where k1 is not free."""
    from .density import PRIOR_HALF_WIDTH

    free = list(problem.free)
    if "k1" not in free:
        return None
    j = free.index("k1")
    if bool(np.asarray(problem.prior_on)[j]):
        m, s = float(np.asarray(problem.prior_mean)[j]), float(np.asarray(problem.prior_sd)[j])
        return m - ALIAS_PRIOR_SD * s, m + ALIAS_PRIOR_SD * s
    return u_fit[j] - PRIOR_HALF_WIDTH, u_fit[j] + PRIOR_HALF_WIDTH


def alias_starts(fit, problem) -> tuple[np.ndarray, list[tuple[float, float]]]:
    """Rows of starts (two a swing) at the aliases of ``fit``'s swing whose k1 is plausible
    (:func:`_k1_range` under ``problem``'s prior rows), and each alias's ``(swing Hz, k1)``;
    empty where the fit has no free k1, no swing frequency or no sample period."""
    from .._fitting._cubic_restart import _STIFFNESSES, _time_power
    from .._fitting._unknowns import with_values
    from .._simulation._aliasing import swing_hz

    model = fit.model
    u = np.asarray(fit.u, dtype=float)
    v = {**model.float_values(), **problem.values_np(u)}
    f0 = float(fit.derived.get("natural_frequency_hz", (math.nan,))[0])
    dt = float(getattr(fit, "sample_period", math.nan))
    rng = _k1_range(problem, u)
    twist = _twist(problem, float(model.ratio))
    f = swing_hz(f0, v, twist) if math.isfinite(twist) else f0
    if rng is None or not (dt > 0 and math.isfinite(f) and f > 0 and v.get("k1", 0) > 0):
        return np.empty((0, u.size)), []
    fs = 1.0 / dt
    fa = f % fs
    fa = min(fa, fs - fa)
    # swings whose k1 (∝ f², the spring scaled as a whole) lies in the plausible range
    lo, hi = (f * math.exp(0.5 * (b - math.log(v["k1"]))) for b in rng)
    cands = sorted({g for k in range(int(hi // fs) + 2) for g in (k * fs - fa, k * fs + fa)
                    if lo <= g <= hi and g > 0 and abs(g / f - 1.0) > SAME_SWING})
    power = {n: _time_power(model.parameter_specs()[n].unit) for n in problem.free}
    rows, info = [], []
    for g in cands:
        r = g / f
        # the trajectory θ(r·t): every parameter by r to minus its power of the second
        stretched = {n: v[n] * r ** -p for n, p in power.items() if p}
        # the decay kept in seconds: stiffnesses by r², the rest timed once less
        decay = {n: v[n] * (r ** -p if n in _STIFFNESSES else r ** (-p - 1))
                 for n, p in power.items() if p}
        rows += [with_values(problem, model, u, stretched), with_values(problem, model, u, decay)]
        info.append((g, v["k1"] * r * r))
    return (np.asarray(rows) if rows else np.empty((0, u.size))), info


def alias_fits(fit, problem, best_cost: float, dchi2_max: float,
               max_steps: int = 150) -> AliasSearch:
    """The local fits from :func:`alias_starts` (the fit's Levenberg–Marquardt, in lanes):
    the end of each alias (the better of its two stretches) within ``dchi2_max`` of the best
    (``best_cost`` or a lower alias) is kept as a start; the others are dropped with a note."""
    from .._fitting._lm import PHASE1_STEPS, PHASE2_CHUNK
    from .lanes import _solve_in_lanes, solve_fresh

    U0, info = alias_starts(fit, problem)
    if not len(U0):
        return AliasSearch(U=U0)
    U, costs, ok = _solve_in_lanes(solve_fresh, problem, U0, np.ones(len(U0), dtype=bool),
                                   PHASE1_STEPS)
    costs = np.where(np.isfinite(costs), costs, np.inf)
    # as find_modes: past the first phase only ends within 10× the margin go on, then
    # within the margin (the shipped paper log's two aliases, Δχ² 1.5e5 and 3e5 after the
    # first phase, ran 150 steps for 20 s of CPU before)
    act = ~ok & (costs - min(best_cost, float(np.min(costs))) < 10 * dchi2_max)
    used = PHASE1_STEPS
    while used < max_steps and act.any():
        U2, c2, d2 = _solve_in_lanes(solve_fresh, problem, U, act, PHASE2_CHUNK)
        U[act], ok[act] = U2[act], d2[act]
        costs[act] = np.where(np.isfinite(c2[act]), c2[act], np.inf)
        used += PHASE2_CHUNK
        act = act & ~ok & (costs - min(best_cost, float(np.min(costs))) < dchi2_max)
    best = min(best_cost, float(np.min(costs)))
    keep, out = [], AliasSearch(U=U0[:0])
    for i, (g, k1) in enumerate(info):
        a = 2 * i + int(costs[2 * i + 1] < costs[2 * i])
        d = float(costs[a] - best)
        k1_end = float(problem.values_np(U[a])["k1"]) if np.isfinite(U[a]).all() else math.nan
        out.tried.append((float(g), float(k1), k1_end, d))
        if d < dchi2_max:
            keep.append(U[a])
        else:
            out.notes.append(f"alias {g:.4g} Hz (k1 {k1:.4g} N m/rad) dropped: its local fit "
                             f"(to k1 {k1_end:.4g}) ended Δχ² {d:.3g} above the best, beyond "
                             f"{dchi2_max:g}")
    out.U = np.asarray(keep) if keep else U0[:0]
    return out


#: An optimum whose k1 is farther than this factor from the fit's sits on another alias.
OTHER_ALIAS = 1.5


def inside_alias_modes(view, found, gauss_prior=None) -> list:
    """Optima of ``found`` on another alias than the fit's (k1 beyond ``OTHER_ALIAS`` of
    it) that break an order the prior imposes (``tau_s ≥ tau_c``), refitted inside it as
    the fit's own optimum is (:func:`~hdid._posterior.inside.inside_optimum`), as
    :class:`~hdid._posterior.modes.Mode` s to add (none that is one of ``found``'s optima
    inside). Without them the order filter of ``sampled_modes`` drops the alias: SBC paper
    log 36003's at k1 2150 (χ² 2.9 against the fit's alias's 22.5) had tau_s < tau_c."""
    from .density import ordered_pairs
    from .inside import broken_pairs, in_support, inside_optimum
    from .optima import Mode, _laplace, _Moved, _same_optimum

    prob = view.problem
    pairs = ordered_pairs(prob)
    k1_fit = float(view.values.get("k1", math.nan))
    out: list = []
    for m in found:
        ratio = m.values.get("k1", math.nan) / k1_fit
        if (m.kind != "optimum" or not math.isfinite(ratio) or 1 / OTHER_ALIAS < ratio < OTHER_ALIAS
                or not broken_pairs(prob, m.u)):
            continue
        moved = _Moved(view, m.u)
        got = inside_optimum(moved, moved, gauss_prior)
        if got is None or got[0] is None or not np.isfinite(got[1]):
            continue
        u_in = np.asarray(got[0], dtype=float)
        if any(_same_optimum(prob, o, u_in) for o in found + out if in_support(pairs, o.u)):
            continue
        cost, cov, logz = _laplace(prob, u_in)
        out.append(Mode(u=u_in, cost=cost, cov=cov, log_evidence=logz, values=prob.values_np(u_in)))
    return out
