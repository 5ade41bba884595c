"""Which physical effect is missing? Refit with each candidate and rank by BIC.

``diagnose`` fits the current model, then adds each library effect the model lacks (or
swaps in a richer law for a base piece), refits, and ranks the candidates by the change
of the Bayesian information criterion.

Refits (:mod:`hdid._refit`)
    Every candidate starts from the current optimum (release instants, start angles and
    offsets included) with its new parameters at data-derived values (several where the
    effect's basin is narrow), from the catalog friction shape when the current fit's is
    unusual, and from the best points of :func:`hdid.fit`'s data-driven grid; all starts
    of one model structure run through one program. The current model gets every start
    a candidate gets: its own grid (``FULL_GRID_STARTS``, more than any candidate), the
    catalog shape, and each candidate's optimum with the added effect removed. A
    candidate is credited only with what the current model cannot reach from there.
Orders
    Position-periodic candidates (``ripple``, ``kinematic_error``) scan their order
    (``RIPPLE_ORDERS`` plus the residual periodogram's two peaks; ``KINEMATIC_ORDERS``),
    low orders included: each is screened by one Gauss–Newton step from the current
    optimum (the score statistic, which sees the collinearity with stiffness and offset),
    the best ``SCAN_REFITS`` are refitted, and the scan costs one parameter in the BIC
    plus ``2·ln M`` for choosing among ``M`` orders (a uniform prior over them: the
    periodogram searches 120, so a ripple pays 9.6 for the freedom of its order).
    The scanned set and each order's one-step gain are in the report's notes.
Evidence
    ``BIC = n·ln(max(χ², n − k)/n) + k·ln n`` (:func:`bic_value`), ``χ²`` in units of the
    quantization variance ``step²/12``, ``n`` the effective observations, ``k`` the fitted
    unknowns. The noise variance is profiled out but never below the quantization floor:
    a fit below the floor is fitting the rounding, and that is no evidence. A candidate
    has strong evidence when ``ΔBIC < STRONG_DBIC`` (−10; Kass & Raftery 1995). The
    false-alarm rate of this rule, measured on clean logs simulated from fitted models
    and quantized like the data, is in ``benchmarks/results/diagnose_suite.md``.
Verdicts (the only four; :func:`_verdict`)
    ``adequate``
        no candidate has strong evidence and the moving residual is at the floor
        (RMS ≤ 1.3× ``step/√12``); a residual that is not white there is noted.
    ``missing_effect``
        the best candidate has strong evidence, no candidate of another family is within
        ``AMBIGUOUS_DBIC`` (10) of it, and with it the moving residual is at the floor.
        At the floor a whiteness test with little power (a few lags at 250 Hz) does not
        overrule it: a non-white residual is noted, not turned into ``unexplained``.
        Candidates of one family (``ripple``/``kinematic_error``: a torque periodic in
        the WG angle) tying is noted with the separating experiment.
    ``ambiguous``
        several candidates of different families have strong evidence within
        ``AMBIGUOUS_DBIC`` of each other: "ambiguous between A, B", with each one's
        separating experiment — never a single confident name.
    ``unexplained``
        the residual is above the floor and either no candidate has strong evidence or
        the best leaves it above the floor (and ``steps`` > 1 did not reach it).
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
#: ... so its candidates get as many grid starts as the base fit always gets.
FULL_GRID_STARTS = 6
#: Two candidates whose BIC differ by less than this explain the data about equally well:
#: the evidence between them is not "very strong" on the Kass–Raftery scale (> 10).
AMBIGUOUS_DBIC = 10.0
#: Discrete settings (orders) refitted after the one-step screen of all of them.
SCAN_REFITS = 3
#: Strong candidates whose residual is analysed (covariance, whiteness) per round: the
#: verdict needs only the best one's (each analysis compiles programs of its own).
MAX_ANALYSED = 1
#: A restart of the current model counts as a better optimum when it lowers χ² by more
#: than this (χ² in quantization variances: 1 is one standard error of the misfit).
BASE_IMPROVED_DCHI2 = 1.0


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

    def to_dict(self) -> dict[str, Any]:
        return {
            "effect": self.key,
            "variant": self.label,
            "rms_before_rad": self.rms_before_rad,
            "rms_after_rad": self.rms_after_rad,
            "delta_bic": self.delta_bic,
            "parameters_added": self.n_added,
            "residual_adequate_after": self.adequate_after,
            "residual_white_after": self.white_after,
            "moving_rms_after_floors": self.moving_ratio_after,
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
    #: wall seconds: total, compile (JAX tracing/compiling or cache reads) and run; CPU
    #: seconds of the process (all threads), less sensitive to other jobs
    timing: dict[str, float] = field(default_factory=dict)
    #: discrete settings scanned per candidate (labels, best one-step gain first)
    scanned: dict[str, list[str]] = field(default_factory=dict)

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
            "scanned": self.scanned,
            "timing": self.timing,
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
        if self.timing:
            t = self.timing
            progs = (f" ({t['programs_stored']:.0f} of {t['programs']:.0f} programs read from "
                     "the store, the rest traced here)" if t.get("programs") else "")
            lines += ["[[timing]]",
                      f"    {t['total_s']:.1f} s: compiling/loading programs {t['compile_s']:.1f} s"
                      f"{progs}, fitting {t['run_s']:.1f} s (CPU {t['cpu_s']:.1f} s)"]
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


#: Orders (cycles per WG revolution) scanned for a position-periodic torque: low orders
#: (1–6: less than one period over a typical swing, still identifiable against a smooth
#: stiffness bend when the data say so), the WG mesh (2, 4) and common motor pole/slot
#: cogging orders; the two largest peaks of the residual's periodogram against the WG
#: angle are added. No order is skipped by a rule of thumb: every one is screened by
#: the fit itself (one Gauss–Newton step, the score statistic) and the best
#: ``SCAN_REFITS`` are refitted to convergence.
RIPPLE_ORDERS = (1.0, 2.0, 3.0, 4.0, 6.0, 8.0, 12.0, 16.0, 24.0, 32.0, 48.0)
#: The residual periodogram searches integer orders 1 … this for peaks; with the fixed
#: list inside that range, the ripple's order is chosen from this many settings.
PERIODOGRAM_ORDERS = 120
#: Orders of the kinematic error scanned (2 is the elliptical wave generator's).
KINEMATIC_ORDERS = (1.0, 2.0, 3.0, 4.0)


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
            reset_shape=False, family="position-periodic", settings=PERIODOGRAM_ORDERS,
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
            "kinematic_error", cubic, _kinematic_variants, scanned=1, reset_shape=False,
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


# -- statistics --------------------------------------------------------------------


def _chi2(result) -> float:
    """χ² at the optimum (data and priors) in units of the quantization variance."""
    return float(result.starts.costs[result.starts.best])


def bic_value(chi2: float, n: float, k: int) -> float:
    """``n·ln(max(χ², n − k)/n) + k·ln n``: the BIC with the noise variance profiled out
    but never below the quantization floor.

    ``χ²`` is in units of the quantization variance ``σ_q² = step²/12``, the noise a
    correct model leaves on a rounded log; a correct model's least-squares fit leaves
    ``E χ² = n − k`` (its ``k`` unknowns absorb part of the rounding). A fit that goes
    below that is fitting the rounding, and the likelihood with a profiled σ would
    reward it without bound (``n·ln`` of a ratio of two tiny numbers): below the floor
    the variance is held at it, so improvements there are no evidence.
    """
    n = float(n)
    floor_chi2 = max(n - k, 1.0)
    return n * math.log(max(chi2, floor_chi2) / n) + k * math.log(n)


def bic(result, extra_parameters: int = 0) -> float:
    """Bayesian information criterion of a fit (:func:`bic_value`).

    ``n`` is the effective number of observations (hold and stuck tail each count once,
    as in the fit's weights) and ``k`` the fitted unknowns (physical parameters, release
    instants, start angles, offsets) plus any discrete settings scanned to get there.
    """
    return bic_value(_chi2(result), result.n_effective, result.n_unknowns + extra_parameters)


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


# -- the driver -----------------------------------------------------------------------


def _base_starts(base_setup, current, cand_fits, values_reset):
    """Starts for the current model from candidates' optima with the effect removed
    (parameters it shares with the current model, and its release instants, start angles
    and offsets), and from the catalog friction shape."""
    from . import _refit

    starts = []
    for sf in cand_fits:
        if not sf.finite:
            continue
        v = sf.values()
        try:
            starts.append((f"reverse:{sf.label}", _refit.warm(
                base_setup, {k: v[k] for k in base_setup.problem.free if k in v},
                _refit.tail_of(sf.setup.problem, sf.u))))
        except ValueError:
            continue
    if values_reset:
        starts.append(("shape_reset", _refit.warm(
            base_setup, {**current.values(), **values_reset},
            _refit.tail_of(current.setup.problem, current.u))))
    return starts


def _merge(a, b):
    """One :class:`~hdid._refit.StructureFit` holding the starts of two runs of the same
    structure (the best of both is its optimum)."""
    from ._refit import StructureFit

    return StructureFit(a.label, a.setup, np.concatenate([a.U, b.U]),
                        np.concatenate([a.costs, b.costs]), np.concatenate([a.ok, b.ok]),
                        np.concatenate([a.steps, b.steps]), a.origins + b.origins,
                        a.wall_s + b.wall_s)


def _candidate_fits(log, cand, current, hints, opts, grid_points, say, scans):
    """Refit ``cand`` on ``log`` from ``current``: a list of StructureFits (one per
    discrete setting refitted) — warm starts from the current optimum with the effect at
    each variant's data-derived values (and from the catalog friction shape), plus the
    best points of the base model's data-driven grid (``grid_points``: ``(values, tail)``
    pairs) with the effect at its first variant's values. (The base grid's points, not
    the candidate's own grid: the same data-driven rule, and one compiled grid program
    instead of one per candidate.) Scanned settings (orders) are first
    screened by one Gauss–Newton step; the best ``SCAN_REFITS`` are refitted."""
    from . import _refit

    values = current.values()
    tail = _refit.tail_of(current.setup.problem, current.u)
    bases = [(current.model, values)]
    if cand.reset_shape and _shape_is_unusual(values):
        reset = _shape_reset(values)
        bases.append((current.model.replace(**reset), {**values, **reset}))
    groups: dict[str, list] = {}
    for m0, v0 in bases:
        for label, m in cand.variants(m0, v0, hints):
            groups.setdefault(label, []).append(m)
    setups = {}
    for label, models in groups.items():
        setups[label] = _refit.setup(log, models[0], opts)
    fits = []
    if cand.scanned:
        gains = {}
        for label, models in groups.items():
            s = setups[label]
            u0 = _refit.warm(s, models[0].float_values(), tail)
            added = [n for n in s.problem.free if n not in current.setup.problem.free]
            gains[label] = (*_refit.gauss_newton_step(s, u0, added), u0)
        order = sorted(gains, key=lambda lb: -gains[lb][0])
        scans[cand.key] = {lb: gains[lb][0] for lb in order}
        for label in order[:SCAN_REFITS]:
            gain, step, u0 = gains[label]
            say(f"  + {label}  (one-step gain Δχ² {gain:.1f})")
            fits.append(_refit.run(label, setups[label], [("warm", u0), ("gauss-newton", u0 + step)]))
        return fits
    for label, models in groups.items():
        s = setups[label]
        starts = [("warm", _refit.warm(s, m.float_values(), tail)) for m in models]
        first = models[0].float_values()
        starts += [("grid", _refit.warm(s, {**first, **v}, t)) for v, t in grid_points]
        say(f"  + {label}  ({len(starts)} starts)")
        fits.append(_refit.run(label, s, starts))
    return fits


def _cand_bic(sf, cand) -> float:
    """BIC of a candidate's refit, its scan's cost included (:meth:`Candidate.penalty`)."""
    return bic_value(sf.cost, sf.n_effective, sf.n_unknowns) + cand.penalty(sf.n_effective)


def _record(cand, sf, current_fit, base_bic_k):
    """A :class:`CandidateResult` from a candidate's refit (ΔBIC against ``current_fit``)."""
    dbic = (_cand_bic(sf, cand)
            - bic_value(current_fit.cost, current_fit.n_effective, base_bic_k))
    vals = sf.values()
    shown = {k: v for k, v in vals.items()
             if k not in current_fit.setup.problem.free or k in ("k1", "tau_c", "tau_s")}
    shown = {k: v for k, v in shown.items() if k in sf.setup.problem.free or k == "order"}
    return CandidateResult(
        cand.key, sf.label, math.nan, sf.rms_rad(), dbic, sf.n_unknowns - current_fit.n_unknowns,
        None, "", shown, None, None, fit=sf,
    )


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
        Data-driven grid starts per candidate refit, besides the warm starts from the
        current fit (the base model gets ``FULL_GRID_STARTS`` of them, more than any
        candidate, and a start from every candidate's optimum).
    progress:
        Called with a short message at each phase (e.g. ``print``).
    **fit_options:
        Passed to :func:`hdid.fit` (``inertia``, ``fix``, ``counts_per_rev``, …).

    Returns
    -------
    Diagnosis
        ``verdict`` and its rules: see the module docstring.
    """
    from . import _programs, _refit
    from ._io import Log, read_log
    from ._model import Model
    from ._residuals import residual_features, residual_frame, whiteness

    say, clock = _programs.phase_reporter(progress)
    if not isinstance(log, Log):
        log = read_log(log, counts_per_rev=fit_options.pop("counts_per_rev", None),
                       resolution=fit_options.pop("resolution", None))
    unknown_opts = set(fit_options) - set(_refit.SETUP_OPTIONS) - {"n_starts", "max_steps"}
    if unknown_opts:
        raise TypeError(f"diagnose: unknown option(s) {sorted(unknown_opts)}")
    fit_options = {k: v for k, v in fit_options.items() if k in _refit.SETUP_OPTIONS}
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
    base_setup = _refit.setup(log, model, fit_options)
    base_grid = _refit.grid(base_setup, FULL_GRID_STARTS)
    current = _refit.run("base", base_setup, [("grid", u) for u in base_grid])
    if not current.finite:
        from ._errors import FitError

        raise FitError(
            f"{base_setup.prep.source}: every start diverged (non-finite residuals); check "
            "units (rad vs counts) and --inertia, or fix some parameters"
        )
    notes: list[str] = []
    ladder: list[dict[str, Any]] = []
    rounds: list[dict[str, Any]] = []
    scans: dict[str, dict[str, float]] = {}
    for step in range(max(1, steps)):
        base_result = current.result()
        white = whiteness(base_result)
        frame = residual_frame(base_result)
        feat = residual_features(frame)
        moving = frame.loc[frame["phase"] == "moving", "theta_wg"]
        swing = float(np.ptp(moving)) if len(moving) else math.inf
        hints = {"ripple_orders": _ripple_orders(frame), "swing_rad": swing}
        floor = base_result.quantization_floor_rad
        # Far from the floor, the current fit is no trustworthy warm start (e.g. a model
        # without static friction that never sticks): candidates get the full grid too.
        far = current.rms_rad() > FAR_FROM_FLOOR * floor
        n_grid = max(n_starts, FULL_GRID_STARTS) if far else n_starts
        p0 = base_setup.problem
        grid_points = [({k: float(v) for k, v in p0.unpack_np(u)[0].items()},
                        _refit.tail_of(p0, u)) for u in base_grid[:n_grid]]
        by_key: dict[str, list] = {}
        for key in wanted:
            cand = all_cands[key]
            if not cand.applies(current.model):
                continue
            try:
                by_key[key] = _candidate_fits(log, cand, current, hints, fit_options,
                                              grid_points, say, scans)
            except Exception as exc:  # one candidate failing must not stop the others
                by_key[key] = exc
        # The current model gets every start a candidate got: from each candidate's
        # optimum with the effect removed, and from the catalog friction shape. A
        # candidate is credited only with what the current model cannot reach.
        # (every one that would be credited, i.e. has strong evidence against the current
        # fit: one start each, ~0.1–0.5 s with one-lane programs)
        k_now = current.n_unknowns
        bic_now = bic_value(current.cost, current.n_effective, k_now)
        cand_fits = sorted(
            (sf for key, v in by_key.items() if not isinstance(v, Exception) for sf in v
             if sf.finite and _cand_bic(sf, all_cands[key]) - bic_now < STRONG_DBIC),
            key=lambda sf: sf.cost)
        values = current.values()
        reset = _shape_reset(values) if _shape_is_unusual(values) else {}
        back = _base_starts(current.setup, current, cand_fits, reset)
        if back:
            say(f"  current model from {len(back)} candidate optima (effect removed)")
            again = _refit.run(current.label, current.setup, back)
            if again.finite and again.cost < current.cost - BASE_IMPROVED_DCHI2:
                best_origin = again.origins[again.best]
                notes.append(
                    f"the current model improved from a start at {best_origin.split(':')[-1]}'s "
                    f"optimum (χ² {current.cost:.1f} → {again.cost:.1f}): its first optimum "
                    "was a local one, and no candidate is credited with the difference"
                )
                current = _merge(current, again)
                base_result = current.result()
                white = whiteness(base_result)
                frame = residual_frame(base_result)
                feat = residual_features(frame)
            else:
                current = _merge(current, again)
                current._result = base_result
        if step == 0:
            ladder.append(_ladder_step(" + ".join(current.model.effect_names), current, None))
        results: list[CandidateResult] = []
        k_base = current.n_unknowns
        for key, fits in by_key.items():
            cand = all_cands[key]
            if isinstance(fits, Exception) or not fits or not any(f.finite for f in fits):
                err = fits if isinstance(fits, Exception) else RuntimeError("no finite refit")
                results.append(CandidateResult(key, key, math.nan, math.nan, math.inf, 0, None,
                                               "", {}, None, f"{type(err).__name__}: {err}"))
                continue
            best_sf = min((f for f in fits if f.finite), key=lambda f: f.cost)
            results.append(_record(cand, best_sf, current, k_base))
        rms_before = current.rms_rad()
        for c in results:
            c.rms_before_rad = rms_before
        results.sort(key=lambda c: (c.error is not None, c.delta_bic))
        strong = [c for c in results if c.error is None and c.delta_bic < STRONG_DBIC]
        for c in strong[:MAX_ANALYSED]:
            c.result = c.fit.result()
            w = whiteness(c.result)
            c.white_after = bool(w.white)
            c.moving_ratio_after = float(w.rms_ratio)
            c.adequate_after = bool(w.at_floor)
        for c in results:
            c.reason = _reason(c, all_cands[c.key], feat, floor)
        rounds.append({"current": current, "results": results, "white": white,
                       "floor": floor, "result": base_result})
        best = strong[0] if strong else None
        if best is None:
            break
        ladder.append(_ladder_step(f"+ {best.label}", best.fit, all_cands[best.key]))
        if best.adequate_after or step + 1 >= steps or _rivals(best, strong, all_cands):
            break
        current = best.fit
        wanted = [k for k in wanted if k != best.key]

    first = rounds[0]
    verdict, summary, vnotes = _verdict(rounds, all_cands)
    notes += vnotes
    results = first["results"]
    if any(c.error for c in results):
        notes.append("some candidate fits failed: " + ", ".join(c.key for c in results if c.error))
    for key, table in scans.items():
        shown = ", ".join(f"{lb.split('order ')[-1].rstrip(')')}: {g:.0f}"
                          for lb, g in list(table.items()))
        notes.append(
            f"{key}: orders scanned (one-step Δχ², best {SCAN_REFITS} refitted): {shown}"
        )
    t = clock()
    say("done")
    return Diagnosis(
        source=first["result"].source,
        verdict=verdict,
        summary=summary,
        base=first["result"],
        candidates=results,
        whiteness_before=first["white"],
        notes=notes,
        ladder=ladder,
        floor_rad=first["floor"],
        timing=t,
        scanned={k: list(v) for k, v in scans.items()},
    )


def _ladder_step(name: str, fit, cand: Candidate | None) -> dict[str, Any]:
    """A ladder row from a FitResult or a refit (:class:`~hdid._refit.StructureFit`); the
    BIC includes the cost of ``cand``'s scan."""
    if hasattr(fit, "starts"):  # FitResult
        chi2, n, k, rms = _chi2(fit), fit.n_effective, fit.n_unknowns, fit.rms_residual_rad
    else:
        chi2, n, k, rms = fit.cost, fit.n_effective, fit.n_unknowns, fit.rms_rad()
    return {
        "model": name,
        "effects": list(fit.model.effect_names),
        "rms_rad": rms,
        "bic": bic_value(chi2, n, k) + (cand.penalty(n) if cand is not None else 0.0),
        "n_unknowns": k,
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


def _rivals(best: CandidateResult, strong: list[CandidateResult], all_cands) -> list:
    """Strong candidates of another family within ``AMBIGUOUS_DBIC`` of the best."""
    fam = all_cands[best.key].family or best.key
    return [c for c in strong[1:] if c.delta_bic - best.delta_bic < AMBIGUOUS_DBIC
            and (all_cands[c.key].family or c.key) != fam]


def _verdict(rounds, all_cands) -> tuple[str, str, list[str]]:
    """The verdict of the first round (and the ladder's), by the rules of the module
    docstring. Returns ``(verdict, summary, notes)``."""
    first = rounds[0]
    results, white, floor = first["results"], first["white"], first["floor"]
    notes: list[str] = []
    ok = [c for c in results if c.error is None]
    strong = [c for c in ok if c.delta_bic < STRONG_DBIC]
    if not strong:
        if white.at_floor:
            if not white.white:
                notes.append(
                    f"the residual is at the floor but not white (Ljung–Box p = {white.p_value:.2g} "
                    f"over {white.max_lag} lag(s)): slow rounding near the reversals correlates "
                    "it, or a small effect remains below what this log can resolve"
                )
            return "adequate", (
                f"no candidate improves the fit strongly (ΔBIC < {STRONG_DBIC:g}) and the "
                f"moving residual is at the quantization floor ({white.rms_ratio:.2f}×)"
            ), notes
        return "unexplained", (
            f"the residual is above the floor (moving RMS {white.rms_ratio:.2f}× floor, "
            f"Ljung–Box p = {white.p_value:.2g}) but no library effect improves it strongly"
        ), notes
    best = strong[0]
    rivals = _rivals(best, strong, all_cands)
    same = [c for c in strong[1:] if c.delta_bic - best.delta_bic < AMBIGUOUS_DBIC
            and c not in rivals]
    if same:
        notes.append(
            f"{best.key} and {', '.join(c.key for c in same)} leave the same mark "
            f"({all_cands[best.key].family}) and fit about equally well; to separate them: "
            f"{all_cands[best.key].experiment}"
        )
    if rivals:
        names = [best.key] + [c.key for c in rivals]
        exps = "; ".join(f"{c.key}: {all_cands[c.key].experiment}" for c in [best] + rivals)
        return "ambiguous", (
            f"ambiguous between {', '.join(names)} (ΔBIC "
            f"{', '.join(f'{c.delta_bic:.1f}' for c in [best] + rivals)}): the log cannot tell "
            f"them apart. Separating experiments — {exps}"
        ), notes
    if best.adequate_after:
        if best.white_after is False:
            notes.append(
                f"after adding {best.label} the residual is at the floor but not white: a "
                "second, smaller effect may remain"
            )
        return "missing_effect", (
            f"add {best.label}: RMS {best.rms_before_rad / floor:.2f} → "
            f"{best.rms_after_rad / floor:.2f}× floor, ΔBIC {best.delta_bic:.1f}"
        ), notes
    # several effects missing at once: the ladder may reach the floor in more steps
    if len(rounds) > 1:
        last = [c for c in rounds[-1]["results"] if c.error is None and c.delta_bic < STRONG_DBIC]
        if last and last[0].adequate_after and not _rivals(last[0], last, all_cands):
            names = [r["results"][0].label for r in rounds]
            return "missing_effect", (
                "add " + " and ".join(names) + f": RMS → {last[0].rms_after_rad / floor:.2f}× floor"
            ), notes
    return "unexplained", (
        f"{best.label} improves the fit (ΔBIC {best.delta_bic:.1f}) but leaves the moving "
        f"residual at {best.moving_ratio_after:.2f}× the floor: the missing physics is "
        "probably not in the library (or several effects are missing: try --steps 2)"
    ), notes


def model_ladder(log, models: Sequence, *, labels: Sequence[str] | None = None, **fit_options):
    """Fit each model in turn and tabulate RMS and BIC: the error falling as effects are added.

    Returns a list of dicts ``{model, effects, rms_rad, bic, n_unknowns, result}``.
    """
    from ._fit import fit

    out = []
    for i, m in enumerate(models):
        r = fit(log, m, **fit_options)
        name = labels[i] if labels else " + ".join(m.effect_names)
        out.append({**_ladder_step(name, r, None), "result": r})
    return out
