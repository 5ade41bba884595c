"""How well a candidate experiment would tell two fitted models apart.

Given two fits of one log by different models ``A`` and ``B`` (two diagnose candidates:
a ripple and a kinematic error, backlash and hysteresis), a candidate's noise-free
readings under ``A`` are fitted by ``B``. The expected ``2·ln LR`` in ``A``'s favour is
that fit's χ² (a noncentrality: with noise the expected value adds nothing), in units of
the candidate's quantization variance ``step²/12``. The separation of the pair is the
smaller of the two directions (data from ``A`` fitted by ``B``, and from ``B`` by ``A``).

Linearised (:func:`separation`), at ``B``'s fitted values for the *log*: the part of the
readings' difference ``W (θ_A − θ_B)/σ`` that ``B``'s Jacobian (physical parameters and
every run's nuisances) cannot absorb,

    2 ln LR_A≻B ≈ |r|² − |Q Qᵀ r|²,   r = W (θ_A − θ_B)/σ,   J_B = Q R.

On a design far from the log's, ``B``'s best approximation of ``A`` moves far from its fit
to the log, and the linearised value overstates the separation (1e3–1e5 on new designs
where refitting leaves tens). :func:`separations` therefore also *refits*: ``B``'s
parameters and nuisances are moved by Levenberg–Marquardt steps on the exact simulator
(every candidate of a sample rate in one simulation per step, :mod:`._stack`) until the
χ² stops falling; the refitted χ² is the computed ``2·ln LR``. Where the refit did not
converge within ``REFIT_STEPS`` it is an upper bound, and where it differs from the
linearised value by more than ``CREDIBLE_FACTOR`` the linearisation is not credible
there (:attr:`Separation.credible`). The local refit has no multi-start: a rival optimum
behind a change of the stick–slip sequence may not be reached, so a locally refitted value
is an upper bound on the noncentrality (3–25× the realised 2·ln LR on the confusable pairs
of ``benchmarks/design_check.py``). The ``best_of`` experiments with the largest local
values (and ``include``, the log's own design) are then fitted *globally*: the rival by
:func:`hdid.fit`'s own multi-start driver on the other form's noise-free readings
(:mod:`._best_rival`), which makes the separation a value, not a bound, and gives the mean
and spread a noisy log's ``2·ln LR`` has around it (:meth:`Separation.expected`).

A test engineer cannot choose the instant within a sample at which each run is released,
and on a coarsely sampled design the separation lives in a few moving samples: which
points of a free-play corner they hit depends on it. On the paper plant at 250 Hz (about
four samples a period, 36 effective readings), backlash against soft wind-up with a
64 000-count encoder gives ``λ`` 23.3 at the source log's fitted release instants,
0.03–2.1 with every run released at the same phase, and 2.4–10.9 (mean 6.8) with each
run's phase drawn at random, the way :func:`hdid._design._check.simulate_logs` draws
them; simulated logs realised a mean 2·ln LR of 5.1 (λ̄ + k_A − k_B = 4.8). A globally
fitted separation is therefore the mean over ``PHASE_DRAWS`` sets of release instants
(the log's own first, then each run's phase uniform in its sample interval), and the
draws' variance joins a noisy log's spread (:meth:`Separation.expected`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .._config import float64
from . import _stack
from . import _best_rival
from ._candidates import Experiment
from ._fisher import as_log, max_substep, parameter_names, readings

#: Levenberg–Marquardt steps of the rival's refit (each one simulation per sample rate).
REFIT_STEPS = 8
#: A refit whose χ² fell by less than this fraction in a step has stopped.
REFIT_RTOL = 1e-3
#: The linearised value within this factor of the refitted one is credible.
CREDIBLE_FACTOR = 2.0
#: Singular values below this fraction of the largest are no direction of a refit.
RCOND = 1e-10
#: Sets of release instants a globally fitted separation is averaged over (module
#: docstring): the experiment's own, then random phases within the sample interval.
PHASE_DRAWS = 4
#: After two draws, stop where their variance ``(λ₁ − λ₀)²/2`` is under this fraction of
#: a noisy log's ``4λ̄ + 2|k_A − k_B|``: the release phase then adds under a tenth to the
#: spread of the 2·ln LR a log gives (a densely sampled design: every rich log measured).
PHASE_SETTLED = 0.1
#: Seed of the drawn release phases (the same draws for every call: reproducible).
PHASE_SEED = 0


@dataclass
class Separation:
    """The expected ``2·ln LR`` of one experiment between fits ``A`` and ``B``."""

    experiment: Experiment
    #: linearised at each fit to the log: ``(A true, B true)``
    linear: tuple[float, float]
    #: after refitting the rival on the noise-free readings: ``(A true, B true)``
    refitted: tuple[float, float] = (math.nan, math.nan)
    #: whether each refit stopped (its χ² no longer falling)
    converged: tuple[bool, bool] = (False, False)
    #: the rival's global fit (:mod:`._best_rival`): ``min χ²`` ``(A true, B true)``, the
    #: smaller of it and the local refit's (NaN: not fitted globally)
    best: tuple[float, float] = (math.nan, math.nan)
    #: physical parameters each form fits ``(k_A, k_B)``, and ``tr((P_A − P_B)²)`` at the
    #: design (the spread of a noisy log's 2·ln LR, :func:`._best_rival.expected`)
    k: tuple[int, int] = (0, 0)
    trace: float | None = None
    #: the rival's global ``min χ²`` at each set of release instants ``(A true, B true)``
    #: (the experiment's own first; ``best`` is their mean, module docstring)
    draws: tuple[tuple[float, ...], tuple[float, ...]] = ((), ())

    @property
    def fitted(self) -> bool:
        """Whether the rival was fitted globally in both directions (a value, not a bound)."""
        return all(math.isfinite(x) for x in self.best)

    @property
    def value(self) -> float:
        """The separation ``λ`` (noise-free): the smaller direction, globally fitted where
        fitted, else refitted locally (an upper bound), else linearised."""
        if self.fitted:
            return min(self.best)
        ref = min(self.refitted)
        return ref if math.isfinite(ref) else min(self.linear)

    def expected(self) -> tuple[tuple[float, float], tuple[float, float]]:
        """``((mean, sd) with A true, (mean, sd) with B true)`` of a noisy log's 2·ln LR
        (:func:`._best_rival.expected`; from the local refit where not fitted globally)."""
        lam = self.best if self.fitted else self.refitted
        ka, kb = self.k
        out = []
        for lam_i, d, (kt, kr) in zip(lam, self.draws, ((ka, kb), (kb, ka))):
            mean, sd = _best_rival.expected(lam_i, kt, kr, self.trace)
            v = np.asarray([x for x in d if math.isfinite(x)])
            if self.fitted and v.size > 1:  # the release phase's share of the spread
                sd = math.sqrt(sd**2 + float(v.var(ddof=1)))
            out.append((mean, sd))
        return out[0], out[1]

    @property
    def credible(self) -> bool:
        """Refitted in both directions, and in each the linearised value within
        ``CREDIBLE_FACTOR`` of the refitted one (give or take one quantization variance:
        a separation below that is none either way)."""
        if not all(math.isfinite(x) for x in (*self.refitted, *self.linear)):
            return False
        return all(ref <= CREDIBLE_FACTOR * lin + 1.0 and lin <= CREDIBLE_FACTOR * ref + 1.0
                   for lin, ref in zip(self.linear, self.refitted))

    def to_dict(self) -> dict:
        (ma, sa), (mb, sb) = self.expected()
        lam = self.best if self.fitted else self.refitted
        return {"experiment": self.experiment.name, "description": self.experiment.describe(),
                "expected_2lnlr": self.value,
                "value_kind": "rival fitted globally" if self.fitted else "upper bound",
                "a_true": lam[0], "b_true": lam[1],
                "noisy_log": {"a_true": {"mean": ma, "sd": sa}, "b_true": {"mean": mb, "sd": sb}},
                "locally_refitted": {"a_true": self.refitted[0], "b_true": self.refitted[1]},
                "release_draws": {"a_true": list(self.draws[0]), "b_true": list(self.draws[1])},
                "linearised": {"a_true": self.linear[0], "b_true": self.linear[1]},
                "refit_converged": list(self.converged),
                "linearisation_credible": self.credible}


@float64
def separation(fit_a, fit_b, experiments: list[Experiment]) -> list[tuple[float, float]]:
    """``(2 ln LR with A true, with B true)`` for every experiment, linearised (NaN where
    a design gives no usable log)."""
    ma, mb = _Model(fit_a, experiments), _Model(fit_b, experiments)
    return [(_Direction(ma, mb, i, e).linear, _Direction(mb, ma, i, e).linear)
            for i, e in enumerate(experiments)]


@float64
def separations(fit_a, fit_b, experiments: list[Experiment], steps: int = REFIT_STEPS,
                best_of: int = 0, include: tuple[int, ...] = (), certify: int = 0
                ) -> list[Separation]:
    """Linearised and locally refitted separation of every experiment; the ``best_of``
    largest local values and the experiments at positions ``include`` then with the rival
    fitted globally (module docstring). ``certify``: then, at most that many more times,
    the rival of the largest separation fitted globally while it is still a local upper
    bound — at the experiment's own release instants a global fit only lowers a value
    (:func:`_fit_globally` keeps the smaller), so once the largest is a globally fitted
    value, no other experiment's own-instant value can beat it (the other drawn instants
    can move a value either way: the mean over them is the prediction)."""
    ma, mb = _Model(fit_a, experiments), _Model(fit_b, experiments)
    ab = [_Direction(ma, mb, i, e) for i, e in enumerate(experiments)]  # A true, B fitted
    ba = [_Direction(mb, ma, i, e) for i, e in enumerate(experiments)]
    out = [Separation(e, (d1.linear, d2.linear)) for e, d1, d2 in zip(experiments, ab, ba)]
    _refit(mb, ab, steps)
    _refit(ma, ba, steps)
    k = (_best_rival.n_physical(fit_a), _best_rival.n_physical(fit_b))
    for s, d1, d2 in zip(out, ab, ba):
        s.refitted = (d1.chi2, d2.chi2)
        s.converged = (d1.converged, d2.converged)
        s.k = k
    order = sorted((i for i, s in enumerate(out)
                    if i not in include and math.isfinite(s.value)),
                   key=lambda i: -out[i].value)
    tried = set()
    for i in (*include, *order[:best_of]):
        if ab[i].ok and ba[i].ok:
            _fit_globally(out[i], fit_a, fit_b, ab[i], ba[i])
            tried.add(i)
    for _ in range(certify):
        live = [i for i, s in enumerate(out) if math.isfinite(s.value) and ab[i].ok and ba[i].ok]
        top = max(live, key=lambda i: out[i].value, default=None)
        if top is None or top in tried:  # a value already (or its global fit failed)
            break
        _fit_globally(out[top], fit_a, fit_b, ab[top], ba[top])
        tried.add(top)
    return out


def _fit_globally(s: Separation, fit_a, fit_b, ab: "_Direction", ba: "_Direction",
                  draws: int | None = None) -> None:
    """``s.best``: each rival fitted by :func:`hdid.fit` to the other's noise-free
    readings (:func:`._best_rival.rival_chi2`) — at the experiment's own release instants
    the smaller of it and the local refit — averaged over ``draws`` sets of release
    instants (module docstring; ``s.draws`` each; the other instants' rival fitted from its
    optimum at the own instants too, :func:`._best_rival.rival_fit`); ``s.trace``:
    ``tr((P_A − P_B)²)`` from both forms' Jacobians at the design."""
    e = s.experiment
    lam_a, ra = _best_rival.rival_fit(fit_b, e, ab.y, truth=fit_a)  # A true: B fitted to A's
    lam_b, rb = _best_rival.rival_fit(fit_a, e, ba.y, truth=fit_b)
    va = [float(np.nanmin([lam_a, ab.chi2])) if math.isfinite(lam_a) else math.nan]
    vb = [float(np.nanmin([lam_b, ba.chi2])) if math.isfinite(lam_b) else math.nan]
    Ub, Ua = ab._svd(ab.system()[0])[0], ba._svd(ba.system()[0])[0]
    if Ua.shape[0] == Ub.shape[0]:
        s.trace = _best_rival.projection_trace(Ua, Ub)
    draws = PHASE_DRAWS if draws is None else draws
    if draws > 1 and math.isfinite(va[0]) and math.isfinite(vb[0]):
        others = phase_draws(e, draws - 1)
        ya, yb = _trajectories(fit_a, others), _trajectories(fit_b, others)
        spread = 2.0 * (s.trace if s.trace is not None else abs(s.k[0] - s.k[1]))
        for j, ej in enumerate(others):  # each started from the own instants' rival optimum too
            va.append(_best_rival.rival_fit(fit_b, ej, ya[j], near=ra)[0])
            vb.append(_best_rival.rival_fit(fit_a, ej, yb[j], near=rb)[0])
            if j == 0 and all(_settled(v, spread) for v in (va, vb)):
                break
    s.draws = (tuple(va), tuple(vb))
    s.best = tuple(float(np.mean([x for x in v if math.isfinite(x)]))
                   if math.isfinite(v[0]) else math.nan for v in (va, vb))


