"""An independent generator of free-motion test logs (issue 16, "Real logs").

Pure numpy/scipy: it imports nothing from hdid (not its simulators, effects or reader), so
logs made here test hdid against physics written a second time, by someone else, in a
different way: event-driven ``scipy.integrate.solve_ivp`` (DOP853, tight tolerances) with a
terminal event at every zero of the velocity and an exact set-valued stick/slip decision
there, instead of hdid's fixed RK4 substeps with split steps.

The plant, at the logged axis (the wave generator, WG; the output is locked)::

    I·θ̈ = −T_k(θ/N)/N − (mgl/N)·sin(θ/N) − tau_0 − τ_f(θ̇)
    T_k(d) = k1·d + k2·d³                                  (output side)
    τ_f(ω) = s·(tau_c + (tau_s − tau_c)·exp(−|ω/v_s|^delta)) + c_v·ω      sliding in s
    at ω = 0: stuck for good when |F(θ)| ≤ tau_s, F the rest torque (first line without
    τ_f); otherwise it slides on in the direction of F.

θ is measured from the spring's (or the hanging pendulum's) zero; the log holds the
reading ``θ + offset(set-up)``, optionally with Gaussian noise, quantized to an encoder on
the WG or on the output (whose step at the WG is ``N·2π/counts``) or not at all (analog).
The system is autonomous, so once stuck it stays stuck (the log may end before that).

A log is a pandas DataFrame in hdid's free-motion CSV format (columns ``run, setup,
time, theta``) plus a ``truth`` dict: the parameters under hdid's names, ``inertia``,
``ratio``, per-run ``theta0``/``omega0``/``t_release``/rest point, per-set-up offsets,
``resolution`` (encoder step at the logged axis, ``None`` for analog), ``noise``,
``rate``, ``natural_frequency_hz`` and ``units``.

Scenarios for the issue's "Must show": :func:`pendulum_drop`, :func:`ring_down`,
:func:`paper_design` (with :data:`GEARS`) and :func:`in_units`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
import pandas as pd
from scipy.integrate import solve_ivp

__all__ = [
    "GEARS",
    "Plant",
    "Trajectory",
    "gear_plant",
    "in_units",
    "make_log",
    "paper_design",
    "pendulum_drop",
    "ring_down",
    "trajectory",
]


@dataclass(frozen=True)
class Plant:
    """Physical parameters at the logged axis (SI units; torques at the WG, stiffness and
    ``mgl`` at the output, ``N`` the gear ratio)."""

    inertia: float
    ratio: float = 1.0
    k1: float = 0.0
    k2: float = 0.0
    mgl: float = 0.0
    tau_0: float = 0.0
    tau_c: float = 0.0
    tau_s: float | None = None  # None: equal to tau_c (no Stribeck rise)
    v_s: float = 1.0
    delta: float = 1.0
    c_v: float = 0.0

    @property
    def static(self) -> float:
        return self.tau_c if self.tau_s is None else self.tau_s

    @property
    def k_wg(self) -> float:
        """Small-swing restoring stiffness at the WG [N m/rad]."""
        return (self.k1 + self.mgl) / self.ratio**2

    @property
    def natural_frequency_hz(self) -> float:
        return math.sqrt(self.k_wg / self.inertia) / (2 * math.pi)

    def rest_torque(self, theta):
        """Net torque at rest [N m] (everything but friction)."""
        N = self.ratio
        d = np.asarray(theta, dtype=float) / N
        return -(self.k1 * d + self.k2 * d**3) / N - self.mgl * np.sin(d) / N - self.tau_0

    def friction(self, omega, s: float):
        """Sliding friction torque opposing motion in direction ``s`` [N m]."""
        rise = (self.static - self.tau_c) * np.exp(-np.abs(omega / self.v_s) ** self.delta)
        return s * (self.tau_c + rise) + self.c_v * omega

    def params(self) -> dict[str, float]:
        """The parameters under hdid's names (``tau_s`` filled in)."""
        out = asdict(self)
        out["tau_s"] = self.static
        return out


