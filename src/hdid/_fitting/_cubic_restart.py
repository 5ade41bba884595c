"""Restarts of a fit whose cubic stiffness has gone to its lower end (``k2 → 0``).

``k2`` is fitted in log (it is positive), so near 0 its gradient vanishes: a fit started at
``k2``'s start (17 % of the spring torque at the largest twist) on a log whose cubic is
0.1 % of it overshoots into the ``k2 → 0`` basin and stays there, ``k1`` absorbing the cubic
(a 42 Hz sweep log, 1 kHz: ``k2`` at 1e-5 of its truth, ``k1`` 12.6 sd off, the RMS 40× its
value with ``k2`` at the truth). No start of the grid sits near such a small cubic, and
the linear-spring limit (:mod:`._limits`) restarts from ``k2 ≈ 0`` itself. So a fit whose
cubic share at the largest twist, ``k2·A²/k1``, is below :data:`GONE_SHARE` restarts the
full model from the shares of :data:`RESTART_SHARES`; the caller keeps a restart that ends
lower. (The log's own backbone, ``f² = f₀²·(1 + ¾·(k2/k1)·A²)`` from the half-periods
between turning points, does not say where: that plant's cubic moves f² by 0.1 % across its
swings, under the ~2 % scatter of half-periods timed at 1 kHz, and a paper-size plant's
friction stops it within one or two half-swings.)

A release instant is mapped onto its bracket by a sigmoid, flat at both ends: an optimum
whose release sits on an end (:data:`RELEASE_STUCK`) restarts with it :data:`RELEASE_EDGE`
inside (:func:`release_row`), kept on the same terms.

An optimum whose swing is above the log's Nyquist frequency while the log's own swing
(its turning points) is below it may sit on an alias: readings 200 Hz apart cannot tell a
54 Hz swing from one at 254 Hz. It restarts folded back (:func:`fold_back_rows`), kept on
the same terms. NumPy only (the local fits are the caller's).
"""

from __future__ import annotations

import math

import numpy as np

from .._simulation._aliasing import swing_hz
from ..effects.stiffness import CubicStiffness
from ._limits import SAME_MARGIN, with_values

#: Cubic share ``k2·A²/k1`` at the largest twist below which ``k2`` has gone to its lower
#: end: it shifts that swing's frequency by less than 1e-4 (¾ of the share), under what
#: a log's timing resolves.
GONE_SHARE = 1e-4
#: Shares the restarts put the cubic at: the decades between :data:`GONE_SHARE` and the
#: start's 0.17 that a descent from the start skips.
RESTART_SHARES = (1e-2, 1e-3)


def restart_rows(problem, model, scales, u) -> np.ndarray | None:
    """Full-model starts from ``u`` with ``k2`` at the restart shares, or ``None`` where the
    model has no free cubic or ``k2`` has not gone to its lower end at ``u``."""
    if type(model.spring) is not CubicStiffness or "k2" not in problem.free:
        return None
    v = {**model.float_values(), **problem.values_np(np.asarray(u))}
    k1, k2, twist = float(v["k1"]), float(v["k2"]), float(scales.twist)
    if not (k1 > 0 and twist > 0 and math.isfinite(k2)):
        return None
    if k2 * twist**2 / k1 >= GONE_SHARE:
        return None
    return np.asarray([with_values(problem, model, u, {"k2": s * k1 / twist**2})
                       for s in RESTART_SHARES])


#: Where a release stuck on an end of its bracket restarts: this fraction of the bracket
#: inside it, where the sigmoid map's slope s(1−s) is a tenth of its peak.
RELEASE_EDGE = 0.025
#: A release within this fraction of an end of its bracket is stuck there: the map's slope
#: is < 1/250 of its peak and Levenberg–Marquardt's step in it vanishes. (A world log, an
#: 18 Hz gear at 100 Hz released 0.57 ms before its second reading: a limit's restart ran
#: the release onto that reading, u = 14.7, and the fit ended at 2.98× the quantization
#: floor, k1 −1.9 %; restarted from RELEASE_EDGE inside: χ² 125 → 1.6.)
RELEASE_STUCK = 1e-3


def release_row(problem, u) -> np.ndarray | None:
    """A full-model start from ``u`` with its releases stuck on a bracket's end moved
    :data:`RELEASE_EDGE` inside, or ``None`` where none is stuck (or none is free)."""
    if not problem.release_free:
        return None
    lo, hi = np.asarray(problem.release_lo), np.asarray(problem.release_hi)
    v = np.array(u, dtype=float)
    i, j = problem.n_physical, problem.n_physical + problem.n_runs
    s = 1.0 / (1.0 + np.exp(-v[i:j]))
    stuck = (np.minimum(s, 1.0 - s) < RELEASE_STUCK) & (hi > lo)
    if not stuck.any():
        return None
    inside = math.log((1.0 - RELEASE_EDGE) / RELEASE_EDGE)  # u at the edge's fraction
    v[i:j] = np.where(stuck, np.sign(v[i:j]) * inside, v[i:j])
    return v[None, :]


#: The power of the second in the SI units of the model's parameters (the newton is
#: kg m s⁻²); units without one (rad, 1, kg m^2) do not change in a time stretch.
_TIME_POWER = {"N": -2, "s": 1, "Hz": -1}


