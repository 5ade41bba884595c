"""Convergence diagnostics and how much the data narrowed each parameter.

Convergence (issue 17's criterion), on every sampled quantity and the stick-band
half-width: bulk and tail effective sample sizes ≥ ``ESS_MIN`` (arviz, each walker taken
as a chain) and either a rank-normalised split R-hat ≤ ``RHAT_MAX`` or, for an ensemble
(the issue's alternative), a kept chain at least ``TAU_MULTIPLE`` integrated
autocorrelation times long (:func:`tau_pooled`, about the *ensemble* mean, so walkers
that sit in different modes lengthen it). The report says which rule was met.

Why both: R-hat with each of 36 walkers taken as a chain asks every walker alone for
enough independent draws to match the others' spread: on 46 paper-design chains
(docs/decisions/ensemble-convergence-rule.md)
R-hat came down to 1.01 only at ≈ 85–125 τ (1.013–1.022 at 50–70 τ with ESS ≥ 1200),
while 50 τ is emcee's own rule for a reliable τ and leaves ≈ 36 × 50 / 2 = 900 and more
effective draws in the ensemble, which the ESS floor checks.
"""

from __future__ import annotations

import math
import warnings as _warnings
from dataclasses import dataclass

import numpy as np

#: Largest rank-normalised split R-hat accepted (Vehtari et al. 2021's recommendation).
RHAT_MAX = 1.01
#: Smallest bulk and tail ESS accepted (same reference: ≥ 100 per chain for 4 chains; the
#: issue asks 400 in all, enough for the 2.5 % / 97.5 % quantiles to ± ~0.8 %).
ESS_MIN = 400
#: Diagnostics are computed on at most this many steps per walker (evenly thinned: the
#: ESS of a thinned chain is never larger than the full chain's, so the test stays
#: conservative; on the paper design τ is hundreds of steps, far above the stride, so
#: little is lost). arviz on 4000 steps × 36 walkers × 20 quantities took 5.7 s of CPU.
DIAG_MAX_STEPS = 1000
#: The ensemble rule: a kept chain at least this many τ long on every quantity (emcee's
#: documentation: τ estimates are reliable from ~50 τ on).
TAU_MULTIPLE = 50


def tau_pooled(chain: np.ndarray, c: float = 5.0) -> np.ndarray:
    """Integrated autocorrelation time per dimension with the ACF about the *ensemble*
    mean (emcee centres each walker on its own mean, which hides walkers that sit in
    different modes and never swap: this estimate does not).

    ``chain`` is ``(steps, walkers, D)``; Sokal's automatic window as in emcee.
    """
    n = chain.shape[0]
    m = 1 << (2 * n - 1).bit_length()
    out = np.empty(chain.shape[2])
    for d in range(chain.shape[2]):
        x = chain[:, :, d] - np.mean(chain[:, :, d])
        f = np.fft.rfft(x, n=m, axis=0)
        acov = np.fft.irfft(f * np.conjugate(f), n=m, axis=0)[:n].mean(axis=1)
        if not acov[0] > 0:
            out[d] = np.nan
            continue
        taus = 2.0 * np.cumsum(acov / acov[0]) - 1.0
        # Sokal's window: the first lag m ≥ c·τ(m); none (emcee would return lag 0): the
        # correlations outlast the chain, τ is at least the whole estimate.
        closed = np.flatnonzero(np.arange(n) >= c * taus)
        out[d] = taus[closed[0]] if closed.size else taus[-1]
    return out


