"""STS3215 drops: one inertia against the motor's rotor behind the gear's free play, fitted by
the same machinery (``hdid.effects._rotor_free_play``: hdid's simulator cannot carry the
rotor's own speed), so that before and after differ only by the rotor.

Each set-up's runs are fitted from their release (the hold before it is the servo's, still
lifting) until the arm last moves (its last reading more than 1.5 counts off its rest, +50 ms):
the smooth dry friction (``tanh(ω/0.01 rad/s)``) would creep after that. Per set-up: m·g·l,
hdid's Stribeck + viscous law on the arm, and per run the release angle and instant; the
lab's total inertia held, as in hdid's fits. The rotor adds J_r, the gap b and its friction
τ_r. Least squares (scipy, trust region, forward-mode Jacobian), unweighted readings.
"""

from __future__ import annotations

import json
import math

import numpy as np

LAW = ["mgl", "tau_c", "tau_s", "v_s", "delta", "c_v"]
ROTOR = ["j_r", "backlash", "tau_r"]
STEP = 2 * math.pi / 4096  # the servo's 12-bit encoder [rad]
FLOOR = STEP / math.sqrt(12)  # rounding floor of a reading [rad]


def load(real, setup: str):
    """The set-up's runs (one-sample −π read dropouts dropped), padded to one length."""
    import pandas as pd

    ref = json.loads((real / "reference.json").read_text())["setups"][setup]
    runs = []
    for run, r in pd.read_csv(real / ref["csv"]).groupby("run", sort=False):
        t, th = r.time.to_numpy(), r.theta.to_numpy()
        med = pd.Series(th).rolling(5, center=True, min_periods=1).median().to_numpy()
        ok = np.abs(th - med) < 0.5
        t, th = t[ok], th[ok]
        moved = np.flatnonzero(np.abs(th - th[-1]) > 1.5 * STEP)
        keep = t <= (t[moved[-1]] + 0.05 if len(moved) else t[-1])
        tr = ref["runs"][run]["release_time_in_csv_s"]
        runs.append(dict(run=run, t=t[keep], th=th[keep], tr=tr, th0=float(np.median(th[t < tr - 0.02]))))
    n = max(len(r["t"]) for r in runs)

    def pad(a):
        return np.concatenate([a, np.full(n - len(a), a[-1])])

    times, data = np.stack([pad(r["t"]) for r in runs]), np.stack([pad(r["th"]) for r in runs])
    w = np.stack([(np.arange(n) < len(r["t"])) & (pad(r["t"]) >= r["tr"]) for r in runs]).astype(float)
    return ref, runs, times, data, w


class Problem:
    """One set-up's least-squares problem; ``rotor``: None (one inertia), ``"free"`` or a
    held ``(j_r, b, tau_r)``; ``data``: readings to fit in place of the log's (same instants)."""

    def __init__(self, real, setup, rotor=None, data=None):
        import jax
        import jax.numpy as jnp

        from hdid.effects._rotor_free_play import DropLaw, RotorFreePlay, simulate_drops

        self.ref, self.runs, self.times, self.data, self.w = load(real, setup)
        self.data = self.data if data is None else np.asarray(data, dtype=float)
        self.inertia, self.R, self.rotor = self.ref["bam_m6_total_inertia_kgm2"], len(self.runs), rotor
        self.nr = 3 if rotor == "free" else 0
        dur = float(np.max(self.times - np.array([r["tr"] for r in self.runs])[:, None])) + 0.1

        def unpack(x):
            rot = None
            if self.rotor is not None:
                rv = x[6:9] if self.rotor == "free" else jnp.asarray(self.rotor, dtype=float)
                rot = RotorFreePlay(j_r=rv[0], backlash=rv[1], tau_r=rv[2])
            return DropLaw(*[x[i] for i in range(6)]), rot, x[6 + self.nr:6 + self.nr + self.R], x[6 + self.nr + self.R:]

        def model(x):
            law, rot, th0, tr = unpack(x)
            return simulate_drops(law, rot, self.inertia, self.times, th0, tr, duration=dur)

        def resid(x):  # a step into an unstable corner (a near-zero arm inertia) is refused, not NaN
            r = ((model(x) - self.data) * self.w).ravel()
            return jnp.where(jnp.isfinite(r), r, 10.0)

        self.model = jax.jit(model)
        self.f = jax.jit(resid)
        self.jac = jax.jit(lambda x: jnp.clip(jnp.nan_to_num(jax.jacfwd(resid)(x), nan=0.0, posinf=0.0,
                                                             neginf=0.0), -1e6, 1e6))

    def bounds(self):
        # the arm keeps at least its point mass's m·l² (known geometry)
        arm = self.ref["mass_kg"] * self.ref["length_m"] ** 2
        rot_lo, rot_hi = [1e-4, 0.0, 0.0][:self.nr], [self.inertia - arm, 0.5, 2.0][:self.nr]
        tr = np.array([r["tr"] for r in self.runs])
        lo = np.r_[[0.05, 0, 0, 1e-3, 0.5, 0], rot_lo, [-3] * self.R, tr - 0.05]
        hi = np.r_[[20, 1e5, 20, 1e3, 4, 20], rot_hi, [3] * self.R, tr + 0.05]
        return lo, hi

    def fit(self, x0):
        import jax.numpy as jnp
        from scipy.optimize import least_squares

        lo, hi = self.bounds()
        x0 = np.clip(np.asarray(x0, float), lo + 1e-9 * (hi - lo), hi - 1e-9 * (hi - lo))
        return least_squares(lambda x: np.asarray(self.f(jnp.asarray(x))), x0,
                             jac=lambda x: np.asarray(self.jac(jnp.asarray(x))), bounds=(lo, hi),
                             x_scale="jac", max_nfev=60, ftol=1e-10, xtol=1e-10).x

    def residual(self, x):
        import jax.numpy as jnp

        return np.asarray(self.f(jnp.asarray(x))).reshape(self.w.shape)

    def rms(self, x) -> float:
        """RMS residual over the fitted readings / the rounding floor."""
        return float(np.sqrt(np.sum(self.residual(x) ** 2) / self.w.sum())) / FLOOR

    def fast(self, x) -> float:
        """Sample-to-sample part / floor: residual minus its 5-sample running mean, ×√(5/4)."""
        tot = n = 0.0
        for rr, ww in zip(self.residual(x), self.w):
            rr = rr[ww > 0]
            tot, n = tot + np.sum((rr - np.convolve(rr, np.ones(5) / 5, "same")) ** 2), n + len(rr)
        return math.sqrt(1.25 * tot / n) / FLOOR

    def quarters(self, x) -> list[list[float]]:
        """Per run, data − model durations [ms] of release → bottom, bottom → turning point,
        turning point → bottom, ... (events of :func:`events`, each on 4-reading means of
        the data and of the model at the same instants)."""
        import jax.numpy as jnp

        model = np.asarray(self.model(jnp.asarray(x)))
        tr = np.asarray(x[6 + self.nr + self.R:])
        out = []
        for k, run in enumerate(self.runs):
            n = len(run["t"])
            ed, em = events(run["t"], self.data[k, :n], tr[k]), events(run["t"], model[k, :n], tr[k])
            q, prev = [], (tr[k], tr[k])
            for a, b in zip(ed, em):
                if a[0] != b[0]:
                    break
                q.append(1e3 * ((a[1] - prev[0]) - (b[1] - prev[1])))
                prev = (a[1], b[1])
            out.append(q)
        return out


