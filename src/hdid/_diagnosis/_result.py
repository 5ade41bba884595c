"""What :func:`hdid.diagnose` returns: :class:`Diagnosis` (verdict, ranked candidates,
model ladder, warnings, the measured false-alarm rate; its report, JSON, file and plots)
and :class:`CandidateResult`.

A diagnosis saved (:meth:`Diagnosis.save`, or ``hdid diagnose --json``) and read back
(:meth:`Diagnosis.load`) has the same report and JSON; what needs the refits themselves
(``CandidateResult.fit``/``result``, the base fit's residuals) stays behind: the base fit
comes back as :class:`SavedBase` (its model, RMS and units check)."""

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

    @classmethod
    def from_dict(cls, d: dict[str, Any]) -> CandidateResult:
        """The candidate :meth:`to_dict` wrote (without its refit; ``floor_gap`` NaN)."""
        return cls(
            key=d["effect"], label=d["variant"], rms_before_rad=_num(d["rms_before_rad"]),
            rms_after_rad=_num(d["rms_after_rad"]), delta_bic=_num(d["delta_bic"]),
            n_added=int(d["parameters_added"]), adequate_after=d["residual_adequate_after"],
            reason=d["reason"], values={k: _num(v) for k, v in d["fitted"].items()},
            error=d.get("error"), white_after=d.get("residual_white_after"),
            moving_ratio_after=_num(d.get("moving_rms_after_floors")),
            chi2_over_floor=_num(d.get("chi2_over_floor")),
            floor_evidence=d.get("floor_evidence"),
        )


@dataclass
class SavedBase:
    """The base fit of a loaded :class:`Diagnosis`: what its report and JSON name (the
    model, the RMS residual, the units check), and the provenance fields the file had."""

    source: str
    model: Any
    rms_residual_rad: float
    units_problem: str | None
    provenance: dict[str, Any] = field(default_factory=dict, repr=False)


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
    #: for an ``ambiguous`` verdict (the best against each rival) and a same-mark pair,
    #: the experiment that separates the two forms, computed by :mod:`hdid._design` with
    #: its expected ``2·ln LR`` (:func:`hdid._diagnosis._separating.separating`)
    separating_experiments: list[dict[str, Any]] = field(default_factory=list)
    #: the nesting rule applied (:mod:`hdid._diagnosis._nesting`): a richer form that
    #: reached the floor only at its corner that is the named, simpler form
    nested: list[dict[str, Any]] = field(default_factory=list)

    @property
    def best(self) -> CandidateResult | None:
        return self.candidates[0] if self.candidates else None

    def _provenance(self) -> dict[str, Any]:
        """The fit JSON's reuse fields of the base fit (version, input and its SHA-256,
        options, model, correlation, covariance): as loaded, or from the base fit."""
        if isinstance(self.base, SavedBase):
            return dict(self.base.provenance)
        from .._results._saved import provenance

        return provenance(self.base)

    def save(self, path) -> None:
        """Write the diagnosis as JSON (what ``hdid diagnose --json`` writes; schema in
        ``hdid/schema/diagnose.schema.json``). :meth:`load` reads it back."""
        import json
        from pathlib import Path

        from .._results._saved import finite

        d = {**self._provenance(), **self.to_dict()}
        Path(path).write_text(json.dumps(finite(d), indent=2) + "\n")

    @classmethod
    def load(cls, path, *, effects: dict | None = None) -> Diagnosis:
        """Read a diagnosis written by :meth:`save` or ``hdid diagnose --json``: the same
        :meth:`report`, :meth:`to_dict` and :meth:`plot`. The refits do not come back (the
        base fit is a :class:`SavedBase`). ``effects`` maps class names to your own effect
        classes (those not in hdid), as for :meth:`hdid.FitResult.load`."""
        from .._results._saved import load_complete

        return load_complete(path, lambda: _load(path, effects, cls), "diagnosis",
                             "hdid diagnose LOG.csv --json or Diagnosis.save")

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
            "separating_experiments": self.separating_experiments,
            **({"nested": self.nested} if self.nested else {}),
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
        if self.separating_experiments:
            lines.append("[[separating experiments]]")
            lines += [f"    - {x['text']}" for x in self.separating_experiments]
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

    def plot(self, *, ax=None):
        """The candidates at one glance: each one's residual RMS after its refit, in
        quantization floors (``step/√12``), with its ΔBIC against the base model written
        beside it; the base model's RMS and the floor as lines. Draws into ``ax`` (a new
        figure without it) and returns the Axes; never saves or picks a backend."""
        from .._results._plot import new_figure

        if ax is None:
            ax = new_figure(figsize=(6, 0.5 * len(self.candidates) + 2),
                            constrained_layout=True).subplots()
        fl = self.floor_rad
        shown = [c for c in self.candidates if not c.error]
        y = np.arange(len(shown))[::-1]  # best first, at the top
        rms = np.array([c.rms_after_rad / fl for c in shown], dtype=float)
        colors = ["C2" if c.adequate_after else "C0" for c in shown]
        ax.barh(y, rms, color=colors, alpha=0.8)
        for yi, r, c in zip(y, rms, shown):
            ax.annotate(f" ΔBIC {c.delta_bic:.1f}", (r, yi), va="center", fontsize=8)
        base = self.base.rms_residual_rad / fl
        ax.axvline(base, color="C3", lw=1.2, label=f"base model ({base:.2f}× floor)")
        ax.axvline(1.0, color="0.3", ls="--", lw=1, label="quantization floor")
        ax.set_yticks(y, [c.label for c in shown], fontsize=8)
        ax.set_xlabel("RMS residual after the refit / quantization floor")
        ax.set_xlim(0, 1.3 * max([base, 1.0, *rms[np.isfinite(rms)]]))
        ax.legend(loc="lower right", fontsize=8)
        ax.set_title(f"{self.verdict}: candidates, best first (green: fixes the residual)",
                     fontsize=9)
        return ax

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