def _settled(v: list[float], spread: float) -> bool:
    """Two draws whose variance is under ``PHASE_SETTLED`` of a noisy log's (module
    docstring): more draws would not move the prediction at a log's precision."""
    if not all(math.isfinite(x) for x in v):
        return False
    var = (v[1] - v[0]) ** 2 / 2.0
    return var <= PHASE_SETTLED * (4.0 * float(np.mean(v)) + spread)


def phase_draws(e: Experiment, n: int, seed: int = PHASE_SEED) -> list[Experiment]:
    """``n`` copies of ``e`` with each run released at a random phase of the sample
    interval after its hold (uniform, as :func:`._check.simulate_logs` draws them)."""
    import dataclasses

    rng = np.random.default_rng(seed)
    return [dataclasses.replace(e, releases=tuple(e.hold + rng.uniform(0.0, 1.0, e.n_runs) / e.rate))
            for _ in range(n)]


def _trajectories(fit, experiments: list[Experiment]) -> list[np.ndarray]:
    """Noise-free trajectories ``(R, n)`` of each experiment (one sample rate) under
    ``fit`` (the spring frame, as the stacks' ``theta``), one simulation for all."""
    _, every = parameter_names(fit)
    st = _stack.stack(list(enumerate(experiments)), fit, every, max_substep(fit))
    theta = _stack.trajectories(st, st.local[None])[0]
    return [theta[st.index[j], :e.n_samples] for j, e in enumerate(experiments)]


