"""Synthetic free-motion logs from the reference simulator: :func:`make_log`, the
CSF-8-100-like truth :data:`TRUTH_CSF8` and the designs of the shipped logs in
``data/synthetic`` (:data:`PAPER_DESIGN`, :data:`RICH_DESIGN`, :data:`HIDDEN_DESIGN`).

Log format: columns ``run,setup,time,theta``; ``time`` restarts at 0 for each run with sample
period ``1/fs``; ``theta`` is the encoder reading
``round((θ_phys + offset)/step)·step`` [rad], ``step = 2π/counts_per_rev``.
"""

from __future__ import annotations

import copy
import math
from collections.abc import Mapping, Sequence

import numpy as np
import pandas as pd

from ._events import reference_trajectory
from ._spring import stick_band_halfwidth

#: Names of the physical parameters passed to the simulator (``ratio`` aside).
PARAM_NAMES = ("k1", "k2", "tau_c", "tau_s", "v_s", "delta", "c_v", "inertia")

#: CSF-8-100-like truth (see ``shared/reference/physics-notes.md``).  ``tau_c``/``tau_s`` and
#: ``c_v`` were tuned so that the rest points of the ±0.157 rad releases are ≈ 0.07 rad apart,
#: as in the paper (gap = 0.0711 rad; each release reverses twice and sticks ≈ 17 ms after
#: release).  c_v = 1.8e-5 Nm·s/rad is 3.5 % of critical damping 2·sqrt(k1/N²·I) = 5.13e-4.
TRUTH_CSF8: dict[str, float] = {
    "k1": 940.0,  # Nm/rad (output side)
    "k2": 6.5e7,  # Nm/rad^3 (output side)
    "tau_c": 2.5e-3,  # Nm (WG)
    "tau_s": 4.5e-3,  # Nm (WG)
    "v_s": 5.0,  # rad/s (WG)
    "delta": 1.0,  # -
    "c_v": 1.8e-5,  # Nm s/rad (WG)
    "inertia": 7.0e-7,  # kg m^2 (WG)
    "ratio": 100.0,  # gear ratio N
}

COUNTS_PER_REV = 4000


def encoder_step(counts_per_rev: int = COUNTS_PER_REV) -> float:
    """Encoder resolution ``2π/counts_per_rev`` [rad]."""
    return 2.0 * math.pi / counts_per_rev


def _sim_kwargs(truth: Mapping) -> dict[str, float]:
    params = truth["params"] if "params" in truth else truth  # a truth.json entry works too
    kw = {name: float(params[name]) for name in PARAM_NAMES}
    kw["ratio"] = float(truth.get("ratio", params.get("ratio", 100.0)))
    return kw


def rest_gap(truth: Mapping[str, float], amplitude: float = 0.157) -> float:
    """Gap between the rest points of the ``+amplitude`` and ``−amplitude`` releases [rad].

    Parameters
    ----------
    truth : mapping
        Physical parameters (``PARAM_NAMES``, optional ``ratio``).
    amplitude : float, optional
        Release angle magnitude [rad, WG] (default 0.157).

    Returns
    -------
    float
        ``θ_rest(+amplitude) − θ_rest(−amplitude)`` (positive when each run stops on the side
        it started from).
    """
    kw = _sim_kwargs(truth)
    rest = []
    for a in (amplitude, -amplitude):
        tr = reference_trajectory(10.0, theta0=a, t_release=0.0, **kw)
        rest.append(tr.theta_rest if tr.stuck else float(tr.evaluate([10.0])[0][0]))
    return rest[0] - rest[1]


