"""The candidates of :func:`hdid.diagnose`: which library effects it tries, how each is
added to the current model (variants, data-derived starting values, scanned orders) and
the residual periodogram that proposes ripple orders. (See :mod:`hdid._diagnose` for how
they are refitted and judged.)"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Candidate:
    """One thing ``diagnose`` can try: a library effect and how to add it.

    Attributes
    ----------
    key:
        The name used by ``--add`` and in the report.
    applies:
        ``applies(model) -> bool``: whether the candidate is meaningful for ``model``
        (e.g. free play only replaces a plain cubic spring).
    variants:
        ``variants(model, values, hints) -> [(label, model), ...]``: the models to fit
        (several when a discrete setting such as a ripple order is scanned).
    scanned:
        Discrete settings scanned, counted as extra parameters in the BIC.
    mark:
        The mark the effect leaves in residuals (plain language).
    experiment:
        The experiment that separates it from its look-alikes.
    """

    key: str
    applies: Callable
    variants: Callable
    scanned: int = 0
    mark: str = ""
    experiment: str = ""
    reset_shape: bool = True
    #: candidates of one family leave the same mark (a tie between them is no ambiguity
    #: about the physics, only about its form); "" = a family of its own
    family: str = ""
    #: how many discrete settings the scan chooses from (M): choosing the best of M
    #: costs ``2·ln M`` on the BIC's −2·ln L scale (a uniform prior over the settings),
    #: besides the ``scanned`` parameter's ``ln n``
    settings: int = 1

    def penalty(self, n: float) -> float:
        """BIC cost of the scanned settings: ``scanned·ln n + 2·ln M``."""
        return self.scanned * math.log(n) + 2.0 * math.log(max(self.settings, 1))



def _has(model, name, cls=None) -> bool:
    if name not in model.effect_names:
        return False
    return cls is None or type(model.effect(name)) is cls


def _library_variant(key: str, starts: Callable | None = None):
    """Variants adding library effect ``key``; ``starts(values) -> [overrides, ...]`` gives
    several starting values for the new parameters (a multi-start, not a model choice:
    the best is kept and no parameter is charged for it)."""

    def variants(model, values, hints):
        from .effects import library

        values = {**values, "_k_wg": _model_k_wg(model, values, hints),
                  "_swing": hints.get("swing_rad", math.nan)}
        overrides = starts(values) if starts is not None else [{}]
        return [(key, model.with_effect(library({**values, **o})[key])) for o in overrides]

    return variants


def _model_k_wg(model, values, hints) -> float:
    """The fitted model's small-swing restoring stiffness at the logged axis [N m/rad]:
    ``k1/N²`` for a cubic spring, else the secant of its rest torque over a tenth of the
    logged swing (a gravity pendulum, segments) — never a catalog number."""
    if "k1" in values:
        return float(values["k1"]) / model.ratio**2
    swing = hints.get("swing_rad", math.nan)
    probe = 0.1 * swing if math.isfinite(swing) and swing > 0 else 1e-3
    return max(float(model.rest_torque(probe)) / -probe, 0.0)


def _k_wg(values) -> float:
    return values["_k_wg"]


def _tau(values) -> float:
    """The fitted Coulomb level, or a small fraction of the spring torque over the swing."""
    if "tau_c" in values:
        return values["tau_c"]
    swing = values.get("_swing", math.nan)
    return 0.02 * values["_k_wg"] * (swing if math.isfinite(swing) else 1.0)


#: Orders (cycles per WG revolution) scanned for a position-periodic torque: every
#: integer order 1 … ``MAX_ORDER`` — low orders (less than one period over the swing,
#: still identifiable against a smooth stiffness bend when the data say so), the WG mesh
#: (2, 4), motor pole/slot cogging orders and anything between — plus the two largest
#: peaks of the residual's periodogram against the WG angle (up to
#: ``PERIODOGRAM_ORDERS``). No order is skipped by a rule of thumb: every one is screened
#: by the fit itself (one Gauss–Newton step: the score statistic), and every order whose
#: screening gain is within ``SCAN_TIE_DCHI2`` of the best is refitted to convergence
#: (see :func:`hdid._diagnose._candidate_fits`), so the order is decided by the fit.
MAX_ORDER = 48
RIPPLE_ORDERS = tuple(float(n) for n in range(1, MAX_ORDER + 1))
#: The residual periodogram searches integer orders 1 … this for peaks; with the fixed
#: list inside that range, the ripple's order is chosen from this many settings.
PERIODOGRAM_ORDERS = 120
#: Orders of the kinematic error scanned (2 is the elliptical wave generator's): every
#: integer order 1 … ``MAX_ORDER``, as the ripple's.
KINEMATIC_ORDERS = tuple(float(n) for n in range(1, MAX_ORDER + 1))


def _ripple_variants(model, values, hints):
    from .effects import library

    orders = list(RIPPLE_ORDERS)
    for n in hints.get("ripple_orders") or []:
        if all(abs(n - o) > 0.5 for o in orders):
            orders.append(float(n))
    out = []
    for n in orders:
        eff = library({**values, "order": float(n)})["ripple"]
        out.append((f"ripple (order {n:g})", model.with_effect(eff)))
    return out


def _kinematic_variants(model, values, hints):
    from .effects import library

    out = []
    for n in KINEMATIC_ORDERS:
        eff = library({**values, "order": float(n)})["kinematic_error"]
        out.append((f"kinematic_error (order {n:g})", model.with_effect(eff)))
    return out


def default_candidates() -> list[Candidate]:
    """The library's candidates, in the order they are tried."""
    from .effects import (
        CubicStiffness,
        LinearStiffness,
        StribeckFriction,
    )

    def cubic(m):
        return _has(m, "stiffness", CubicStiffness)

    return [
        Candidate(
            "backlash", cubic,
            # free play a few % of the logged swing (0.005 and 0.02 rad on a CSF-8's ±0.157)
            _library_variant("backlash", lambda v: [
                {"backlash": f * v["_swing"]} for f in (0.016, 0.064)
            ] if math.isfinite(v["_swing"]) else [{}]),
            mark="the approach to rest is too abrupt in the model — the gear coasts through a "
                 "dead zone without spring torque — and rest points spread wider than stiction "
                 "explains",
            experiment="releases from several amplitudes and a 1 kHz log resolve the coasting "
                       "through the dead zone; an added-inertia run changes the coasting time "
                       "but not the band",
        ),
        Candidate(
            "hysteresis", lambda m: not _has(m, "hysteresis"),
            _library_variant("hysteresis", lambda v: [
                {"f_h": a * _tau(v), "sigma_h": b * _k_wg(v)} for a in (0.2, 0.5) for b in (0.5, 2.0)
            ]),
            mark="after each reversal the gear decelerates more gently than Coulomb friction "
                 "allows and the rest point is pulled towards where it came from",
            experiment="releases of several amplitudes (the loop's rounded corners do not "
                       "scale with amplitude, Coulomb friction and stiffness do) and 1 kHz "
                       "sampling around the reversals",
        ),
        Candidate(
            "asymmetric_friction", lambda m: _has(m, "stribeck", StribeckFriction),
            _library_variant("asymmetric_friction", lambda v: [{"asym": -0.25}, {"asym": 0.25}]),
            mark="rest points of + and − releases sit asymmetrically and part of the residual "
                 "does not flip with the velocity",
            experiment="a known spring zero (zero-torque reading with the servo on): without "
                       "it the Coulomb part of an asymmetry is the same as an encoder offset",
        ),
        Candidate(
            "load_friction", lambda m: not _has(m, "load_friction"),
            _library_variant("load_friction", lambda v: [
                {"c_load": 0.02 * _k_wg(v)}, {"c_load": 0.1 * _k_wg(v)}
            ]),
            mark="large swings lose more amplitude per half-cycle than small ones, so a "
                 "constant friction is too weak early and too strong late",
            experiment="releases from at least three amplitudes: the decrement per half-cycle "
                       "then shows its growth with load",
        ),
        Candidate(
            "ripple", lambda m: not _has(m, "ripple"), _ripple_variants, scanned=1,
            family="position-periodic", settings=PERIODOGRAM_ORDERS,
            mark="the residual is periodic in the wave-generator angle, not in time, with the "
                 "same phase in every run",
            experiment="releases starting from different WG angles (shift the spring zero by "
                       "a fraction of the ripple period) separate a position-periodic torque "
                       "from stiffness",
        ),
        Candidate(
            "soft_windup", cubic,
            _library_variant("soft_windup", lambda v: [{}, {"K1": 0.6 * v["k1"]}] if "k1" in v
                             else [{}]),
            mark="the swing period near rest differs from the cubic model's: the phase error "
                 "grows as the amplitude decays",
            experiment="a small-amplitude release (inside the first catalog segment) measures "
                       "the centre stiffness K1 directly",
        ),
        Candidate(
            "kinematic_error", cubic, _kinematic_variants, scanned=1,
            family="position-periodic", settings=len(KINEMATIC_ORDERS),
            mark="a spring torque modulated periodically in the WG angle",
            experiment="a driven input/output test with the output encoder: free motion "
                       "barely sees the positional error",
        ),
        Candidate(
            "stiffness", lambda m: _has(m, "stiffness", LinearStiffness),
            _library_variant("stiffness"),
            mark="large first swings are faster than a linear spring allows (hardening)",
            experiment="releases at two amplitudes: the frequency then depends on amplitude",
        ),
        Candidate(
            "stribeck", lambda m: not _has(m, "stribeck"), _library_variant("stribeck"),
            mark="the residual flips with the sign of the velocity and peaks just before rest: "
                 "static friction above Coulomb is missing",
            experiment="1 kHz sampling around the reversals resolves the Stribeck rise",
        ),
        Candidate(
            "viscous", lambda m: not _has(m, "viscous"), _library_variant("viscous"),
            mark="the decay envelope is exponential rather than linear and the error grows "
                 "with speed",
            experiment="releases at several amplitudes separate viscous (∝ speed) from "
                       "Coulomb (constant) losses",
        ),
    ]