@dataclass
class Convergence:
    """Per-quantity R-hat, bulk / tail ESS and (for an ensemble) τ of a chain, and the
    verdict."""

    names: list[str]
    rhat: np.ndarray
    ess_bulk: np.ndarray
    ess_tail: np.ndarray
    #: integrated autocorrelation time of each quantity in steps (ensemble chains only)
    tau: np.ndarray | None = None
    #: kept chain length in steps (ensemble chains only)
    steps: int | None = None

    @property
    def ess_ok(self) -> bool:
        return bool(np.all(self.ess_bulk >= ESS_MIN) and np.all(self.ess_tail >= ESS_MIN))

    @property
    def chain_in_tau(self) -> float:
        """Kept chain length over the largest τ (NaN without τ; 0 when a τ is not finite)."""
        if self.tau is None or self.steps is None:
            return math.nan
        t = np.asarray(self.tau, dtype=float)
        if t.size == 0 or not np.all(np.isfinite(t)) or np.max(t) <= 0:
            return 0.0
        return float(self.steps / np.max(t))

    @property
    def met_by(self) -> str | None:
        """``"R-hat"``, ``"50 tau"`` (the ensemble rule) or ``None`` (not converged)."""
        if not self.ess_ok:
            return None
        if np.all(self.rhat <= RHAT_MAX):
            return "R-hat"
        if self.chain_in_tau >= TAU_MULTIPLE:
            return f"{TAU_MULTIPLE} tau"
        return None

    @property
    def converged(self) -> bool:
        return self.met_by is not None

    @property
    def criterion(self) -> str:
        rule = f"bulk and tail ESS >= {ESS_MIN}, and arviz rank-normalised R-hat <= {RHAT_MAX}"
        if self.tau is not None:
            rule += f" or a chain >= {TAU_MULTIPLE} tau (ensemble)"
        return rule + ", on every sampled quantity and the band"

    @property
    def worst(self) -> tuple[str, str]:
        """``(name, what)`` of the quantity furthest from the criterion."""
        with np.errstate(divide="ignore", invalid="ignore"):
            score = np.fmax((self.rhat - 1.0) / (RHAT_MAX - 1.0),
                            ESS_MIN / np.fmin(self.ess_bulk, self.ess_tail))
        score = np.where(np.isfinite(score), score, np.inf)
        i = int(np.argmax(score))
        return self.names[i], (f"R-hat {self.rhat[i]:.3f}, ESS bulk {self.ess_bulk[i]:.0f}, "
                               f"tail {self.ess_tail[i]:.0f}")

    def to_dict(self) -> dict:
        return {
            "criterion": self.criterion,
            "converged": self.converged,
            "met_by": self.met_by,
            "chain_in_tau_max": (None if math.isnan(self.chain_in_tau) else self.chain_in_tau),
            "rhat_max": float(np.nanmax(self.rhat)),
            "ess_bulk_min": float(np.nanmin(self.ess_bulk)),
            "ess_tail_min": float(np.nanmin(self.ess_tail)),
            "per_quantity": {n: {"rhat": float(r), "ess_bulk": float(b), "ess_tail": float(t)}
                             for n, r, b, t in zip(self.names, self.rhat, self.ess_bulk, self.ess_tail)},
        }


#: τ that grows at least this fast with the chain, as the exponent ``g`` of τ ∝ steps^g
#: over a doubling (a stationary chain: g → 0 once it is tens of τ long; walkers that
#: never cross between optima or along a ridge: g ≈ 1, the correlations outlast the chain),
#: on a chain still under ``OUTLAST_TAU`` τ, means a longer chain will not converge.
#: Measured on the calibration's paper logs (docs/decisions/emcee-calibration-logs.md):
#: seed 36008 g = 0.98 at 1.6 τ (not converged at 40 000 steps; τ of tau_c, c_v ≈ 25 000), 36027 g = 0.10 (converged at 15 262 steps); 36 AR(1) walkers of τ ≈ 200 at
#: 7.5 → 15 τ: g sd ≈ 0.25, largest of 20 seeds 0.73; 36 random walks: g 0.91–1.16.
OUTLAST_GROWTH = 0.8
#: ... on a chain shorter than this many τ (a stationary chain this long has τ to ±~20 %
#: with 36 walkers, so ``g`` over a doubling stays well under ``OUTLAST_GROWTH``).
OUTLAST_TAU = 20.0


def tau_outlasts_chain(history) -> tuple[float, float] | None:
    """``(g, steps ratio)`` when the largest τ grew like the chain itself — ``history`` is
    ``[(steps, τ_max), ...]`` at the chain's checks; ``g`` is the exponent of τ ∝ steps^g
    from the last check back to the latest one at most half its length — and the chain is
    still under ``OUTLAST_TAU`` τ; ``None`` otherwise (too short a history to say)."""
    h = [(float(n), float(t)) for n, t in history if n > 0 and math.isfinite(t) and t > 0]
    if len(h) < 2:
        return None
    n2, t2 = h[-1]
    earlier = [(n, t) for n, t in h[:-1] if n <= 0.5 * n2]
    if not earlier or n2 / t2 >= OUTLAST_TAU:
        return None
    n1, t1 = earlier[-1]
    g = math.log(t2 / t1) / math.log(n2 / n1)
    return (g, n2 / n1) if g >= OUTLAST_GROWTH else None


def diagnostic_stride(steps: int) -> int:
    """Thinning that keeps at most ``DIAG_MAX_STEPS`` steps per walker."""
    return max(1, math.ceil(steps / DIAG_MAX_STEPS))