@dataclass
class Trajectory:
    """An event-driven solution from the release (time 0 here)."""

    plant: Plant
    segments: list = field(default_factory=list)  # (t0, t1, dense solution, direction)
    events: list = field(default_factory=list)  # (t, theta, "stick" | "slide+" | "slide-")
    stuck_at: tuple[float, float] | None = None  # (time, theta) of the final stick
    theta0: float = 0.0

    def __call__(self, t):
        """``(theta, omega)`` at times ``t`` [s after release] (before 0: at theta0, rest)."""
        t = np.asarray(t, dtype=float)
        theta = np.full(t.shape, self.theta0)
        omega = np.zeros(t.shape)
        for t0, t1, sol, _ in self.segments:
            m = (t >= t0) & (t <= t1)
            if np.any(m):
                y = sol(t[m])
                theta[m], omega[m] = y[0], y[1]
        if self.stuck_at is not None:
            m = t >= self.stuck_at[0]
            theta[m], omega[m] = self.stuck_at[1], 0.0
        return theta, omega

    @property
    def rest(self) -> float | None:
        return None if self.stuck_at is None else self.stuck_at[1]


def trajectory(plant: Plant, theta0: float, t_end: float, omega0: float = 0.0, *,
               rtol: float = 1e-10, max_events: int = 100000) -> Trajectory:
    """Solve from ``(theta0, omega0)`` at time 0 to ``t_end`` (or until stuck)."""
    I = plant.inertia
    wn = math.sqrt(plant.k_wg / I) if plant.k_wg > 0 else 1.0
    scale = max(abs(theta0), abs(omega0) / wn, 1e-300)
    atol = np.array([1e-12 * scale, 1e-12 * scale * wn])
    traj = Trajectory(plant=plant, theta0=float(theta0))
    t, theta, omega = 0.0, float(theta0), float(omega0)
    if omega == 0.0:
        s = _decide(plant, theta)
        if s == 0:
            traj.stuck_at = (0.0, theta)
            return traj
    else:
        s = float(np.sign(omega))
    smooth = plant.tau_c == 0.0 and plant.static == 0.0  # no set-valued friction: no events
    for _ in range(max_events):
        def rhs(_t, y, s=s):
            return (y[1], (plant.rest_torque(y[0]) - plant.friction(y[1], s)) / I)

        def zero_speed(_t, y):
            return y[1]

        zero_speed.terminal = True
        zero_speed.direction = -s  # ω leaves the sliding side
        sol = solve_ivp(rhs, (t, t_end), (theta, omega), method="DOP853", rtol=rtol,
                        atol=atol, dense_output=True, events=None if smooth else zero_speed)
        if sol.status == -1:
            raise RuntimeError(f"solve_ivp failed: {sol.message}")
        traj.segments.append((t, float(sol.t[-1]), sol.sol, s))
        if sol.status == 0:  # reached t_end sliding
            return traj
        t, theta = float(sol.t_events[0][0]), float(sol.y_events[0][0][0])
        omega = 0.0
        s = _decide(plant, theta)
        traj.events.append((t, theta, "stick" if s == 0 else ("slide+" if s > 0 else "slide-")))
        if s == 0:
            traj.stuck_at = (t, theta)
            return traj
    raise RuntimeError(f"more than {max_events} velocity zeros")


def _decide(plant: Plant, theta: float) -> float:
    """Set-valued friction at rest: 0 (stuck) or the direction it slides in."""
    F = float(plant.rest_torque(theta))
    return 0.0 if abs(F) <= plant.static else float(np.sign(F))