#: The catalog Stribeck shape, a second starting point for candidates when the base fit's
#: shape is far from it (see :func:`_shape_is_unusual`).
SHAPE_RESET = {"v_s": 3.0, "delta": 1.0}


def _shape_reset(values) -> dict[str, float]:
    """Catalog Stribeck shape, and tau_c/tau_s at the catalog ratio 1.5 around the base
    fit's geometric mean (a bent shape usually comes with a stretched tau_s/tau_c)."""
    out = {k: v for k, v in SHAPE_RESET.items() if k in values}
    if "tau_c" in values and "tau_s" in values:
        gm = math.sqrt(values["tau_c"] * values["tau_s"])
        out["tau_c"], out["tau_s"] = gm / math.sqrt(1.5), gm * math.sqrt(1.5)
    return out


def _shape_is_unusual(values) -> bool:
    """Stribeck shape more than a factor e from the catalog v_s or δ off by over 0.3."""
    if "v_s" not in values or "delta" not in values:
        return False
    return abs(math.log(values["v_s"] / SHAPE_RESET["v_s"])) > 1.0 or abs(values["delta"] - 1.0) > 0.3



def _ripple_orders(frame, top: int = 2) -> list[float]:
    """Orders (cycles per WG rev) of the largest peaks of the residual vs WG angle."""
    from scipy.signal import lombscargle

    mov = frame[frame["phase"] == "moving"]
    if len(mov) < 10:
        return []
    x = mov["theta_wg"].to_numpy()
    y = mov["residual_rad"].to_numpy() - mov["residual_rad"].mean()
    orders = np.arange(1, PERIODOGRAM_ORDERS + 1, dtype=float)
    # sin(n·θ) with θ in rad has angular frequency n: the order per revolution
    power = lombscargle(x, y, orders)
    picks: list[float] = []
    for i in np.argsort(power)[::-1]:
        if all(abs(orders[i] - p) > 2 for p in picks):
            picks.append(float(orders[i]))
        if len(picks) == top:
            break
    return picks


