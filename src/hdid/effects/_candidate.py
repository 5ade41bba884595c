"""How ``hdid diagnose`` tries an effect, declared by the effect itself.

An effect that ``diagnose`` should try sets the class variable ``candidate`` to a
:class:`Candidate`: where it comes in the trial order, which model it applies to, the
data-derived starting values of its new parameters, the orders it scans (a periodic
effect), and the plain-language mark it leaves and the experiment that separates it from
its look-alikes. ``hdid.diagnose`` reads the candidates from the registry
(:func:`candidates`), so a new library file or an installed plugin is tried with no other
edit. An effect without a ``candidate`` is not tried (it can still be ``--add``-ed).

The functions here work on the duck-typed model (``effects``, ``effect_names``,
``with_effect``, ``ratio``, ``rest_torque``) and on the fitted values: this module is
below the model layer and imports nothing above ``effects``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

#: Orders (cycles per WG revolution) a position-periodic candidate scans: every integer
#: order 1 … ``MAX_ORDER`` — low orders (less than one period over the swing, still
#: identifiable against a smooth stiffness bend when the data say so), the WG mesh (2, 4),
#: motor pole/slot cogging orders and anything between. No order is skipped by a rule of
#: thumb: ``diagnose`` screens every one by the fit itself (one Gauss–Newton step: the
#: score statistic) and refits the ties, so the order is decided by the fit.
MAX_ORDER = 48
ORDERS = tuple(float(n) for n in range(1, MAX_ORDER + 1))
#: The residual periodogram against the WG angle searches integer orders 1 … this for
#: peaks (a candidate with ``periodogram=True`` adds its two largest): with ``ORDERS``
#: inside that range the order is chosen from this many settings.
PERIODOGRAM_ORDERS = 120


@dataclass(frozen=True)
class Candidate:
    """One thing ``diagnose`` can try: a registry effect and how to add it.

    Declared on the effect class (``candidate: ClassVar[Candidate] = Candidate(...)``);
    :func:`candidates` fills in ``key`` from the effect.

    Attributes
    ----------
    trial:
        Place in the trial order (lower first; ties by key). The library's run 10 … 100;
        a plugin picks its own.
    mark:
        The mark the effect leaves in residuals (plain language).
    experiment:
        The experiment that separates it from its look-alikes.
    replaces:
        The registry key of the effect this one replaces: the candidate applies only to a
        model whose effect in the same slot (``name``) is exactly of that key's class (free
        play replaces a plain cubic spring, ``"stiffness"``). ``None``: it applies to a
        model with nothing in its slot.
    starts:
        ``starts(values) -> [overrides, ...]``: several data-derived starting values for
        the new parameters (a multi-start, not a model choice: the best is kept and no
        parameter is charged for it). ``values`` are the fitted model's, plus ``_k_wg``
        (its small-swing restoring stiffness at the WG, N m/rad) and ``_swing`` (the
        logged swing, rad, NaN if unknown).
    orders:
        Orders scanned for the effect's ``order`` field (a position-periodic torque):
        each is a variant, the scan counts as one parameter in the BIC.
    periodogram:
        Also scan the residual periodogram's largest peaks (``hints["ripple_orders"]``).
    settings:
        How many discrete settings the scan chooses from (M): choosing the best of M costs
        ``2·ln M`` on the BIC's −2·ln L scale.
    family:
        Candidates of one family leave the same mark: a tie between them is no ambiguity
        about the physics, only about its form ("" = a family of its own).
    reset_shape:
        Also start from the catalog Stribeck shape when the current fit's is unusual.
    key:
        The effect's registry key (the ``--add`` name), set by :func:`candidates`.
    """

    trial: int
    mark: str
    experiment: str
    replaces: str | None = None
    starts: Callable[[dict[str, float]], list[dict[str, float]]] | None = None
    orders: tuple[float, ...] = ()
    periodogram: bool = False
    settings: int = 1
    family: str = ""
    reset_shape: bool = True
    key: str = ""
    effect: type | None = dataclasses.field(default=None, repr=False, compare=False)

    @property
    def scanned(self) -> int:
        """Discrete settings scanned (the order), counted as parameters in the BIC."""
        return 1 if self.orders else 0

    def penalty(self, n: float) -> float:
        """BIC cost of the scanned settings: ``scanned·ln n + 2·ln M``."""
        return self.scanned * math.log(n) + 2.0 * math.log(max(self.settings, 1))

    def applies(self, model) -> bool:
        """Whether trying the effect on ``model`` is meaningful."""
        slot = self.effect.name
        held = next((e for e in model.effects if e.name == slot), None)
        if self.replaces is None:
            return held is None
        from ._registry import registry

        return type(held) is registry()[self.replaces]

    def variants(self, model, values: dict[str, float], hints: dict[str, Any]):
        """``[(label, model), ...]``: the models to fit — one per starting value, or one
        per scanned order."""
        from ._registry import registry  # not the package's namespace: no cycle

        start = registry()[self.key].start_from  # what library(values)[key] is

        if self.orders:
            orders = list(self.orders)
            if self.periodogram:
                for n in hints.get("ripple_orders") or []:
                    if all(abs(n - o) > 0.5 for o in orders):
                        orders.append(float(n))
            return [(f"{self.key} (order {n:g})",
                     model.with_effect(start({**values, "order": float(n)})))
                    for n in orders]
        values = {**values, "_k_wg": model_k_wg(model, values, hints),
                  "_swing": hints.get("swing_rad", math.nan)}
        overrides = self.starts(values) if self.starts is not None else [{}]
        return [(self.key, model.with_effect(start({**values, **o})))
                for o in overrides]


def model_k_wg(model, values, hints) -> float:
    """The fitted model's small-swing restoring stiffness at the logged axis [N m/rad]:
    ``k1/N²`` for a cubic spring, else the secant of its rest torque over a tenth of the
    logged swing (a gravity pendulum, segments) — never a catalog number."""
    if "k1" in values:
        return float(values["k1"]) / model.ratio**2
    swing = hints.get("swing_rad", math.nan)
    probe = 0.1 * swing if math.isfinite(swing) and swing > 0 else 1e-3
    return max(float(model.rest_torque(probe)) / -probe, 0.0)


def friction_level(values) -> float:
    """The fitted Coulomb level, or 2 % of the spring torque over the swing [N m]."""
    if "tau_c" in values:
        return values["tau_c"]
    swing = values.get("_swing", math.nan)
    return 0.02 * values["_k_wg"] * (swing if math.isfinite(swing) else 1.0)


def candidates(registry: dict[str, type]) -> list[Candidate]:
    """The candidates the effects of ``registry`` (key → class) declare, in trial order."""
    out = [dataclasses.replace(cls.candidate, key=key, effect=cls)
           for key, cls in registry.items() if getattr(cls, "candidate", None) is not None]
    return sorted(out, key=lambda c: (c.trial, c.key))


__all__: Sequence[str] = ("Candidate", "candidates", "friction_level", "model_k_wg",
                          "MAX_ORDER", "ORDERS", "PERIODOGRAM_ORDERS")