def make_log(plant: Plant, releases: Sequence[float], *, rate: float, duration: float,
             hold: float = 0.0, omega0: Sequence[float] | float = 0.0,
             setups: Sequence[str] | None = None, offsets: dict[str, float] | None = None,
             counts_per_rev: float | None = None, encoder: str = "wg", noise: float = 0.0,
             release_phase: Sequence[float] | float = 0.37, time_origin: float = 0.0,
             seed: int = 0) -> tuple[pd.DataFrame, dict]:
    """One log: a run per release (``theta0`` from the zero, at the WG [rad]).

    ``hold`` seconds of pre-release hold (the release falls ``release_phase`` of a sample
    interval after the last hold sample); ``hold=0`` starts the log at the release
    instant itself (with ``omega0`` nonzero: a ring-down already in motion). ``duration``
    is the logged time after the release. ``encoder`` ``"wg"`` or ``"output"``: where the
    ``counts_per_rev`` encoder sits (``None``: analog, no quantization). ``noise``: Gaussian
    σ [rad at the WG] added before quantization. ``time_origin``: the first sample's time.
    """
    R = len(releases)
    omega0 = np.broadcast_to(np.asarray(omega0, dtype=float), (R,))
    phase = np.broadcast_to(np.asarray(release_phase, dtype=float), (R,))
    setups = list(setups) if setups is not None else ["A"] * R
    offsets = dict(offsets) if offsets is not None else {s: 0.0 for s in set(setups)}
    if counts_per_rev is None:
        step = None
    else:
        step = 2 * math.pi / counts_per_rev * (plant.ratio if encoder == "output" else 1.0)
    rng = np.random.default_rng(seed)
    dt = 1.0 / rate
    frames, runs = [], []
    for r, theta0 in enumerate(releases):
        n_hold = int(round(hold * rate))
        t_rel = (n_hold - 1 + phase[r]) * dt if n_hold > 0 else 0.0
        n = n_hold + int(math.floor(duration * rate + 1e-9)) + (0 if n_hold else 1)
        times = np.arange(n) * dt
        traj = trajectory(plant, theta0, times[-1] - t_rel + dt, omega0[r])
        theta, _ = traj(times - t_rel)
        reading = theta + offsets[setups[r]] + noise * rng.standard_normal(n)
        if step is not None:
            reading = np.round(reading / step) * step
        frames.append(pd.DataFrame({"run": str(r + 1), "setup": setups[r],
                                    "time": time_origin + times, "theta": reading}))
        runs.append({"run": str(r + 1), "setup": setups[r], "theta0": float(theta0),
                     "omega0": float(omega0[r]), "t_release": time_origin + t_rel,
                     "rest": traj.rest, "events": len(traj.events),
                     "stuck_at": None if traj.stuck_at is None else float(time_origin + t_rel + traj.stuck_at[0])})
    truth = {
        "params": plant.params(),
        "inertia": plant.inertia,
        "ratio": plant.ratio,
        "runs": runs,
        "offsets": offsets,
        "resolution": step,
        "counts_per_rev": counts_per_rev,
        "encoder": encoder if step is not None else "analog",
        "noise": noise,
        "rate": rate,
        "natural_frequency_hz": plant.natural_frequency_hz,
        "units": {"angle": "rad", "time": "s", "torque": "N m"},
    }
    return pd.concat(frames, ignore_index=True), truth


# -- scenarios ---------------------------------------------------------------------------

def pendulum_drop(*, ratio: float = 1.0, frequency_hz: float = 1.0, swing: float = 0.6,
                  counts_per_rev: float = 4096, rate: float = 100.0, duration: float = 6.0,
                  hold: float = 0.5, noise: float = 0.0, seed: int = 0) -> tuple[pd.DataFrame, dict]:
    """A pendulum on a servo's output, released from a hold at ±``swing`` rad (output) with
    the torque off: no spring, gravity ``mgl`` sets ``frequency_hz`` (small swings) with
    the output inertia; Stribeck friction; a ``counts_per_rev`` encoder on the OUTPUT.

    At the output: m = 0.2 kg at l = 0.1 m plus a 5e-4 kg m² arm and rotor, so
    ``I_out ≈ 2.5e-3 kg m²``; ``mgl`` follows from the frequency. Friction at the output:
    Coulomb 4 % of ``mgl``, static 7 %, Stribeck velocity 0.05 rad/s, viscous 1 % of
    critical (it sticks after about four swings from 0.6 rad); all reflected to the WG (÷N, speeds ×N, inertia ÷N²)."""
    I_out = 0.2 * 0.1**2 + 5e-4
    mgl = I_out * (2 * math.pi * frequency_hz) ** 2
    N = float(ratio)
    plant = Plant(
        inertia=I_out / N**2, ratio=N, mgl=mgl,
        tau_c=0.04 * mgl / N, tau_s=0.07 * mgl / N, v_s=0.05 * N, delta=1.0,
        c_v=0.01 * 2 * math.sqrt(mgl * I_out) / N**2,
    )
    return make_log(plant, [swing * N, -swing * N], rate=rate, duration=duration, hold=hold,
                    setups=["A", "A"], offsets={"A": 0.3 * N},
                    counts_per_rev=counts_per_rev, encoder="output", noise=noise, seed=seed)