def events(t, th, tr):
    """Bottom crossings (θ = 0, linear interpolation) and the turning points between them
    (vertex of a quadratic through ±4 samples of the extreme), on 4-reading means after
    release: the servo's 8 ms encoder clock ages readings in a 4-poll sawtooth, the mean
    nulls it."""
    box = np.ones(4) / 4
    tm, y = np.convolve(t, box, "valid"), np.convolve(th, box, "valid")
    tm, y = tm[tm > tr], y[tm > tr]
    bottoms, side = [], np.sign(y[0])
    for i in range(len(y) - 1):
        if np.sign(y[i + 1]) == -side and abs(y[i + 1]) > 0.005:  # crossed by > 3 counts
            j = i
            while j > 0 and np.sign(y[j]) == -side:
                j -= 1
            bottoms.append(tm[j] + (tm[j + 1] - tm[j]) * y[j] / (y[j] - y[j + 1]))
            side = -side
    ev = []
    for k, tb in enumerate(bottoms):
        ev.append(("B", tb))
        if k + 1 < len(bottoms):
            seg = np.flatnonzero((tm > tb) & (tm < bottoms[k + 1]))
            i = seg[np.argmax(np.abs(y[seg]))]
            a, b = max(i - 4, 0), min(i + 5, len(y))
            c = np.polyfit(tm[a:b] - tm[i], y[a:b], 2)
            ev.append(("T", tm[i] - c[1] / (2 * c[0]) if c[0] != 0 else tm[i]))
    return ev


def median_quarters(q: list[list[float]], n: int = 5) -> list[float | None]:
    """Median over runs of each of the first ``n`` quarters (None where no run has it)."""
    out = []
    for j in range(n):
        v = [r[j] for r in q if len(r) > j]
        out.append(float(np.median(v)) if v else None)
    return out


def signature(real, setup: str, law: dict, rotors) -> list[dict]:
    """What the rotor leaves in a one-inertia fit: noiseless drops of ``setup`` (its runs'
    instants, release angles and times; arm law ``law``) made with each held rotor of
    ``rotors``, fitted with one inertia; the quarters' data − model as for a log."""
    import jax.numpy as jnp

    out = []
    for rotor in rotors:
        gen = Problem(real, setup, tuple(rotor))
        x = np.r_[[law[n] for n in LAW], [r["th0"] for r in gen.runs], [r["tr"] for r in gen.runs]]
        one = Problem(real, setup, data=np.asarray(gen.model(jnp.asarray(x))))
        y = one.fit(x)
        out.append(dict(setup=setup, rotor=dict(zip(ROTOR, map(float, rotor))), rms=one.rms(y),
                        mgl=float(y[0]), mgl_true=float(x[0]), quarters=median_quarters(one.quarters(y))))
    return out
