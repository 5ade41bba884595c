"""What :func:`hdid.diagnose` returns: :class:`Diagnosis` (verdict, ranked candidates,
model ladder, warnings, the measured false-alarm rate; its report and ladder plot) and
:class:`CandidateResult`."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ._excess import floor_text


@dataclass
class CandidateResult:
    key: str
    label: str
    rms_before_rad: float
    rms_after_rad: float
    delta_bic: float
    n_added: int
    adequate_after: bool | None
    reason: str
    values: dict[str, float]
    result: Any = field(default=None, repr=False)
    error: str | None = None
    #: the refit (all its starts); ``result`` is its analysed FitResult when inspected
    fit: Any = field(default=None, repr=False)
    white_after: bool | None = None
    moving_ratio_after: float = math.nan
    #: the refit's χ² over the *base* fit's rounding floor F (:mod:`._excess`)
    chi2_over_floor: float = math.nan
    #: below the floor, the evidence for the round's best over this candidate: the BIC
    #: gap plus the rounding's ``2·ln LR`` (:mod:`._rival`; NaN where not computed)
    floor_gap: float = math.nan
    #: below the floor, this candidate's fit against the best's under the rounding alone
    #: (:meth:`hdid._diagnosis._rival.Evidence.to_dict`; ``None`` where not compared)
    floor_evidence: dict[str, Any] | None = None

    def to_dict(self) -> dict[str, Any]:
        from .._results._saved import finite

        return finite({
            "effect": self.key,
            "variant": self.label,
            "rms_before_rad": self.rms_before_rad,
            "rms_after_rad": self.rms_after_rad,
            "delta_bic": self.delta_bic,
            "parameters_added": self.n_added,
            "residual_adequate_after": self.adequate_after,
            "residual_white_after": self.white_after,
            "moving_rms_after_floors": self.moving_ratio_after,
            "chi2_over_floor": self.chi2_over_floor,
            **({"floor_evidence": self.floor_evidence} if self.floor_evidence else {}),
            "fitted": self.values,
            "reason": self.reason,
            **({"error": self.error} if self.error else {}),
        })


@dataclass
class Diagnosis:
    """Outcome of :func:`diagnose`: a verdict, the ranked candidates and the model ladder."""

    source: str
    verdict: str
    summary: str
    base: Any
    candidates: list[CandidateResult]
    whiteness_before: Any
    notes: list[str]
    ladder: list[dict[str, Any]]
    floor_rad: float
    #: wall seconds: total, compile (JAX tracing/compiling or cache reads) and run; CPU
    #: seconds of the process (all threads), less sensitive to other jobs
    timing: dict[str, float] = field(default_factory=dict)
    #: discrete settings scanned per candidate (labels, best one-step gain first)
    scanned: dict[str, list[str]] = field(default_factory=dict)
    #: of those, the ones refitted to convergence (screen ties included), per candidate
    refitted: dict[str, list[str]] = field(default_factory=dict)
    #: why the verdict may not be trustworthy (empty when nothing is known against it)
    warnings: list[str] = field(default_factory=list)
    #: the verdict rules' measured false-alarm rate on clean logs of the nearest design
    #: (:mod:`hdid._diagnosis._rates`), ``None`` when none was measured near this log's
    false_alarm: dict[str, Any] | None = None
    #: the base fit's χ² against the rounding floor a correct model leaves on this log
    #: (:meth:`hdid._diagnosis._excess.FloorCheck.to_dict`), ``None`` where not computed
    rounding_floor: dict[str, Any] | None = None

    @property
    def best(self) -> CandidateResult | None:
        return self.candidates[0] if self.candidates else None

    def to_dict(self) -> dict[str, Any]:
        from .._results._saved import finite

        return finite({
            "units_problem": getattr(self.base, "units_problem", None),
            "source": self.source,
            "verdict": self.verdict,
            "summary": self.summary,
            "quantization_floor_rad": self.floor_rad,
            "base_model": list(self.base.model.effect_names),
            "base_rms_rad": self.base.rms_residual_rad,
            "whiteness_before": self.whiteness_before.to_dict(),
            "candidates": [c.to_dict() for c in self.candidates],
            "ladder": self.ladder,
            "notes": self.notes,
            "scanned": self.scanned,
            "refitted": self.refitted,
            "warnings": self.warnings,
            "false_alarm": self.false_alarm,
            "rounding_floor": self.rounding_floor,
            "timing": self.timing,
        })

    def report(self) -> str:
        fl = self.floor_rad
        w = self.whiteness_before
        units = getattr(self.base, "units_problem", None)  # a wrong unit leads the report
        lines = [
            *([units.upper()[:6] + units[6:]] if units else []),
            f"[[diagnosis]] {self.source}",
            f"    verdict: {self.verdict} — {self.summary}",
            f"    base model: {' + '.join(self.base.model.effect_names)}; RMS "
            f"{self.base.rms_residual_rad / fl:.2f}× the quantization floor "
            f"({fl:.2e} rad); moving residual {w.rms_ratio:.2f}× floor, Ljung–Box p = "
            f"{w.p_value:.2g}",
            *([f"    {floor_text(self.rounding_floor)}"] if self.rounding_floor else []),
            *([f"    rules' {_false_alarm_text(self.false_alarm)}"] if self.false_alarm else []),
            "[[candidates]] (best first; ΔBIC < −10 is strong evidence; χ²/F against the "
            "base's F)",
            f"    {'effect':22s} {'RMS before':>11s} {'RMS after':>10s} {'ΔBIC':>9s} "
            f"{'χ²/F':>6s}  fixes it",
        ]
        for c in self.candidates:
            if c.error:
                lines.append(f"    {c.label:22s} failed: {c.error}")
                continue
            fixes = {True: "yes", False: "no", None: "—"}[c.adequate_after]
            lines.append(
                f"    {c.label:22s} {c.rms_before_rad / fl:10.2f}× {c.rms_after_rad / fl:9.2f}× "
                f"{c.delta_bic:9.1f} {c.chi2_over_floor:6.2f}  {fixes}"
            )
        if self.best is not None and not self.best.error:
            lines += ["[[why]]", "    " + self.best.reason]
        if self.ladder:
            lines.append("[[model ladder]]")
            for step in self.ladder:
                lines.append(
                    f"    {step['model']:45s} RMS {step['rms_rad'] / fl:5.2f}× floor  "
                    f"BIC {step['bic']:9.1f}"
                )
        if self.warnings:
            lines.append("[[warnings]]")
            lines += [f"    - {n}" for n in self.warnings]
        if self.notes:
            lines.append("[[notes]]")
            lines += [f"    - {n}" for n in self.notes]
        if self.timing:
            t = self.timing
            progs = (f" ({t['programs_stored']:.0f} of {t['programs']:.0f} programs read from "
                     "the store, the rest traced here)" if t.get("programs") else "")
            if t.get("programs_prefetched"):
                progs += (f"; {t['programs_prefetched']:.0f} read in the background while "
                          f"fitting ({t['compile_background_s']:.1f} s, only the wait counted)")
            lines += ["[[timing]]",
                      f"    {t['total_s']:.1f} s: compiling/loading programs {t['compile_s']:.1f} s"
                      f"{progs}, fitting {t['run_s']:.1f} s (CPU {t['cpu_s']:.1f} s)"]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.report()

    def plot_ladder(self, *, ax=None):
        """RMS (in quantization floors) and BIC along the model ladder: the error falling.
        Draws into ``ax`` (a new figure without it) and returns the Axes."""
        from .._results._plot import new_figure

        if ax is None:
            ax = new_figure(figsize=(6, 3.5), constrained_layout=True).subplots()
        names = [s["model"] for s in self.ladder]
        rms = [s["rms_rad"] / self.floor_rad for s in self.ladder]
        x = np.arange(len(names))
        bars = ax.bar(x, rms, color="C0", alpha=0.8, label="RMS residual")
        ax.axhline(1.0, color="0.3", ls="--", lw=1, label="quantization floor")
        for b, step in zip(bars, self.ladder):
            ax.annotate(f"BIC {step['bic']:.0f}", (b.get_x() + b.get_width() / 2, b.get_height()),
                        ha="center", va="bottom", fontsize=8)
        ax.set_xticks(x, names, rotation=15, ha="right", fontsize=8)
        ax.set_ylabel("RMS / quantization floor")
        ax.set_ylim(0, 1.15 * max(max(rms), 1.0))
        ax.legend(loc="upper right", fontsize=8)
        ax.set_title("model ladder")
        return ax


def _false_alarm_text(fa: dict[str, Any]) -> str:
    lo, hi = fa["interval_95"]
    return (f"false alarms on clean logs of the {fa['design']} design ({fa['rate_hz']:g} Hz, "
            f"{fa['runs']} runs): {fa['false_alarms']} of {fa['clean_logs']} (95 % interval "
            f"{100 * lo:.1f}–{100 * hi:.1f} %)")