# -- scanned settings (orders) -----------------------------------------------------

#: Discrete settings (orders) refitted after the one-step screen of all of them: the
#: best ``SCAN_REFITS`` and every one whose one-step gain is within ``SCAN_TIE_DCHI2`` of
#: the best (ties: when less than a period fits the swing, low orders screen alike and
#: only the refit tells them apart), at most ``SCAN_MAX_REFITS``.
SCAN_REFITS = 3
SCAN_TIE_DCHI2 = 4.0
SCAN_MAX_REFITS = 16
#: The best-screened and the best-refitted orders (this many of each) that also get
#: the candidate's own data-driven grid starts.
SCAN_GRID = 2


def _merge(a, b):
    """One :class:`~hdid._refit.StructureFit` holding the starts of two runs of the same
    structure (the best of both is its optimum)."""
    from ._refit import StructureFit

    return StructureFit(a.label, a.setup, np.concatenate([a.U, b.U]),
                        np.concatenate([a.costs, b.costs]), np.concatenate([a.ok, b.ok]),
                        np.concatenate([a.steps, b.steps]), a.origins + b.origins,
                        a.wall_s + b.wall_s)


def _scan_refits(gains: Sequence[float]) -> int:
    """How many of the screened settings (one-step gains, best first) are refitted: the
    best ``SCAN_REFITS`` and every one within ``SCAN_TIE_DCHI2`` of the best, at most
    ``SCAN_MAX_REFITS``."""
    if not gains:
        return 0
    tied = sum(g >= gains[0] - SCAN_TIE_DCHI2 for g in gains)
    return min(max(SCAN_REFITS, tied), SCAN_MAX_REFITS, len(gains))


def _effect_of(model, key: str):
    """``model``'s effect whose library key is ``key``."""
    return next(e for e in model.effects if e.key == key)


