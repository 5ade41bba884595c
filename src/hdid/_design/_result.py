"""The outcome of :func:`hdid.design`: ranking, predicted standard errors, the check."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from ._check import CheckResult
from ._fisher import Prediction
from ._rank import std_of

#: Version of the JSON layout (``hdid/schema/design.schema.json``).
SCHEMA_VERSION = 1


@dataclass
class DesignResult:
    """Candidate experiments ranked by the predicted standard errors they would give.

    ``predictions[0]`` is the log's own design (the reference of every ratio);
    ``ranking`` lists ``(candidate index, score)`` best first, the score being
    ``ln`` of the geometric-mean std ratio to this log (:mod:`hdid._design._rank`).
    """

    source: str
    criterion: str
    targets: tuple[str, ...]
    values: dict[str, float]
    derived: dict[str, float]
    predictions: list[Prediction]
    ranking: list[tuple[int, float]]
    noise_rad: float
    check: CheckResult | None = None
    warnings: list[str] = field(default_factory=list)
    wall_time_s: float = math.nan

    # -- access -------------------------------------------------------------------
    @property
    def best(self) -> Prediction:
        """The top-ranked candidate's prediction."""
        return self.predictions[self.ranking[0][0]]

    @property
    def current(self) -> Prediction:
        return self.predictions[0]

    def quantities(self) -> list[str]:
        """Parameters (every candidate's), then derived quantities, reported."""
        names = list(dict.fromkeys(n for p in self.predictions for n in p.names))
        return names + [k for k in self.derived if not k.startswith("stick_band_lower")
                        and not k.startswith("stick_band_upper")]

    def shown(self) -> list[str]:
        """What the table and plot show: the targets, else the free parameters and band."""
        if self.targets:
            return list(self.targets)
        return list(self.current.names) + ["stick_band_halfwidth_rad"]

    def relative(self, i: int, name: str) -> float:
        """Predicted std of candidate ``i`` over this log's."""
        a, b = std_of(self.predictions[i], name), std_of(self.current, name)
        if not math.isfinite(b):
            return 0.0 if math.isfinite(a) else math.nan
        return a / b if b > 0 else math.nan

    # -- output -------------------------------------------------------------------
    def report(self) -> str:
        shown = self.shown()
        crit = {"targets": "geometric mean of the std ratios of " + ", ".join(self.targets),
                "d": "D-optimality (confidence-volume ratio as a geometric-mean std ratio)",
                "separate": "the expected 2 ln LR between the two rival fits (the smaller "
                            "direction; score column: the rival fitted globally by hdid.fit "
                            "where marked '=', else refitted locally, an upper bound '<=': "
                            "the values first), std ratios"
                }[self.criterion]
        lines = [f"hdid design: {self.source}", "",
                 f"ranking by {crit}, relative to this log (1 = as now, < 1 better):"]
        width = max(len(self.predictions[i].experiment.name) for i, _ in self.ranking)
        head = f"{'#':>3}  {'candidate':<{width}}  {'runs':>4}  {'rate':>6}  {'counts':>6}  {'score':>7}"
        head += "".join(f"  {_short(n):>10}" for n in shown)
        lines.append(head)
        for k, (i, s) in enumerate(self.ranking, 1):
            p = self.predictions[i]
            e = p.experiment
            if p.error:
                lines.append(f"{k:>3}  {e.name:<{width}}  {e.n_runs:>4}  not evaluated: {p.error}")
                continue
            row = (f"{k:>3}  {e.name:<{width}}  {e.n_runs:>4}  {e.rate:>6.0f}  "
                   f"{e.counts_per_rev:>6.0f}  {self._score_text(s, p):>7}")
            row += "".join(f"  {_ratio(self.relative(i, n)):>10}" for n in shown)
            lines.append(row + ("  !" if p.honesty else ""))
        best = self.best
        lines += ["", f"top candidate: {best.experiment.name} — {best.experiment.describe()}",
                  f"  {best.experiment.note}", "",
                  f"{'quantity':<26} {'value':>11} {'std now':>10} {'std top':>10} {'ratio':>7}"
                  f" {'top/prior':>9}"]
        for n in self.quantities():
            v = self.values.get(n, self.derived.get(n, math.nan))
            a, b = std_of(self.current, n), std_of(best, n)
            pr = best.prior_ratio.get(n)
            lines.append(f"{n:<26} {v:>11.5g} {_num(a):>10} {_num(b):>10} "
                         f"{_ratio(b / a if a > 0 and math.isfinite(a) else math.nan):>7} "
                         f"{'' if pr is None else f'{pr:.2f}':>9}")
        lines += ["", f"noise: the encoder's rounding (step/sqrt 12) plus {self.noise_rad:.3g} rad "
                  "beyond it (from this fit's residual)"]
        for label, p in (("this log", self.current), ("the top candidate", best)):
            if p.honesty:
                lines.append(f"linearisation not honest for {label} (its std is not the "
                             "fits' spread): " + _summary(p.honesty))
        if self.check is not None:
            lines += ["", *self._check_lines()]
        if self.warnings:
            lines += ["", "warnings:", *[f"  - {w}" for w in self.warnings]]
        return "\n".join(lines)

    def _score_text(self, s: float, p: Prediction | None = None) -> str:
        if self.criterion == "separate":
            mark = {"rival fitted globally": "=", "upper bound": "<="}.get(
                getattr(p, "separation_kind", None), "")
            return mark + _num(-s) if math.isfinite(s) else "n/a"
        return _ratio(math.exp(s) if math.isfinite(s) else s)

    def _check_lines(self) -> list[str]:
        c = self.check
        out = [f"check: {c.n_fitted} of {c.n_logs} simulated logs of {c.experiment!r} fitted "
               f"({c.seconds:.0f} s); a spread of {c.n_fitted} fits is itself uncertain by "
               f"±{100 * c.relative_se:.0f} %",
               f"{'quantity':<26} {'truth':>11} {'mean fit':>11} {'spread':>10} {'predicted':>10} "
               f"{'pred/spread':>11}"]
        for n in c.predicted:
            out.append(f"{n:<26} {c.truth.get(n, math.nan):>11.5g} {c.mean.get(n, math.nan):>11.5g} "
                       f"{_num(c.spread.get(n, math.nan)):>10} {_num(c.predicted[n]):>10} "
                       f"{_ratio(c.ratio(n)):>11}")
        if c.above_floor:
            out.append(f"  {c.above_floor} fit(s) ended above 3x the quantization floor (a "
                       "poorer basin): the spread includes them")
        out += [f"  failed: {f}" for f in c.failures[:5]]
        return out

    def __str__(self) -> str:
        return self.report()

    def to_dict(self) -> dict[str, Any]:
        """Strict JSON (no NaN/inf: ``null``, each listed in ``non_finite``); schema
        ``hdid/schema/design.schema.json``."""
        from .._results._saved import finite, hdid_version
        from ._saved import non_finite

        def pred(i, p: Prediction):
            return {
                "experiment": p.experiment.to_dict(),
                "error": p.error,
                "n_effective": p.n_effective,
                "noise_rad": p.sigma,
                "std": dict(p.std),
                "std_data_only": dict(p.std_data),
                "posterior_over_prior": dict(p.prior_ratio),
                "derived_std": dict(p.derived_std),
                "relative_to_this_log": {n: self.relative(i, n) for n in self.quantities()},
                "linearisation": list(p.honesty),
                "expected_2lnlr": None if p.separation is None else {
                    "a_true": p.separation[0], "b_true": p.separation[1],
                    "value_kind": p.separation_kind},
            }

        d = {
            "schema_version": SCHEMA_VERSION,
            "kind": "design",
            "hdid_version": hdid_version(),
            "source": self.source,
            "criterion": self.criterion,
            "targets": list(self.targets),
            "values": dict(self.values),
            "derived": dict(self.derived),
            "noise_beyond_quantization_rad": self.noise_rad,
            "ranking": [{"rank": k, "candidate": self.predictions[i].experiment.name,
                         "index": i, "score": s} for k, (i, s) in enumerate(self.ranking, 1)],
            "candidates": [pred(i, p) for i, p in enumerate(self.predictions)],
            "check": None if self.check is None else self.check.to_dict(),
            "warnings": list(self.warnings),
            "wall_time_s": self.wall_time_s,
        }
        d["non_finite"] = non_finite(d)  # which null is NaN, inf or -inf: load restores it
        return finite(d)

    def save(self, path) -> None:
        """Write :meth:`to_dict` as JSON (what ``hdid design --json`` writes)."""
        from ._saved import save

        save(self, path)

    @classmethod
    def load(cls, path) -> DesignResult:
        """Read a result written by :meth:`save` or ``hdid design --json``: the same report,
        JSON and plot (the ranking, every candidate's predicted stds, the check). A file of
        another kind, an incomplete one or one of a newer layout is refused in one line
        naming the file and the fix."""
        from ._saved import load

        return load(path, cls, SCHEMA_VERSION)

    def plot(self, *, ax=None):
        """Predicted std of each candidate relative to this log's (log scale), one row of
        bars per candidate in rank order, one bar per shown quantity. Returns the axes;
        never saves and never chooses a backend."""
        if ax is None:
            import matplotlib.pyplot as plt

            _, ax = plt.subplots(figsize=(7.0, 0.35 * len(self.ranking) + 1.5))
        shown = self.shown()
        order = [i for i, _ in self.ranking if self.predictions[i].error is None]
        h = 0.8 / max(len(shown), 1)
        for j, n in enumerate(shown):
            ys = [k + (j - (len(shown) - 1) / 2) * h for k in range(len(order))]
            xs = [self.relative(i, n) for i in order]
            xs = [x if math.isfinite(x) and x > 0 else math.nan for x in xs]
            ax.barh(ys, xs, height=h, left=0, label=_short(n))
        ax.set_xscale("log")
        ax.axvline(1.0, color="k", lw=0.8)
        ax.set_yticks(range(len(order)))
        ax.set_yticklabels([self.predictions[i].experiment.name for i in order])
        ax.invert_yaxis()
        ax.set_xlabel("predicted std relative to this log")
        ax.legend(fontsize="small", loc="best")
        return ax


def _summary(lines: list[str]) -> str:
    """The honesty lines grouped by cause: ``stops change at ±2 std of k1, tau_c; …``."""
    causes = {"a stop changes": "a stop changes within ±2 std of",
              "curved": "the readings are curved within ±2 std of",
              "log-normal": "log-normal spread (std > 30 % of the value) of",
              "leaves its range": "±2 std leaves the range of"}
    groups: dict[str, list[str]] = {}
    for line in lines:
        name = line.split(":", 1)[0]
        key = next((k for k in causes if k in line), None)
        groups.setdefault(causes[key] if key else line, []).append(name if key else "")
    return "; ".join(f"{c} {', '.join(dict.fromkeys(n))}".strip() for c, n in groups.items())


def _short(name: str) -> str:
    return {"stick_band_halfwidth_rad": "band", "natural_frequency_hz": "f_n"}.get(name, name)


def _num(x: float) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    if math.isinf(x):
        return "undet."
    return f"{x:.3g}"


#: ratios print as numbers do
_ratio = _num