def ring_down(*, frequency_hz: float = 5.0, amplitude: float = 0.2, hardening: float = 0.3,
              damping_ratio: float = 0.01, inertia: float = 1e-3, rate: float | None = None,
              cycles: float = 12.0, counts_per_rev: float | None = None, noise: float = 0.0,
              seed: int = 0) -> tuple[pd.DataFrame, dict]:
    """Ring-downs of a cubic-spring oscillator (no gear, ``ratio = 1``; no Coulomb or
    static friction, light viscous damping) logged from an instant when it is already
    moving: no hold, each run starts with a nonzero velocity.

    ``hardening``: cubic share of the spring torque at ``amplitude``
    (``k2·A³ = hardening·k1·A``). Two runs: one caught at ``+0.6·A`` moving up, one at
    ``−0.3·A`` moving down, both with energy ``≈ ½·k1·A²``. Default rate 40 samples per
    period, analog (no quantization) unless ``counts_per_rev`` is given."""
    k1 = inertia * (2 * math.pi * frequency_hz) ** 2
    k2 = hardening * k1 / amplitude**2
    c_v = damping_ratio * 2 * math.sqrt(k1 * inertia)
    plant = Plant(inertia=inertia, ratio=1.0, k1=k1, k2=k2, c_v=c_v)
    rate = 40 * frequency_hz if rate is None else rate
    E = 0.5 * k1 * amplitude**2 + 0.25 * k2 * amplitude**4
    starts = [0.6 * amplitude, -0.3 * amplitude]
    omegas = []
    for x, s in zip(starts, (1.0, -1.0)):
        pe = 0.5 * k1 * x**2 + 0.25 * k2 * x**4
        omegas.append(s * math.sqrt(2 * (E - pe) / inertia))
    return make_log(plant, starts, omega0=omegas, rate=rate, duration=cycles / frequency_hz,
                    hold=0.0, setups=["A", "A"], offsets={"A": 0.05},
                    counts_per_rev=counts_per_rev, noise=noise, seed=seed, time_origin=12.345)


#: Gear-size presets for :func:`paper_design`: output stiffness k1 [N m/rad], ratio N and
#: WG inertia [kg m²] (gear input + motor rotor, plus a flywheel for ``csf32_flywheel``),
#: spanning two decades of natural frequency (≈7 Hz to ≈430 Hz at the WG). The catalog
#: K1 of CSF-8/14/20/32 are about 900/4700/13000/50000 N m/rad.
GEARS = {
    "csf32_flywheel": dict(k1=50000.0, ratio=160.0, inertia=1e-3),
    "csf32": dict(k1=50000.0, ratio=160.0, inertia=1e-4),
    "csf20": dict(k1=13000.0, ratio=100.0, inertia=2e-5),
    "csf14": dict(k1=4700.0, ratio=100.0, inertia=5e-6),
    "csf8": dict(k1=940.0, ratio=100.0, inertia=7e-7),
    "csf8_ratio50": dict(k1=940.0, ratio=50.0, inertia=7e-7),
    "csf14_ratio30": dict(k1=4700.0, ratio=30.0, inertia=7e-7),
}


def gear_plant(gear: str | dict, amplitude: float = 0.157) -> Plant:
    """A gear made dynamically like the paper's CSF-8-100 (the shipped example's truth):
    at a WG release of ``amplitude`` the cubic term is 17 % of the spring torque, Coulomb
    friction 17 % and static 30 % of the spring torque ``k_wg·amplitude``, Stribeck
    velocity 9 % of the peak speed ``ω_n·amplitude``, delta 1, viscous 3.5 % of critical."""
    g = GEARS[gear] if isinstance(gear, str) else gear
    k1, N, I = g["k1"], g["ratio"], g["inertia"]
    k_wg = k1 / N**2
    wn = math.sqrt(k_wg / I)
    spring = k_wg * amplitude
    return Plant(inertia=I, ratio=N, k1=k1, k2=0.17 * k1 / (amplitude / N) ** 2,
                 tau_c=0.17 * spring, tau_s=0.30 * spring, v_s=0.09 * wn * amplitude,
                 delta=1.0, c_v=0.035 * 2 * math.sqrt(k_wg * I))