def convergence(chain: np.ndarray, names: list[str], tau=None, steps: int | None = None) -> Convergence:
    """R-hat and ESS of every column of ``chain`` ``(steps, walkers, K)`` (walkers as chains;
    pass a thinned chain to bound the cost: its ESS is a lower bound of the full chain's).
    ``tau`` (per column, in steps of the full chain) and ``steps`` (its length) enable the
    ensemble rule."""
    import arviz as az

    x = np.ascontiguousarray(np.swapaxes(chain, 0, 1))  # (chains, draws, K)
    rhat, bulk, tail = (np.empty(x.shape[2]) for _ in range(3))
    with _warnings.catch_warnings():
        _warnings.simplefilter("ignore")
        for k in range(x.shape[2]):
            v = x[:, :, k]
            if not np.all(np.isfinite(v)) or np.ptp(v) == 0:
                rhat[k], bulk[k], tail[k] = np.nan, np.nan, np.nan
                continue
            rhat[k] = float(az.rhat(v, method="rank"))
            bulk[k] = float(az.ess(v, method="bulk"))
            tail[k] = float(az.ess(v, method="tail"))
    # NaN (constant or non-finite column) fails the criterion
    rhat = np.where(np.isfinite(rhat), rhat, np.inf)
    bulk = np.where(np.isfinite(bulk), bulk, 0.0)
    tail = np.where(np.isfinite(tail), tail, 0.0)
    return Convergence(list(names), rhat, bulk, tail,
                       None if tau is None else np.asarray(tau, dtype=float), steps)


def prior_sd(problem, centre, half_width: float, linear_prior: np.ndarray) -> np.ndarray:
    """Standard deviation of each free physical parameter's prior in the fit's transformed
    coordinates: the flat box ``±half_width`` around the fit (flat in the value for
    ``linear_prior`` parameters: density ∝ e^u in u) times the problem's own Gaussian prior
    where ``prior_on`` (computed on a grid: exact to the grid's resolution)."""
    P = problem.n_physical
    mean = np.asarray(problem.prior_mean, dtype=float)
    sd = np.asarray(problem.prior_sd, dtype=float)
    on = np.asarray(problem.prior_on, dtype=bool)
    out = np.empty(P)
    for i in range(P):
        u = np.linspace(centre[i] - half_width, centre[i] + half_width, 4001)
        logp = np.zeros_like(u)
        if linear_prior[i] > 0:
            logp += u - centre[i]
        if on[i]:
            logp += -0.5 * ((u - mean[i]) / sd[i]) ** 2
        w = np.exp(logp - logp.max())
        w /= w.sum()
        m = float(w @ u)
        out[i] = math.sqrt(float(w @ (u - m) ** 2))
    return out


#: Posterior / prior width at or below which the data carry at least half of the
#: precision (1 − r² ≥ ½ for Gaussians): "measured".
MEASURED_MAX = math.sqrt(0.5)
#: Above this the data carry less than a fifth of the precision (1 − r² < 0.2): "assumed".
ASSUMED_MIN = math.sqrt(0.8)
#: Posterior / prior width above which the report says "set by the prior" (issue 34): the
#: data carry less than three quarters of the precision (1 − r² < 0.75 for Gaussians).
SET_BY_PRIOR = 0.5


def width_ratios(problem, draws_u: np.ndarray, centre, half_width: float,
                 linear_prior: np.ndarray, gauss_prior=None) -> dict[str, dict]:
    """For each free physical parameter: posterior sd / prior sd in the fit's transformed
    coordinates, ``set_by_prior`` (> ``SET_BY_PRIOR``) and the verdict ``measured``
    (≤ ``SET_BY_PRIOR``), ``set by the prior (assumed)`` (> ``ASSUMED_MIN``: the data carry
    under a fifth of the precision) or ``set by the prior (partly measured)``.
    ``gauss_prior`` (``(3, P)``: mean, sd, on) gives the sd of parameters with a Gaussian
    prior (a default or the user's)."""
    psd = prior_sd(problem, np.asarray(centre, dtype=float), half_width, linear_prior)
    if gauss_prior is not None:
        G = np.asarray(gauss_prior, dtype=float)
        psd = np.where(G[2] > 0, G[1], psd)
    out = {}
    for i, n in enumerate(problem.free):
        r = float(np.std(draws_u[:, i]) / psd[i])
        verdict = ("measured" if r <= SET_BY_PRIOR else "set by the prior (assumed)"
                   if r > ASSUMED_MIN else "set by the prior (partly measured)")
        out[n] = {"posterior_over_prior_width": r, "verdict": verdict,
                  "set_by_prior": bool(r > SET_BY_PRIOR)}
    return out


def mode_shares(found, mix, X, what: str, tail: str):
    """Each optimum's share of the draws ``X`` (the mode whose weighted Laplace density
    ``mix`` is highest at the draw), and the MULTIMODAL warning when the fit's cost has
    several optima (``what``: "draws" / "particles"; ``tail`` ends the sentence), or None."""
    comp = np.argmax(mix.component_logpdf(X), axis=1)
    share = np.bincount(comp, minlength=len(found)) / comp.size
    optima = [i for i, m in enumerate(found) if m.kind == "optimum"]
    if len(optima) < 2:
        return share, None
    return share, (
        f"MULTIMODAL: {len(optima)} separate optima of the fit's cost (Laplace weights "
        + ", ".join(f"{found[i].weight:.2f}" for i in optima)
        + f"; share of the {what} " + ", ".join(f"{share[i]:.2f}" for i in optima)
        + "); " + tail)
