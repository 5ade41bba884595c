"""The candidates of :func:`hdid.diagnose`: the effects of the registry that declare a
:class:`~hdid.effects.Candidate` (``effects/<key>.py``: trial order, data-derived starts,
scanned orders, residual mark, separating experiment), the catalog-shape restart, the
residual periodogram that proposes ripple orders, the variants' set-ups and the order scan's
machinery. (See
:mod:`hdid._diagnosis._diagnose` for how they are refitted and judged.)"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from ..effects._candidate import MAX_ORDER, ORDERS, PERIODOGRAM_ORDERS, Candidate  # noqa: F401

#: Orders scanned for a position-periodic torque (``ripple``: also the residual
#: periodogram's two largest peaks) and for the kinematic error: every integer order
#: 1 … ``MAX_ORDER``, declared by the effects (:data:`hdid.effects._candidate.ORDERS`).
RIPPLE_ORDERS = ORDERS
KINEMATIC_ORDERS = ORDERS


def default_candidates() -> list[Candidate]:
    """The candidates the registry's effects declare (the library's files and installed
    plugins'), in their declared trial order."""
    from ..effects._candidate import candidates
    from ..effects._registry import registry

    return candidates(registry())


def _variants_of(key: str):
    cand = next(c for c in default_candidates() if c.key == key)
    return cand.variants


def _ripple_variants(model, values, hints):
    """The ripple candidate's variants (one per scanned order)."""
    return _variants_of("ripple")(model, values, hints)


def _kinematic_variants(model, values, hints):
    """The kinematic-error candidate's variants (one per scanned order)."""
    return _variants_of("kinematic_error")(model, values, hints)


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
    """One :class:`~hdid._fitting._refit.StructureFit` holding the starts of two runs of the same
    structure (the best of both is its optimum)."""
    from .._fitting._refit import StructureFit

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
    """The refits of a scanned candidate (for :func:`hdid._diagnosis._refits._candidate_fits`):
    every setting (order) screened by one Gauss–Newton step from the current optimum;
    the best and every tie refitted (:func:`_scan_refits`) from the current optimum, its
    step and the other bases (the catalog friction shape); the best ``SCAN_GRID`` by
    screen and by refit also from the base grid's points (``grid_points``). The screen
    goes to ``scans``, the refitted settings to ``scan_refitted``."""
    from .._fitting import _refit

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


def _at_optimum(model, values):
    """``model`` with every parameter it has at ``values`` (a fit's optimum)."""
    own = model.float_values()
    return model.replace(**{k: v for k, v in values.items() if k in own})


def _candidate_setups(log, cand, current, hints, opts):
    """The variants of ``cand`` built on ``current`` at its optimum (grouped by label) and
    one least-squares set-up per group: ``(groups, setups)``."""
    from .._fitting import _refit

    values = current.values()
    # The current model *at its optimum*: ``current.model`` is the model the refit was
    # set up with (its starting values, e.g. the catalog's), and a variant built on it
    # would start every shared parameter there — not from the current optimum.
    fitted = _at_optimum(current.model, values)
    bases = [(fitted, values)]
    if cand.reset_shape and _shape_is_unusual(values):
        reset = _shape_reset(values)
        bases.append((fitted.replace(**reset), {**values, **reset}))
    groups: dict[str, list] = {}
    for m0, v0 in bases:
        for label, m in cand.variants(m0, v0, hints):
            groups.setdefault(label, []).append(m)
    setups = {}
    for label, models in groups.items():
        if cand.scanned and setups:
            # the settings differ only in the order, a traced value: one set-up, the
            # order replaced (the same problem, leaf for leaf; ~27 ms of set-up each)
            setups[label] = _reorder(next(iter(setups.values())), cand.key,
                                     _effect_of(models[0], cand.key).order)
        else:
            setups[label] = _refit.setup(log, models[0], opts)
    return groups, setups