def paper_design(gear: str | dict = "csf8", *, rate: float = 250.0, counts_per_rev: float = 4000,
                 amplitude: float = 0.157, duration: float | None = None, hold: float = 0.04,
                 noise: float = 0.0, seed: int = 0) -> tuple[pd.DataFrame, dict]:
    """The paper's design on any gear: releases +A, −A, +A, −A at the WG (A = 0.157 rad),
    runs 1–2 on set-up A (offset +0.012 rad), 3–4 on B (−0.020 rad), a 4000-count WG
    encoder, 250 Hz, a short hold. ``duration`` default: 0.5 s or 25 natural periods,
    whichever is longer. Each run's release falls at a different phase of its sample
    interval."""
    plant = gear_plant(gear, amplitude)
    if duration is None:
        duration = max(0.5, 25.0 / plant.natural_frequency_hz)
    return make_log(plant, [amplitude, -amplitude, amplitude, -amplitude], rate=rate,
                    duration=duration, hold=hold, setups=["A", "A", "B", "B"],
                    offsets={"A": 0.012, "B": -0.020}, counts_per_rev=counts_per_rev,
                    release_phase=[0.19, 0.43, 0.61, 0.87], noise=noise, seed=seed)


#: How each parameter's value transforms when angles are multiplied by ``a``, time by
#: ``b`` and torque by ``c`` (an inertia is a torque × time² per angle).
_POWERS = {  # (angle, time, torque)
    "k1": (-1, 0, 1), "k2": (-3, 0, 1), "tau_c": (0, 0, 1), "tau_s": (0, 0, 1),
    "tau_0": (0, 0, 1), "mgl": (0, 0, 1), "v_s": (1, -1, 0), "delta": (0, 0, 0),
    "c_v": (-1, 1, 1), "inertia": (-1, 2, 1), "ratio": (0, 0, 0),
}


def in_units(log: pd.DataFrame, truth: dict, *, angle: float = 1.0, time: float = 1.0,
             torque: float = 1.0) -> tuple[pd.DataFrame, dict]:
    """The same physical log in other units: angles × ``angle`` (1000: mrad), time ×
    ``time`` (1000: ms), torques × ``torque`` (1000: mN m); the truth transformed exactly
    as the parameters' units (``k1`` torque/angle, ``inertia`` torque·time²/angle, …).

    Gravity's ``sin(θ/N)`` needs θ in radians, so a log with ``mgl ≠ 0`` keeps its meaning
    only for ``angle = 1``."""
    out = log.copy()
    out["time"] = out["time"] * time
    out["theta"] = out["theta"] * angle
    t = {**truth}

    def conv(name, value):
        pa, pt, pc = _POWERS[name]
        return value * angle**pa * time**pt * torque**pc

    t["params"] = {k: conv(k, v) for k, v in truth["params"].items()}
    t["inertia"] = conv("inertia", truth["inertia"])
    t["runs"] = [{**r, "theta0": r["theta0"] * angle, "omega0": r["omega0"] * angle / time,
                  "t_release": r["t_release"] * time,
                  "rest": None if r["rest"] is None else r["rest"] * angle,
                  "stuck_at": None if r["stuck_at"] is None else r["stuck_at"] * time}
                 for r in truth["runs"]]
    t["offsets"] = {k: v * angle for k, v in truth["offsets"].items()}
    t["resolution"] = None if truth["resolution"] is None else truth["resolution"] * angle
    t["noise"] = truth["noise"] * angle
    t["rate"] = truth["rate"] / time
    t["natural_frequency_hz"] = truth["natural_frequency_hz"] / time
    t["units"] = {"angle": f"rad×{angle:g}", "time": f"s×{time:g}", "torque": f"N m×{torque:g}"}
    return out, t