def _time_power(unit: str) -> int:
    """The power of the second in ``unit`` (e.g. ``"N m s/rad"`` → −1)."""
    num, _, den = unit.partition("/")

    def power(part: str) -> int:
        out = 0
        for token in part.split():
            name, _, exp = token.partition("^")
            out += _TIME_POWER.get(name, 0) * (int(exp) if exp.lstrip("-").isdigit() else 1)
        return out
    return power(num) - power(den)


def fold_back_rows(problem, model, u, sample_period: float, fitted_hz: float,
                   log_hz: float, twist: float) -> np.ndarray | None:
    """Full-model starts from ``u`` with its swing folded back below the Nyquist frequency
    of ``sample_period`` [s], or ``None`` where the fitted swing (``fitted_hz`` [Hz],
    hardened at the largest ``twist`` [rad]: :func:`~hdid._simulation._aliasing.swing_hz`)
    is below it or the log's own swing ``log_hz`` (its turning points,
    :attr:`Prepared.frequency_hz`) is not.

    The folded swing is the alias ``|f − k·fs|`` nearest the log's own: the same readings
    at the samples. ``r`` = folded / fitted swing. At a fixed inertia the model's
    trajectory ``θ(r·t)`` has every parameter scaled by ``r`` to the power of the second in
    its unit, negated (torques and stiffnesses by ``r²``, speeds such as ``v_s`` and viscous
    coefficients by ``r``): the first row. That stretch also slows the decay, which the
    readings fix in time, not in swings; the second row keeps it — the stiffnesses by
    ``r²``, everything else timed as the first row by ``r`` once less (dry friction by
    ``r``: its decrement per second; viscous damping as it was). (A world log, a 53 Hz gear
    at 200 Hz: the fit ended on the 254 Hz alias, k1 22× its truth, 2.96× the floor.)"""
    fs = 1.0 / sample_period if sample_period > 0 else math.nan
    v = {**model.float_values(), **problem.values_np(np.asarray(u))}
    f_fit = swing_hz(fitted_hz, v, twist) if math.isfinite(twist) else fitted_hz
    if not (math.isfinite(fs) and math.isfinite(f_fit) and math.isfinite(log_hz)
            and 0.0 < log_hz < 0.5 * fs < f_fit):
        return None
    aliases = [abs(f_fit - k * fs) for k in range(1, int(f_fit // fs) + 2)]
    folded = min((a for a in aliases if 0.0 < a < 0.5 * fs), key=lambda a: abs(a - log_hz),
                 default=log_hz)
    r = folded / f_fit
    specs = model.parameter_specs()
    power = {n: _time_power(specs[n].unit) for n in problem.free}
    stretched = {n: v[n] * r ** -p for n, p in power.items() if p}
    stiff = {n for n, p in power.items() if p == -2 and n in _STIFFNESSES}
    decay = {n: v[n] * (r ** (-p - 1) if n not in stiff else r ** -p)
             for n, p in power.items() if p}
    if not stretched:
        return None
    return np.asarray([with_values(problem, model, u, stretched),
                       with_values(problem, model, u, decay)])


#: Parameters that set the swing's frequency (scaled by ``r²`` in both fold-back rows).
_STIFFNESSES = ("k1", "k2")


def restarted(result, problem, model, scales, solutions, local_fits, finish,
              log_hz: float = math.nan, start=None):
    """``result`` with the restarts of :func:`restart_rows`, :func:`release_row` and
    :func:`fold_back_rows` (``log_hz``: the log's own swing frequency [Hz]) run by
    ``local_fits`` (rows → ``(U, costs, ok, steps)``, the optimum's row first), kept where one
    ends lower than the optimum by more than the limits' same-optimum margin: then
    ``finish(solutions)`` assembles the result again from all local fits (its limits checked
    anew). Returns the
    result and the local fits ``solutions`` ``(U, costs, ok, steps)``, extended if kept; a
    result kept from a fold-back row carries the optimum it was folded from as
    ``unfolded``."""
    fitted_hz = result.derived.get("natural_frequency_hz", (math.nan,))[0]
    more = [r for r in (restart_rows(problem, model, scales, result.u),
                        release_row(problem, result.u)) if r is not None]
    folded = fold_back_rows(problem, model, result.u, result.sample_period, fitted_hz,
                            log_hz, float(scales.twist))
    if not more and folded is None:
        return result, solutions
    new = local_fits(np.concatenate([np.asarray(result.u, dtype=float)[None, :], *more]))
    if folded is not None and start is not None:  # also from the data's release guesses
        P = problem.n_physical
        again = np.array(folded)
        again[:, P:] = np.asarray(start, dtype=float)[P:]
        folded = np.concatenate([folded, again])
    if folded is not None:  # a basin of its own: not dropped beside the optimum's lane
        new = tuple(np.concatenate([a, b]) for a, b in zip(new, local_fits(folded)))
    costs = np.where(np.isfinite(new[1]), np.asarray(new[1]), np.inf)
    if not np.min(costs[1:]) < costs[0] * (1.0 - SAME_MARGIN):
        return result, solutions
    solutions = tuple(np.concatenate([a, b]) for a, b in zip(solutions, new))
    out = finish(solutions)
    if folded is not None and int(np.argmin(costs)) >= len(costs) - len(folded):
        # a folded swing won at a substep picked for the slow one: the fast optimum may
        # have lost by the integrator's error alone (:func:`hdid._fitting._substep.refined`
        # refits it at the substep it wants)
        out.unfolded = result
    return out, solutions
