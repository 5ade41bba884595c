"""Which physical effect is missing? Refit with each candidate and rank by BIC.

``diagnose`` fits the current model, then adds each library effect the model lacks (or
swaps in a richer law for a base piece), refits from the fitted values, and ranks the
candidates by the change of the Bayesian information criterion. A candidate is believed
only if the evidence is strong (ΔBIC < −10, Kass & Raftery 1995) *and* the residual it
leaves is as white as the quantization allows; otherwise the verdict is ``unexplained``,
never a forced wrong effect.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field
from typing import Any

import numpy as np

#: ΔBIC below this is "very strong" evidence (Kass & Raftery 1995: |ΔBIC| > 10).
STRONG_DBIC = -10.0
#: A current fit with RMS above this many quantization floors is a poor warm start ...
FAR_FROM_FLOOR = 3.0
#: ... so its candidates get as many grid starts as a fresh fit.
FULL_GRID_STARTS = 6
#: Two candidates whose BIC differ by less than this explain the data about equally well:
#: the evidence between them is not "very strong" on the Kass–Raftery scale (> 10).
AMBIGUOUS_DBIC = 10.0


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

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.key,
            "variant": self.label,
            "rms_before_rad": self.rms_before_rad,
            "rms_after_rad": self.rms_after_rad,
            "delta_bic": self.delta_bic,
            "parameters_added": self.n_added,
            "residual_adequate_after": self.adequate_after,
            "fitted": self.values,
            "reason": self.reason,
            **({"error": self.error} if self.error else {}),
        }


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

    @property
    def best(self) -> CandidateResult | None:
        return self.candidates[0] if self.candidates else None

    def to_dict(self) -> dict[str, Any]:
        return {
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
        }

    def report(self) -> str:
        fl = self.floor_rad
        w = self.whiteness_before
        lines = [
            f"[[diagnosis]] {self.source}",
            f"    verdict: {self.verdict} — {self.summary}",
            f"    base model: {' + '.join(self.base.model.effect_names)}; RMS "
            f"{self.base.rms_residual_rad / fl:.2f}× the quantization floor "
            f"({fl:.2e} rad); moving residual {w.rms_ratio:.2f}× floor, Ljung–Box p = "
            f"{w.p_value:.2g}",
            "[[candidates]] (best first; ΔBIC < −10 is strong evidence)",
            f"    {'effect':22s} {'RMS before':>11s} {'RMS after':>10s} {'ΔBIC':>9s}  fixes it",
        ]
        for c in self.candidates:
            if c.error:
                lines.append(f"    {c.label:22s} failed: {c.error}")
                continue
            fixes = {True: "yes", False: "no", None: "—"}[c.adequate_after]
            lines.append(
                f"    {c.label:22s} {c.rms_before_rad / fl:10.2f}× {c.rms_after_rad / fl:9.2f}× "
                f"{c.delta_bic:9.1f}  {fixes}"
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
        if self.notes:
            lines.append("[[notes]]")
            lines += [f"    - {n}" for n in self.notes]
        return "\n".join(lines)

    def __str__(self) -> str:
        return self.report()

    def plot_ladder(self, path=None, *, ax=None):
        """RMS (in quantization floors) and BIC along the model ladder: the error falling."""
        import matplotlib

        if path is not None and ax is None:
            matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        fig = None
        if ax is None:
            fig, ax = plt.subplots(figsize=(6, 3.5), constrained_layout=True)
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
        fig = fig or ax.figure
        if path is not None:
            fig.savefig(path, dpi=120)
        return fig


# -- the candidates -------------------------------------------------------------------


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


#: Orders (cycles per WG revolution) scanned for a position-periodic torque: the WG mesh
#: (2, 4) and common motor pole/slot cogging orders; the largest peak of the residual's
#: periodogram against the WG angle is added to them. Only orders with at least one full
#: period over the logged swing are tried: a fraction of a period is a smooth bend that
#: a stiffness law (or the offset) fits just as well, so it cannot be told apart.
RIPPLE_ORDERS = (2.0, 4.0, 8.0, 12.0, 16.0, 24.0, 32.0, 48.0)


def _ripple_variants(model, values, hints):
    from .effects import library

    swing = hints.get("swing_rad", math.inf)
    shortest = 2 * math.pi / swing if swing > 0 else math.inf  # one period over the swing
    orders = [n for n in RIPPLE_ORDERS if n >= shortest]
    for n in hints.get("ripple_orders") or []:
        if n >= shortest and all(abs(n - o) > 1 for o in orders):
            orders.append(float(n))
    out = []
    for n in orders:
        eff = library({**values, "order": float(n)})["ripple"]
        out.append((f"ripple (order {n:g})", model.with_effect(eff)))
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
            reset_shape=False,
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
            "kinematic_error", cubic, _library_variant("kinematic_error"),
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


# -- statistics --------------------------------------------------------------------


def _chi2(result) -> float:
    """Data χ² at the optimum in units of the quantization variance."""
    return float(result.starts.costs[result.starts.best])


def bic(result, extra_parameters: int = 0) -> float:
    """Bayesian information criterion of a fit with the noise level profiled out.

    ``n·ln(χ²/n) + k·ln n`` with ``n`` the effective number of observations (hold and
    stuck tail each count once, as in the fit's weights) and ``k`` the fitted unknowns
    (physical parameters, release instants, start angles, offsets) plus any discrete
    settings scanned to get there.
    """
    n = float(result.n_effective)
    k = result.n_unknowns + extra_parameters
    return n * math.log(max(_chi2(result), 1e-300) / n) + k * math.log(n)


def _features_text(feat: dict[str, float]) -> str:
    parts = []
    c = feat.get("corr_sign_omega")
    if c is not None and np.isfinite(c) and abs(c) > 0.2:
        parts.append(f"flips with the velocity (corr with sign ω {c:+.2f})")
    e = feat.get("near_rest_energy_share")
    if e is not None and np.isfinite(e) and e > 0.35:
        parts.append(f"{100 * e:.0f} % of its energy in the last fifth before rest")
    r = feat.get("stuck_signed_counts")
    if r is not None and np.isfinite(r) and abs(r) > 0.5:
        side = "beyond" if r > 0 else "short of"
        parts.append(f"logged rest points lie {abs(r):.1f} counts {side} the model's (towards the release side)")
    o = feat.get("theta_peak_order")
    s = feat.get("theta_peak_share")
    if o is not None and s is not None and np.isfinite(s) and s > 0.3:
        parts.append(f"periodic in the WG angle (order ≈ {o:.0f} per rev, {100 * s:.0f} % of power)")
    ce = feat.get("corr_abs_theta")
    if ce is not None and np.isfinite(ce) and abs(ce) > 0.3:
        parts.append(f"grows with the twist (corr with |θ| {ce:+.2f})")
    return "; ".join(parts) if parts else "no single dominant pattern"


def _ripple_orders(frame, top: int = 1) -> list[float]:
    """Orders (cycles per WG rev) of the largest peaks of the residual vs WG angle."""
    from scipy.signal import lombscargle

    mov = frame[frame["phase"] == "moving"]
    if len(mov) < 10:
        return [24.0]
    x = mov["theta_wg"].to_numpy()
    y = mov["residual_rad"].to_numpy() - mov["residual_rad"].mean()
    orders = np.arange(2, 121, dtype=float)
    # sin(n·θ) with θ in rad has angular frequency n: the order per revolution
    power = lombscargle(x, y, orders)
    picks = []
    for i in np.argsort(power)[::-1]:
        if all(abs(orders[i] - p) > 2 for p in picks):
            picks.append(float(orders[i]))
        if len(picks) == top:
            break
    return picks


# -- the driver -----------------------------------------------------------------------


def diagnose(
    log,
    model=None,
    *,
    candidates: Iterable[str] | None = None,
    steps: int = 1,
    n_starts: int = 2,
    progress: Callable[[str], None] | None = None,
    **fit_options,
) -> Diagnosis:
    """Fit ``model``, then rank the effects that could be missing from it.

    Parameters
    ----------
    log:
        A log (path, DataFrame or :class:`~hdid.Log`).
    model:
        The current model (default :meth:`Model.default`).
    candidates:
        Keys to try (default: every library candidate that applies to the model; see
        :func:`default_candidates`).
    steps:
        Forward-selection steps: after adding the best candidate, diagnose again from the
        improved model, at most this many times (the model ladder).
    n_starts:
        Starts per candidate fit, besides the warm start from the current fit.
    progress:
        Called with a short message before each fit (e.g. ``print``).
    **fit_options:
        Passed to :func:`hdid.fit` (``inertia``, ``fix``, ``counts_per_rev``, …).

    Returns
    -------
    Diagnosis
        ``verdict`` is ``"missing_effect"`` (strong evidence and the residual then at the
        floor), ``"adequate"`` (no candidate gives strong evidence and the residual is as
        white as the quantization allows) or ``"unexplained"`` (structured residual that no
        candidate fixes).
    """
    from ._fit import fit
    from ._io import Log, read_log
    from ._model import Model
    from ._residuals import residual_features, residual_frame, whiteness

    say = progress or (lambda msg: None)
    if not isinstance(log, Log):
        log = read_log(log, counts_per_rev=fit_options.pop("counts_per_rev", None))
    model = Model.default() if model is None else model
    all_cands = {c.key: c for c in default_candidates()}
    if candidates is not None:
        wanted = list(candidates)
        unknown = [k for k in wanted if k not in all_cands]
        if unknown:
            raise KeyError(
                f"candidates: unknown {unknown}; choose from {sorted(all_cands)}"
            )
    else:
        wanted = list(all_cands)

    say(f"fitting the base model ({' + '.join(model.effect_names)})")
    base = fit(log, model, **fit_options)
    notes: list[str] = []
    values = base.model.float_values()
    if _shape_is_unusual(values):
        # Candidates get a restart from the catalog friction shape; give the base model
        # the same chance, so that no candidate is credited with a better basin.
        say("  restarting the base model from the catalog friction shape")
        again = fit(log, base.model.replace(**_shape_reset(values)), start_from_model=True,
                    n_starts=n_starts, **fit_options)
        if _chi2(again) < _chi2(base):
            notes.append(
                f"the base fit improved from a restart at the catalog friction shape "
                f"(RMS {base.rms_residual_rad / base.quantization_floor_rad:.2f} → "
                f"{again.rms_residual_rad / again.quantization_floor_rad:.2f}× floor): "
                "its first optimum was a local one"
            )
            base = again
    floor = base.quantization_floor_rad
    ladder = [_ladder_step(" + ".join(base.model.effect_names), base, 0)]
    current = base
    rounds: list[tuple[Any, list[CandidateResult], Any]] = []
    for step in range(max(1, steps)):
        white = whiteness(current)
        frame = residual_frame(current)
        feat = residual_features(frame)
        moving = frame.loc[frame["phase"] == "moving", "theta_wg"]
        swing = float(np.ptp(moving)) if len(moving) else math.inf
        hints = {"ripple_orders": _ripple_orders(frame), "swing_rad": swing}
        values = current.model.float_values()
        # Far from the floor, the current fit is no trustworthy warm start (e.g. a model
        # without static friction that never sticks): give candidates the full grid.
        far = current.rms_residual_rad > FAR_FROM_FLOOR * current.quantization_floor_rad
        starts_here = max(n_starts, FULL_GRID_STARTS) if far else n_starts
        results: list[CandidateResult] = []
        fix = fit_options.get("fix")
        for key in wanted:
            cand = all_cands[key]
            if not cand.applies(current.model):
                continue
            best_variant = None
            bases = [(current.model, values)]
            if cand.reset_shape and _shape_is_unusual(values):
                # The base fit's Stribeck shape may be bent to mimic the missing effect:
                # start the candidate from the catalog shape too.
                reset = _shape_reset(values)
                bases.append((current.model.replace(**reset), {**values, **reset}))
            variants = [v for m0, v0 in bases for v in cand.variants(m0, v0, hints)]
            for i_v, (label, m) in enumerate(variants):
                say(f"  + {label}" + (f" (start {i_v + 1}/{len(variants)})" if len(variants) > 1 else ""))
                opts = dict(fit_options)
                if isinstance(fix, dict):
                    opts["fix"] = {k: v for k, v in fix.items() if k in m.parameter_specs()}
                elif fix is not None:
                    opts["fix"] = [k for k in fix if k in m.parameter_specs()]
                try:
                    r = fit(log, m, start_from_model=True, n_starts=starts_here, **opts)
                except Exception as exc:  # one candidate failing must not stop the others
                    cr = CandidateResult(key, label, current.rms_residual_rad, math.nan,
                                         math.inf, 0, None, "", {}, None,
                                         f"{type(exc).__name__}: {exc}")
                    best_variant = best_variant or cr
                    continue
                n_added = r.n_unknowns - current.n_unknowns
                dbic = bic(r, cand.scanned) - bic(current)
                cr = CandidateResult(
                    key, label, current.rms_residual_rad, r.rms_residual_rad, dbic, n_added,
                    None, "", {k: p.value for k, p in r.parameters.items()
                               if k not in current.parameters or k in ("k1", "tau_c", "tau_s")}, r,
                )
                if best_variant is None or best_variant.error or dbic < best_variant.delta_bic:
                    best_variant = cr
            if best_variant is not None:
                results.append(best_variant)
        results.sort(key=lambda c: (c.error is not None, c.delta_bic))
        for c in results:
            if c.result is not None and c.delta_bic < STRONG_DBIC:
                c.adequate_after = bool(whiteness(c.result).adequate)
            c.reason = _reason(c, all_cands[c.key], feat, floor)
        rounds.append((current, results, white))
        best = results[0] if results and results[0].error is None else None
        if best is None or best.delta_bic >= STRONG_DBIC:
            break
        ladder.append(_ladder_step(f"+ {best.label}", best.result, cand_scanned(all_cands, best)))
        if best.adequate_after or step + 1 >= steps:
            break
        current = best.result
        wanted = [k for k in wanted if k != best.key]

    first_base, first_results, first_white = rounds[0]
    verdict, summary = _verdict(rounds, floor)
    strong = [c for c in first_results if c.error is None and c.delta_bic < STRONG_DBIC]
    if len(strong) >= 2 and strong[1].delta_bic - strong[0].delta_bic < AMBIGUOUS_DBIC:
        a, b = strong[0], strong[1]
        notes.append(
            f"{a.key} and {b.key} explain this log about equally well (ΔBIC {a.delta_bic:.1f} "
            f"vs {b.delta_bic:.1f}): the data cannot tell them apart. To separate them: "
            f"{all_cands[a.key].experiment}; {all_cands[b.key].experiment}."
        )
    if any(c.error for c in first_results):
        notes.append("some candidate fits failed: " + ", ".join(c.key for c in first_results if c.error))
    return Diagnosis(
        source=base.source,
        verdict=verdict,
        summary=summary,
        base=base,
        candidates=first_results,
        whiteness_before=first_white,
        notes=notes,
        ladder=ladder,
        floor_rad=floor,
    )


def cand_scanned(all_cands, c: CandidateResult) -> int:
    return all_cands[c.key].scanned


def _ladder_step(name: str, result, scanned: int) -> dict[str, Any]:
    return {
        "model": name,
        "effects": list(result.model.effect_names),
        "rms_rad": result.rms_residual_rad,
        "bic": bic(result, scanned),
        "n_unknowns": result.n_unknowns,
    }


def _reason(c: CandidateResult, cand: Candidate, feat: dict[str, float], floor: float) -> str:
    if c.error:
        return f"fit failed: {c.error}"
    head = (
        f"{c.label}: RMS {c.rms_before_rad / floor:.2f} → {c.rms_after_rad / floor:.2f}× the "
        f"quantization floor, ΔBIC {c.delta_bic:.1f} for {c.n_added} more parameter(s)."
    )
    return f"{head} The residual before: {_features_text(feat)}. A missing {c.key} leaves this " \
           f"mark: {cand.mark}."


def _verdict(rounds, floor) -> tuple[str, str]:
    base, results, white = rounds[0]
    ok = [c for c in results if c.error is None]
    strong = [c for c in ok if c.delta_bic < STRONG_DBIC]
    if not strong:
        if white.adequate:
            return "adequate", (
                "no candidate improves the fit strongly and the residual is as white as the "
                "quantization allows"
            )
        return "unexplained", (
            f"the residual is structured (moving RMS {white.rms_ratio:.2f}× floor, Ljung–Box "
            f"p = {white.p_value:.2g}) but no library effect improves it strongly"
        )
    best = strong[0]
    if best.adequate_after:
        return "missing_effect", (
            f"add {best.label}: RMS {best.rms_before_rad / floor:.2f} → "
            f"{best.rms_after_rad / floor:.2f}× floor, ΔBIC {best.delta_bic:.1f}"
        )
    # several effects missing at once: the ladder may reach the floor in more steps
    if len(rounds) > 1:
        last_results = rounds[-1][1]
        last = last_results[0] if last_results else None
        if last is not None and last.adequate_after:
            names = [r[1][0].label for r in rounds]
            return "missing_effect", (
                "add " + " and ".join(names) + f": RMS → {last.rms_after_rad / floor:.2f}× floor"
            )
    return "unexplained", (
        f"{best.label} improves the fit (ΔBIC {best.delta_bic:.1f}, RMS "
        f"{best.rms_after_rad / floor:.2f}× floor) but leaves a structured residual: the "
        "missing physics is probably not in the library"
    )


def model_ladder(log, models: Sequence, *, labels: Sequence[str] | None = None, **fit_options):
    """Fit each model in turn and tabulate RMS and BIC: the error falling as effects are added.

    Returns a list of dicts ``{model, effects, rms_rad, bic, n_unknowns, result}``.
    """
    from ._fit import fit

    out = []
    for i, m in enumerate(models):
        r = fit(log, m, **fit_options)
        name = labels[i] if labels else " + ".join(m.effect_names)
        out.append({**_ladder_step(name, r, 0), "result": r})
    return out