def make_log(
    truth: Mapping[str, float],
    amplitudes: Sequence[float],
    fs: float,
    duration: float,
    hold: float,
    offsets_by_setup: Mapping[str, float],
    seed: int,
    quantize: bool = True,
    noise_std: float = 0.0,
    *,
    setups: Sequence[str] | None = None,
    counts_per_rev: int = COUNTS_PER_REV,
    as_counts: bool = False,
    return_truth: bool = False,
    hidden: Mapping | None = None,
) -> pd.DataFrame | tuple[pd.DataFrame, dict]:
    """Make one synthetic free-motion log with the reference simulator.

    Parameters
    ----------
    truth : mapping
        Physical parameters ``k1, k2, tau_c, tau_s, v_s, delta, c_v, inertia`` and optionally
        ``ratio`` (default 100), e.g. :data:`TRUTH_CSF8`; an entry of ``truth.json`` (with a
        nested ``"params"``) is accepted as well.
    amplitudes : sequence of float
        Physical release angle ``theta0`` [rad, WG, from the spring's zero] of each run.
    fs : float
        Sample rate [Hz].
    duration : float
        Length of each run [s]; each run has ``round(duration·fs)`` samples at ``k/fs``.
    hold : float
        Pre-release hold [s].  The release instant is ``hold + u/fs`` with ``u ~ U(0, 1)``, i.e.
        at a random sub-sample instant.
    offsets_by_setup : mapping of str to float
        Encoder offset of each set-up [rad]: the encoder reads ``θ_phys + offset``.
    seed : int
        Seed of :func:`numpy.random.default_rng` (release instants, noise).
    quantize : bool, optional
        Round readings to the encoder's counts (default True).
    noise_std : float, optional
        Standard deviation [rad] of Gaussian noise added to ``θ_phys + offset`` *before*
        quantization (default 0).
    setups : sequence of str, optional
        Set-up label of each run.  By default the runs are split into contiguous, equal blocks
        over the set-ups in the order of ``offsets_by_setup`` (4 runs, 2 set-ups → A, A, B, B).
    counts_per_rev : int, optional
        Encoder resolution (default 4000).
    as_counts : bool, optional
        Write ``theta`` as integer counts instead of radians (needs ``quantize``).
    return_truth : bool, optional
        Also return the truth dictionary as a second value.
    hidden : mapping, optional
        Extra keyword arguments of :func:`hdid.reference.reference_trajectory`
        (``extra_torque``, ``extra_holding``, ``dahl``) that hide an effect the base
        model lacks; see :data:`hdid.reference.logs.HIDDEN`.

    Returns
    -------
    pandas.DataFrame or (pandas.DataFrame, dict)
        Columns ``run`` (1-based int), ``setup`` (str), ``time`` [s], ``theta`` [rad, or counts].
        The truth dictionary is always attached as ``df.attrs["truth"]``: ``params``, ``ratio``,
        ``fs``, ``counts_per_rev``, ``step_rad``, ``units``, ``quantized``, ``noise_std``,
        ``seed``, ``duration``, ``hold``, ``offsets``, ``stick_band_halfwidth`` and ``runs``
        (per run: ``run``, ``setup``, ``theta0`` (physical), ``theta0_enc`` (first reading),
        ``t_release``, ``offset``, ``theta_rest`` (physical), ``t_stick``).
    """
    if as_counts and not quantize:
        raise ValueError("as_counts requires quantize=True")
    amplitudes = [float(a) for a in amplitudes]
    n_runs = len(amplitudes)
    setup_names = list(offsets_by_setup)
    if setups is None:
        if not setup_names:
            raise ValueError("offsets_by_setup is empty")
        per = math.ceil(n_runs / len(setup_names))
        setups = [setup_names[min(i // per, len(setup_names) - 1)] for i in range(n_runs)]
    setups = [str(s) for s in setups]
    if len(setups) != n_runs:
        raise ValueError("setups must have one label per run")
    missing = set(setups) - set(map(str, setup_names))
    if missing:
        raise ValueError(f"no offset given for set-ups {sorted(missing)}")

    kw = _sim_kwargs(truth)
    rng = np.random.default_rng(seed)
    step = encoder_step(counts_per_rev)
    n = int(round(duration * fs))
    t = np.arange(n) / fs

    frames = []
    runs_info = []
    for i, (a, setup) in enumerate(zip(amplitudes, setups), start=1):
        offset = float(offsets_by_setup[setup])
        t_rel = float(hold + rng.uniform(0.0, 1.0) / fs)
        traj = reference_trajectory(float(t[-1]), theta0=a, t_release=t_rel, **kw,
                                    **(dict(hidden) if hidden else {}))
        theta_phys, _ = traj.evaluate(t)
        reading = theta_phys + offset
        if noise_std > 0:
            reading = reading + rng.normal(0.0, noise_std, size=reading.shape)
        if quantize:
            counts = np.round(reading / step)
            reading = counts.astype(np.int64) if as_counts else counts * step
        frames.append(pd.DataFrame({"run": i, "setup": setup, "time": t, "theta": reading}))
        runs_info.append({
            "run": i,
            "setup": setup,
            "theta0": a,
            "theta0_enc": float(reading[0]) * (step if as_counts else 1.0),
            "t_release": t_rel,
            "offset": offset,
            "theta_rest": float(traj.theta_rest) if traj.stuck else None,
            "t_stick": float(traj.t_stick) if traj.stuck else None,
        })
    df = pd.concat(frames, ignore_index=True)
    info = {
        "params": {name: kw[name] for name in PARAM_NAMES},
        "ratio": kw["ratio"],
        "fs": float(fs),
        "counts_per_rev": int(counts_per_rev),
        "step_rad": step,
        "units": "counts" if as_counts else "rad",
        "quantized": bool(quantize),
        "noise_std": float(noise_std),
        "seed": int(seed),
        "duration": float(duration),
        "hold": float(hold),
        "offsets": {str(k): float(v) for k, v in offsets_by_setup.items()},
        "stick_band_halfwidth": stick_band_halfwidth(kw["k1"], kw["k2"], kw["tau_s"],
                                                     kw["ratio"]),
        "runs": runs_info,
    }
    df.attrs["truth"] = info
    if return_truth:
        return df, copy.deepcopy(info)
    return df


# ---------------------------------------------------------------- the shipped designs

#: The paper's design (``csf8_paper.csv``): 250 Hz, ±0.157 rad twice, set-ups A and B.
PAPER_DESIGN = dict(amplitudes=[0.157, -0.157, 0.157, -0.157], fs=250.0, duration=0.5,
                    hold=0.04, offsets_by_setup={"A": 0.012, "B": -0.020}, seed=20240611)
#: A richer design (``csf8_rich_1khz.csv``): 1 kHz, four amplitudes, one set-up.
RICH_DESIGN = dict(amplitudes=[0.157, -0.157, 0.12, -0.12, 0.08, -0.08, 0.05, -0.05],
                   fs=1000.0, duration=0.3, hold=0.04, offsets_by_setup={"A": 0.005},
                   seed=20240612)

#: A log with a hidden effect (Dahl hysteresis, :data:`HIDDEN`) for ``hdid diagnose`` and
#: ``notebooks/discover-missing-effect.ipynb``: 1 kHz, two amplitudes, one set-up.
HIDDEN_DESIGN = dict(amplitudes=[0.157, -0.157, 0.08, -0.08], fs=1000.0, duration=0.25,
                     hold=0.02, offsets_by_setup={"A": 0.005}, seed=20240613)