def _reorder(s, key: str, order):
    """Set-up ``s`` with effect ``key``'s ``order`` replaced (model and problem)."""
    import equinox as eqx
    import jax.numpy as jnp

    def where(m):
        return _effect_of(m, key).order

    old = where(s.problem.base)
    problem = eqx.tree_at(lambda p: where(p.base), s.problem,
                          jnp.asarray(float(order), dtype=jnp.asarray(old).dtype))
    return s._replace(model=eqx.tree_at(where, s.model, float(order)), problem=problem)


def _scan_fits(cand, groups, setups, current, tail, grid_points, say, scans, scan_refitted):
    """The refits of a scanned candidate (for :func:`hdid._diagnose._candidate_fits`):
    every setting (order) screened by one Gauss–Newton step from the current optimum;
    the best and every tie refitted (:func:`_scan_refits`) from the current optimum, its
    step and the other bases (the catalog friction shape); the best ``SCAN_GRID`` by
    screen and by refit also from the base grid's points (``grid_points``). The screen
    goes to ``scans``, the refitted settings to ``scan_refitted``."""
    from . import _refit

    fits = []
    gains = {}
    for label, models in groups.items():
        s = setups[label]
        u0 = _refit.warm(s, models[0].float_values(), tail)
        added = [n for n in s.problem.free if n not in current.setup.problem.free]
        gains[label] = (*_refit.gauss_newton_step(s, u0, added), u0)
    order = sorted(gains, key=lambda lb: -gains[lb][0])
    chosen = _scan_refits([gains[lb][0] for lb in order])
    scans[cand.key] = {lb: gains[lb][0] for lb in order}
    scan_refitted.setdefault(cand.key, [])
    say(f"  + {cand.key}: {len(order)} orders screened, {chosen} refitted")
    for label in order[:chosen]:
        gain, step, u0 = gains[label]
        s = setups[label]
        starts = [("warm", u0), ("gauss-newton", u0 + step)]
        # the other bases (the catalog friction shape where the current fit's is
        # unusual: a current optimum in a poor basin is a poor start for the
        # candidate too), the effect at the step's values
        stepped, *_ = s.problem.unpack_np(u0 + step)
        new = {k: float(v) for k, v in stepped.items()
               if k not in current.setup.problem.free}
        starts += [("shape_reset", _refit.warm(s, {**m.float_values(), **new}, tail))
                   for m in groups[label][1:]]
        fits.append(_refit.run(label, s, starts))
        if label not in scan_refitted[cand.key]:
            scan_refitted[cand.key].append(label)
    if grid_points:
        # The current optimum may be a poor basin, and every start near it stays
        # there (seed 8905: 2.3× the floor, the base grid's points: 0.86×): the
        # best-screened and the best-refitted orders also start from the base grid's
        # points with the effect at zero, as many as the other candidates get (no
        # program of its own: the candidate's own grid would compile one).
        by_cost = [f.label for f in sorted((f for f in fits if f.finite),
                                           key=lambda f: f.cost)]
        pick = list(dict.fromkeys(order[:SCAN_GRID] + by_cost[:SCAN_GRID]))
        for label in pick:
            i = next(j for j, f in enumerate(fits) if f.label == label)
            s = fits[i].setup
            first = groups[label][0].float_values()
            starts = [("grid", _refit.warm(s, {**first, **v}, t)) for v, t in grid_points]
            say(f"  + {label}  ({len(starts)} grid starts)")
            fits[i] = _merge(fits[i], _refit.run(label, s, starts))
    return fits


def _order(label: str) -> str:
    return label.split("order ")[-1].rstrip(")")


def _scan_note(key: str, table: dict[str, float], refitted: list[str]) -> str:
    """The scanned set, each order's one-step gain and which orders were refitted."""
    nums = sorted(float(_order(lb)) for lb in table)
    ints = [n for n in nums if n == int(n)]
    runs, start = [], None
    for i, n in enumerate(ints):  # consecutive integers as ranges: "1–48, 98, 101"
        if start is None:
            start = n
        if i + 1 == len(ints) or ints[i + 1] != n + 1:
            runs.append(f"{start:g}" if start == n else f"{start:g}–{n:g}")
            start = None
    runs += [f"{n:g}" for n in nums if n != int(n)]
    gains = ", ".join(f"{_order(lb)}: {g:.0f}" for lb, g in table.items())
    return (f"{key}: orders scanned {', '.join(runs)} ({len(table)}; one-step Δχ², best "
            f"first: {gains}); refitted (the best {SCAN_REFITS} and every one within "
            f"{SCAN_TIE_DCHI2:g} of the best, at most {SCAN_MAX_REFITS}): "
            f"{', '.join(_order(lb) for lb in refitted)}")