def _num(x) -> float:
    """A JSON number back to float: ``null`` (a NaN or infinity written) as NaN."""
    return math.nan if x is None else float(x)


def _load(path, effects, cls) -> Diagnosis:
    import json
    from pathlib import Path

    from .._errors import HdidError
    from .._results._saved import SCHEMA_VERSION, model_from_structure
    from .._results._whiteness import Whiteness

    try:
        d = json.loads(Path(path).read_text())
    except (OSError, UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise HdidError(f"{path}: cannot read it as hdid diagnosis JSON ({exc})") from None
    if not isinstance(d, dict) or "verdict" not in d:
        raise HdidError(f"{path}: not the JSON of an hdid diagnosis (written by `hdid diagnose "
                        "--json` or Diagnosis.save)")
    if d.get("schema_version", 0) > SCHEMA_VERSION:
        raise HdidError(f"{path}: written by a newer hdid ({d.get('hdid_version')}); upgrade hdid")
    model = model_from_structure(d["model"], effects)
    if list(model.effect_names) != list(d["base_model"]):
        raise HdidError(f"{path}: its model {list(model.effect_names)} is not its base model "
                        f"{d['base_model']}; the file was edited")
    keys = {"schema_version", "hdid_version", "input", "options", "model", "correlation",
            "covariance"}
    base = SavedBase(source=d["source"], model=model, rms_residual_rad=_num(d["base_rms_rad"]),
                     units_problem=d.get("units_problem"),
                     provenance={k: v for k, v in d.items() if k in keys})
    w = dict(d["whiteness_before"])
    floats = {f for f, t in Whiteness.__annotations__.items() if t == "float"}
    w = {k: (_num(v) if k in floats else v) for k, v in w.items()}
    w["lags"] = np.asarray(w["lags"], dtype=int)
    for k in ("acf", "acf_null"):
        w[k] = None if w.get(k) is None else np.array([_num(x) for x in w[k]])
    return cls(
        source=d["source"], verdict=d["verdict"], summary=d["summary"], base=base,
        candidates=[CandidateResult.from_dict(c) for c in d["candidates"]],
        whiteness_before=Whiteness(**w), notes=list(d["notes"]), ladder=list(d["ladder"]),
        floor_rad=_num(d["quantization_floor_rad"]), timing=dict(d.get("timing") or {}),
        scanned=dict(d.get("scanned") or {}), refitted=dict(d.get("refitted") or {}),
        warnings=list(d.get("warnings") or []), false_alarm=d.get("false_alarm"),
        rounding_floor=d.get("rounding_floor"),
        separating_experiments=list(d.get("separating_experiments") or []),
        nested=list(d.get("nested") or []),
    )
