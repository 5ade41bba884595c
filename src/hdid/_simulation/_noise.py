"""The readings' noise, from the log alone: the still stretches (holds and stuck tails)
pooled, and the jumps of readings on a grid that an encoder's still gear never makes.

:func:`hdid._simulation._prepare.prepare` uses them to choose between an encoder grid and
a noise model, and to set the weights. NumPy (and scipy.special) only.
"""

from __future__ import annotations

import math

import numpy as np

#: Still stretches whose noise estimate lies within this factor of the runs' typical one
#: are pooled (:func:`noise_sigma`): ~10 differences each put a still stretch's estimate
#: within about 0.5–2× σ; a moving stretch is orders of magnitude above.
STILL_SPREAD = 3.0


def _still_pieces(runs):
    """First differences of every run's head and tail (``m`` samples each, ``m`` a tenth
    of the run within 4–50) and the run each belongs to: the still stretches, where the
    run holds or rests, of :func:`noise_sigma` and :func:`grid_noise`."""
    pieces, owner = [], []
    for k, run in enumerate(runs):
        th = np.asarray(run.theta, dtype=float)
        m = max(4, min(50, len(th) // 10))
        for seg in (th[:m], th[-m:]):
            d = np.diff(seg)
            if d.size >= 3:
                pieces.append(d)
                owner.append(k)
    return pieces, np.asarray(owner, dtype=int)


#: A run whose range is under this many noise σ could be read as never leaving its hold
#: (:func:`hdid._simulation._prepare.prepare`: 5–6 σ from one level, either side): where
#: every run is and no still stretch is noise, the σ is checked against the swing's own
#: prediction (:func:`noise_sigma`). Ring-downs read right span 50–250 σ.
SWING_RANGE = 20.0


#: A still stretch's readings span at most this many of its own noise σ (estimated from its
#: differences' MAD): the range of ≤ 50 Gaussian readings is 4.5σ on average (3.1σ for
#: 10), above 7σ about once in a thousand; the MAD reads σ low from ~10 differences (0.6×
#: at -2 sd) or from differences rounded to whole steps (1.4 steps of noise: median |d| of
#: 1 step, σ 0.73×). Motion (a run cut at its first moving sample swings by tens of steps,
#: most of its differences already 0 once stuck) spans far more.
STILL_RANGE = 10.0


#: Largest |lag-k autocorrelation| (k = 2, 3) of a still stretch's first differences: white
#: noise's are 0 (sd 1/√n, ≤ 0.14 for 50 differences: 0.45 is 3 sd there), a sampled swing's
#: are cos(2πkf/fs), never all small together (at f = 3/8 fs, where lag 2's is 0, lag 3's
#: is 0.71).
STILL_LAG = 0.45


def _noisy(d: np.ndarray) -> bool:
    """Whether a stretch's first differences ``d`` are noise about a still level, not
    motion. White noise's differences are anticorrelated at lag 1 (−½) and uncorrelated
    beyond; a smooth motion's carry on (lag 1 +1), a swing sampled a few times a period
    correlates at every lag (a 60 Hz swing at 250 Hz has lag-1 anticorrelated differences
    too). And the readings stay near one level: their range within :data:`STILL_RANGE` of
    the σ its differences' MAD gives (a motion that stops within the stretch)."""
    if d.size < 4 or not np.any(d != 0.0):
        return False
    c = d - float(np.mean(d))
    var = float(np.sum(c * c))
    if var <= 0.0 or float(np.sum(d[:-1] * d[1:])) >= 0.0:
        return False
    if any(abs(float(np.sum(c[:-k] * c[k:]))) > STILL_LAG * var for k in (2, 3)):
        return False
    sig = 1.4826 * float(np.median(np.abs(d - np.median(d)))) / math.sqrt(2.0)
    level = np.concatenate([[0.0], np.cumsum(d)])
    return bool(float(np.ptp(level)) <= STILL_RANGE * sig)


def _per_run(pieces, owner, score) -> tuple[np.ndarray, np.ndarray]:
    """Each run's still-stretch score (the smaller of its head's and tail's: one of them may
    move) and which pieces take part. A head that repeats one reading exactly (all its
    differences 0) gives way to the run's tail where that one is noise about a still level
    (:func:`_noisy`): a hold read before the noise starts (a sensor or drive that is quiet
    until the release) is clean, and the readings that count — the motion and the stuck
    tail — carry the tail's noise. Never the other way round: a run cut at its first
    moving sample (no hold) starts with motion and may end on one clean level."""
    score = np.asarray(score, dtype=float)
    use = np.ones(len(pieces), dtype=bool)
    per_run = []
    for k in np.unique(owner):
        mine = np.flatnonzero(owner == k)
        if (len(mine) == 2 and not np.any(pieces[mine[0]] != 0.0)
                and _noisy(pieces[mine[1]])):
            use[mine[0]] = False
            mine = mine[1:]
        per_run.append(float(np.min(score[mine])))
    return np.asarray(per_run), use


def grid_noise(runs, step: float) -> float:
    """Error σ [log units] of readings on a grid of ``step`` whose still stretches jump by
    two steps or more, 0 where they do not.

    An encoder's still gear reads one level, or flickers between two adjacent ones (its
    reading's error ≤ step/2, σ = step/√12 on average): no first difference of a still
    stretch is 2 steps or more. Noise ``s`` ahead of the rounding gives readings of error
    σ ≈ √(s² + step²/12) (Sheppard) and differences ~ N(0, 2σ²), so a fraction
    ``p = 2·Q(1.5·step / (√2·σ))`` of them round to 2 steps or more: σ follows from ``p``.
    ``p`` from the still stretches' differences: per run the stiller of head and tail (one
    of them may move), the median over runs (a few runs may move at both ends), then
    pooled over the stretches within :data:`STILL_SPREAD` of that (as :func:`noise_sigma`). The
    median-absolute differences cannot tell this noise from flicker: at 1.4 steps of
    noise half the differences are 0 or ±1 step, as for a flicker between two levels."""
    from scipy.special import ndtri

    pieces, owner = _still_pieces(runs)
    if not pieces:
        return 0.0
    jumps = [np.abs(d) >= 1.5 * step for d in pieces]
    frac = np.array([float(np.mean(j)) for j in jumps])
    per_run, use = _per_run(pieces, owner, frac)
    ref = float(np.median(per_run))
    if ref <= 0.0:
        return 0.0
    # pooled over the stretches within STILL_SPREAD of it (the smaller of two estimates
    # from ~11 differences each is biased low: σ 0.73× at 1.4 steps)
    p = float(np.mean(np.concatenate([j for j, f, ok in zip(jumps, frac, use)
                                      if ok and f <= STILL_SPREAD * ref])))
    return 1.5 * step / (math.sqrt(2.0) * float(ndtri(1.0 - min(p, 0.99) / 2.0)))


def noise_sigma(runs, step: float | None, still_only: bool = False) -> float:
    """Noise standard deviation of the readings [log units], robustly.

    From the still stretches (hold, stuck tail: runs of samples within a few MADs of each
    other at the start and end of every run) where there are any, else from the third
    differences (variance ``20·σ²`` for white noise; an upper bound where the motion is
    coarsely sampled). Never below ``1e-4`` of the log's angle span (the simulator's accuracy).
    """
    pieces, owner = _still_pieces(runs)
    span = max(float(np.ptp(np.concatenate([r.theta for r in runs]))), 1e-300)
    sig_still = np.inf
    if pieces:
        # first differences of a still stretch: variance 2σ². The smaller of the head's
        # and tail's estimates per run (one of them may move); the stretches within
        # STILL_SPREAD of the runs' median of those, pooled: the smallest of a few
        # estimates from ~10 differences each is biased low (a 66 Hz log at 250 Hz: 0.53 σ,
        # and its stuck tails then looked like motion)
        # (each piece about its own median difference: a slow creep's steady step is
        # not noise)
        centred = [d - np.median(d) for d in pieces]
        mads = np.array([1.4826 * float(np.median(np.abs(d))) / math.sqrt(2) for d in centred])
        per_run, use = _per_run(pieces, owner, mads)
        ref = float(np.median(per_run))
        kept = [d for d, e, ok in zip(centred, mads, use) if ok and e <= STILL_SPREAD * ref]
        sig_still = 1.4826 * float(np.median(np.abs(np.concatenate(kept)))) / math.sqrt(2)
    if still_only:  # (nan where the still stretches say nothing)
        return sig_still if np.isfinite(sig_still) else float("nan")
    d3 = np.concatenate([np.diff(np.asarray(r.theta, float), 3) for r in runs if len(r.theta) > 4])
    sig_d3 = 1.4826 * float(np.median(np.abs(d3))) / math.sqrt(20.0) if d3.size else np.inf
    # Where no head or tail is noise about one level (:func:`_noisy`: every run swings
    # from its first reading to its last, a ring-down the log cuts at both ends) and every
    # run's range is within SWING_RANGE of the estimate, both took the swing for noise — at
    # 3.6 samples a period a 44 mrad swing read as 20 mrad of noise against 0.73, and
    # prepare found no run moving — and the swing's own prediction says more
    # (:func:`_ar2_sigma`).
    sig_ar2 = np.inf
    rough = min([x for x in (sig_still, sig_d3) if np.isfinite(x)], default=np.inf)
    if (pieces and np.isfinite(rough) and not any(_noisy(d) for d in pieces)
            and max(float(np.ptp(r.theta)) for r in runs) < SWING_RANGE * rough):
        sig_ar2 = _ar2_sigma(runs)
    # All are upper bounds where the "still" stretches move (a ring-down has none) or the
    # motion is coarse: the smallest positive one.
    positive = [x for x in (sig_still, sig_d3, sig_ar2) if np.isfinite(x) and x > 0]
    sig = min(positive) if positive else 0.0
    # The simulator's own error (RK4 substeps: 1.9e-5 rad on a 0.157 rad swing,
    # docs/decisions/simulator-scheme.md) is ~1e-4 of the swing; weights finer than
    # what the model can resolve only make the fit ill-conditioned (a noiseless log).
    return max(sig, 1e-4 * span)


#: Closest distinct readings of a run, in print units, at which the print lattice is the
#: readings' resolution (:func:`print_floor`): one unit (with floating-point slack).
PRINT_LATTICE_GAP = 1.5


def print_floor(runs, unit: float | None) -> float:
    """Error σ [log units] of readings whose resolution is their print unit: ``unit/√12``
    where every still stretch repeats one printed level (:func:`noise_sigma`'s still
    estimate 0: the noise is below the unit) and a run's readings step by one unit (its
    closest distinct levels within :data:`PRINT_LATTICE_GAP` units); 0 otherwise.

    An encoder finer than the print unit (2^20 counts printed in degrees to 3 decimals:
    0.34 units) or a quiet sensor printed coarsely reads each angle rounded to the unit:
    a moving reading's error is uniform on ``±unit/2`` (``unit²/12``, plus an unknown
    ``q²/12 < unit²/12`` from an encoder step ``q`` that no level difference shows), a
    still stretch one value printed again and again. The noise estimate there has nothing
    to measure: its floor was the simulator's accuracy (``1e-4`` of the span, 6× this on a
    0.3 rad swing in degrees). Readings printed far finer than their steps (a processed
    log at 1e-10) have no levels one unit apart and keep the noise estimate."""
    if not unit or not np.isfinite(unit) or unit <= 0.0:
        return 0.0
    if noise_sigma(runs, None, still_only=True) != 0.0:
        return 0.0
    gaps = [np.diff(np.unique(np.asarray(r.theta, dtype=float))) for r in runs]
    gaps = [g for g in gaps if g.size]
    if not gaps or float(np.min(np.concatenate(gaps))) > PRINT_LATTICE_GAP * unit:
        return 0.0
    return unit / math.sqrt(12.0)


def _ar2_sigma(runs) -> float:
    """Noise σ [log units] from how well each run's readings follow from their two
    predecessors: ``θₙ = a₁θₙ₋₁ + a₂θₙ₋₂ + c`` holds exactly for a damped sinusoid (a
    viscous ring-down, ``a₁ = 2r·cos ωh``, ``a₂ = −r²``) at any sampling rate, and for a
    Coulomb ring-down between its turns. White noise σ on the readings leaves residuals
    ``eₙ − a₁eₙ₋₁ − a₂eₙ₋₂`` of standard deviation ``σ·√(1 + a₁² + a₂²)``; their MAD (a
    few switches of a Coulomb centre are outliers) over all runs, least squares per run
    of ≥ 8 readings. An upper bound where the motion follows no such recurrence; inf
    where no run is long enough."""
    scaled = []
    for r in runs:
        th = np.asarray(r.theta, dtype=float)
        if th.size < 8:
            continue
        A = np.column_stack([th[1:-1], th[:-2], np.ones(th.size - 2)])
        coef, *_ = np.linalg.lstsq(A, th[2:], rcond=None)
        res = th[2:] - A @ coef
        scaled.append(res / math.sqrt(1.0 + coef[0] ** 2 + coef[1] ** 2))
    if not scaled:
        return np.inf
    e = np.concatenate(scaled)
    return 1.4826 * float(np.median(np.abs(e - np.median(e))))


#: Noise ahead of the rounding counts where it raises the readings' error above the grid's
#: step/√12 by over 10 % (σ ≥ 0.13 step) and the still stretches say so beyond chance: the
#: likelihood at the estimate exceeds that at σ = 0.1 step by more than 3 (χ²₁ of 6,
#: p ≈ 0.01). A clean grid's still level (one reading, or a flicker between two adjacent
#: ones) is as likely without noise: an encoder never gains a floor.
ADC_MIN_SIGMA, ADC_NULL_SIGMA, ADC_MIN_GAIN = 0.13, 0.1, 3.0

#: Share of a still stretch's readings allowed to be anything (:func:`_level_loglik`):
#: 0.45 steps of noise reads 2 steps off 1 time in 1000, at 20× this mixture's density.
ADC_OUTLIER = 1e-3


def _level_loglik(k: np.ndarray, s: np.ndarray, x: np.ndarray) -> np.ndarray:
    """Log-likelihood ``(len(s), len(x))`` of integer readings ``k`` [steps] of a held level
    ``x`` [steps] read through Gaussian noise ``s`` [steps] and rounded to the step:
    ``P(k) = Φ((k + ½ − x)/s) − Φ((k − ½ − x)/s)``, mixed with :data:`ADC_OUTLIER` of
    readings spread over ±10 steps (a stretch's first or last sample of motion, a glitch,
    costs a bounded amount instead of setting ``s``)."""
    from scipy.special import ndtr

    levels, counts = np.unique(k, return_counts=True)
    z = (levels[None, None, :] - x[None, :, None]) / s[:, None, None]
    half = 0.5 / s[:, None, None]
    hi, lo = z + half, z - half
    # upper tail where both are above 0 (Φ(−lo) − Φ(−hi) there, no cancellation)
    p = np.where(lo > 0, ndtr(-lo) - ndtr(-hi), ndtr(hi) - ndtr(lo))
    p = (1.0 - ADC_OUTLIER) * p + ADC_OUTLIER / 21.0
    return np.sum(counts * np.log(p), axis=-1)


def adc_noise(runs, step: float) -> float:
    """Noise σ [log units] ahead of the rounding to a grid of ``step`` (an analog sensor read
    by an ADC), from how the still stretches' readings spread over the levels; 0 where it
    is not significant (:data:`ADC_MIN_SIGMA`).

    A still stretch at ``x`` (in steps, any offset from the levels) read through noise ``s``
    gives reading ``k`` with probability ``Φ((k+½−x)/s) − Φ((k−½−x)/s)``: a level near the
    middle of a step flickers out to its neighbours ever more often as ``s`` grows, one near
    a boundary splits between two levels whatever ``s``. The maximum-likelihood ``s``,
    common to the stretches (each its own ``x``), over a log grid of 0.02–3 steps; the
    stretches are every run's head and tail (as :func:`grid_noise`), per run the stiller
    (its own maximum-likelihood ``s``), those within :data:`STILL_SPREAD` of the runs'
    median (or within half a step) pooled. Moving stretches spread far wider."""
    pieces, owner, stretches = [], [], []
    for k, run in enumerate(runs):
        th = np.asarray(run.theta, dtype=float)
        m = max(4, min(50, len(th) // 10))
        for seg in (th[:m], th[-m:]):
            if seg.size >= 4:
                lv = np.round((seg - float(np.median(seg))) / step)
                stretches.append(lv)
                pieces.append(np.diff(seg))
                owner.append(k)
    if not stretches:
        return 0.0
    s = np.geomspace(0.02, 3.0, 40)  # [steps] (14 % apart)
    x = np.linspace(-1.0, 1.0, 161)  # (0.0125 steps)
    ll = np.array([np.max(_level_loglik(lv, s, x), axis=1) for lv in stretches])  # (n, s)
    own = s[np.argmax(ll, axis=1)]
    per_run, use = _per_run(pieces, np.asarray(owner, dtype=int), own)
    ref = float(np.median(per_run))
    keep = use & (own <= max(STILL_SPREAD * ref, 0.5))
    total = np.sum(ll[keep], axis=0)
    best = int(np.argmax(total))
    null = float(np.interp(ADC_NULL_SIGMA, s, total))
    if s[best] < ADC_MIN_SIGMA or total[best] - null <= ADC_MIN_GAIN:
        return 0.0
    if 0 < best < s.size - 1:  # the parabola's vertex in log s
        y0, y1, y2 = total[best - 1:best + 2]
        den = y0 - 2.0 * y1 + y2
        shift = 0.5 * (y0 - y2) / den if den < 0 else 0.0
        return float(s[best] * (s[1] / s[0]) ** shift) * step
    return float(s[best]) * step


def noise_ahead(runs, step: float) -> float:
    """The readings' error σ [log units], rounding to the ``step`` grid included, where noise
    ahead of the rounding counts; 0 where the grid's ``step/√12`` stands. Noise of half a
    step and more jumps still stretches by two steps (:func:`grid_noise`); below that the
    spread over the levels says (:func:`adc_noise`), and the error is
    ``√(σ² + step²/12)`` (Sheppard: the moving readings' offsets from the levels are spread
    evenly)."""
    jumps = grid_noise(runs, step)
    if jumps > 2.0 * step / math.sqrt(12.0):
        return jumps
    s = adc_noise(runs, step)
    return math.sqrt(s * s + step * step / 12.0) if s > 0.0 else 0.0