class _Model:
    """One fit's model simulated on every experiment (a stack per sample rate)."""

    def __init__(self, fit, experiments):
        self.fit = fit
        free, every = parameter_names(fit)
        self.free, self.every = free, every
        P = len(every)
        self.cols = [every.index(n) for n in free] + [P, P + 1, P + 2]
        groups: dict[float, list[tuple[int, Experiment]]] = {}
        for i, e in enumerate(experiments):
            groups.setdefault(float(e.rate), []).append((i, e))
        self.stacks = []
        self.where = {}
        for cands in groups.values():
            st = _stack.stack(cands, fit, every, max_substep(fit))
            _stack.evaluate(st)
            self.stacks.append(st)
            for pos, _ in cands:
                self.where[pos] = (st, st.index[pos])

    def theta_jac(self, pos, n):
        st, rows = self.where[pos]
        return st.theta[rows, :n].copy(), st.J[rows, :n][:, :, self.cols].copy()


class _Direction:
    """Noise-free readings of experiment ``e`` under ``truth`` fitted by ``fitted``."""

    def __init__(self, truth: _Model, fitted: _Model, pos: int, e: Experiment):
        from .._errors import HdidError
        from .._simulation._prepare import prepare

        self.fitted, self.pos, self.e = fitted, pos, e
        self.y, _ = truth.theta_jac(pos, e.n_samples)
        self.theta, self.J = fitted.theta_jac(pos, e.n_samples)
        st, rows = fitted.where[pos]
        self.local = st.local[rows].copy()
        self.chi2 = self.linear = math.nan
        self.converged = False
        self.lam = 1e-3
        self.w = None
        if not (np.all(np.isfinite(self.y)) and np.all(np.isfinite(self.theta))
                and np.all(np.isfinite(self.J))):
            return
        quantized = bool(fitted.fit.resolution_known)
        try:
            prep = prepare(as_log(e, readings(e, self.y, quantized), e.name, quantized))
        except HdidError:
            return
        self.w = prep.weight[:, :e.n_samples]
        self.sigma = e.resolution / math.sqrt(12.0)
        A, r = self.system()
        self.chi2 = float(r @ r)
        self.linear = self.chi2 - self._absorbed(A, r)

    @property
    def ok(self) -> bool:
        return self.w is not None and math.isfinite(self.chi2)

    def system(self):
        """Weighted design matrix (physical, each run's release and start, each set-up's
        offset) and residual of the current state."""
        e, P = self.e, len(self.fitted.free)
        R, setups, m = e.n_runs, e.setup_names, e.n_samples
        A = np.zeros((R * m, P + 2 * R + len(setups)))
        r = np.zeros(R * m)
        for j in range(R):
            rows = slice(j * m, (j + 1) * m)
            wj = self.w[j][:, None] / self.sigma
            A[rows, :P] = wj * self.J[j][:, :P]
            A[rows, P + j] = wj[:, 0] * self.J[j][:, P]
            A[rows, P + R + j] = wj[:, 0] * self.J[j][:, P + 1]
            A[rows, P + 2 * R + setups.index(e.setups[j])] = wj[:, 0] * self.J[j][:, P + 2]
            r[rows] = self.w[j] * (self.y[j] - self.theta[j]) / self.sigma
        return A, r

    @staticmethod
    def _svd(A):
        scale = np.linalg.norm(A, axis=0)
        scale = np.where(scale > 0, scale, 1.0)
        # from the SVD (a rank-deficient J — an undetermined direction — must not add
        # directions of its own, as a plain QR would)
        U, sv, Vt = np.linalg.svd(A / scale, full_matrices=False)
        keep = sv > RCOND * sv.max() if sv.size else sv > 0
        return U[:, keep], sv[keep], Vt[keep], scale

    def _absorbed(self, A, r) -> float:
        U, _, _, _ = self._svd(A)
        return float(np.sum((U.T @ r) ** 2))

    def trial(self) -> np.ndarray | None:
        """Local unknowns after one Levenberg–Marquardt step (``None``: nothing to do)."""
        A, r = self.system()
        U, sv, Vt, scale = self._svd(A)
        proj = U.T @ r
        # the linearised fit would lower χ² by |Uᵀr|²: a refit that cannot gain a
        # thousandth of it (or 1e-6 quantization variances) has stopped
        if not sv.size or float(proj @ proj) <= REFIT_RTOL * self.chi2 + 1e-6:
            self.converged = True
            return None
        lam = self.lam * sv[0] ** 2
        delta = (Vt.T @ ((sv / (sv**2 + lam)) * proj)) / scale
        e, P = self.e, len(self.fitted.free)
        R, setups = e.n_runs, e.setup_names
        local = self.local.copy()
        for j in range(R):
            idx = self.fitted.cols
            local[j, idx[:P]] += delta[:P]
            local[j, idx[P]] += delta[P + j]
            local[j, idx[P + 1]] += delta[P + R + j]
            local[j, idx[P + 2]] += delta[P + 2 * R + setups.index(e.setups[j])]
        return local


def _refit(fitted: _Model, directions: list[_Direction], steps: int) -> None:
    """Refit ``fitted``'s model to each direction's readings (all experiments of a stack
    in one simulation per step)."""
    live = [d for d in directions if d.ok]
    for _ in range(steps):
        live = [d for d in live if not d.converged]
        if not live:
            return
        trials = {}
        for st in fitted.stacks:
            mine = [d for d in live if fitted.where[d.pos][0] is st]
            if not mine:
                continue
            local = st.local.copy()
            for d in mine:
                t = d.trial()
                if t is None:
                    continue
                trials[id(d)] = t
                local[fitted.where[d.pos][1]] = t
            saved = (st.local, st.theta, st.J)
            st.local, st.theta, st.J = local, None, None
            _stack.evaluate(st)
            for d in mine:
                if id(d) not in trials:
                    continue
                theta, J = fitted.theta_jac(d.pos, d.e.n_samples)
                old = d.chi2
                if np.all(np.isfinite(theta)) and np.all(np.isfinite(J)):
                    keep = (d.theta, d.J)
                    d.theta, d.J = theta, J
                    _, r = d.system()
                    new = float(r @ r)
                    if new < old:
                        d.local, d.chi2 = trials[id(d)], new
                        d.lam = max(d.lam / 10.0, 1e-9)
                        d.converged = old - new <= REFIT_RTOL * old
                        continue
                    d.theta, d.J = keep
                d.lam *= 10.0
                d.converged = d.lam > 1e6
            st.local, st.theta, st.J = saved
