"""Candidate experiments of the free-motion test: what a test engineer can change.

An :class:`Experiment` is a release test as the simulator sees it: the release angles
(wave-generator angle from the spring's zero at the release, rad), how many samples a
second, how long each run is logged, how long it is held before the release, the encoder
step, the inertia added to each run and the set-ups (encoder readings at the spring zero).
:func:`baseline` reads the experiment behind a fit; :func:`default_candidates` varies it
one knob at a time (amplitudes and their number, repeats, rate, encoder, added inertia,
releases shifted in the wave-generator angle when the model has a position-periodic
term); :func:`load_candidates` reads a user's own from TOML/JSON or Python mappings.
Everything is relative to the log in hand: no number below is tied to one gear.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import statistics
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from pathlib import Path

from .._errors import HdidError


@dataclass(frozen=True)
class Experiment:
    """One candidate free-motion test.

    Attributes
    ----------
    name:
        What the candidate changes, e.g. ``"rate x4"``.
    amplitudes:
        Release angle of each run [rad, WG, from the spring's zero].
    rate:
        Sample rate [Hz].
    duration:
        Logged length of each run [s] (hold included).
    hold:
        Time the gear is held before the release [s].
    resolution:
        Encoder step [rad] (the readings are rounded to it).
    added_inertia:
        Inertia added to each run [kg m²] (one value per run).
    setups:
        Set-up of each run; ``offsets`` maps a set-up to its encoder reading at the
        spring's zero [rad].
    note:
        One line for the report (what it costs or assumes).
    """

    name: str
    amplitudes: tuple[float, ...]
    rate: float
    duration: float
    hold: float
    resolution: float
    added_inertia: tuple[float, ...] = ()
    setups: tuple[str, ...] = ()
    offsets: Mapping[str, float] = field(default_factory=dict)
    note: str = ""
    #: release instant of each run [s] (default: half a sample after ``hold``)
    releases: tuple[float, ...] = ()

    def __post_init__(self):
        amps = tuple(float(a) for a in self.amplitudes)
        object.__setattr__(self, "amplitudes", amps)
        R = len(amps)
        added = tuple(float(a) for a in self.added_inertia) or (0.0,) * R
        if len(added) == 1 and R > 1:
            added = added * R
        setups = tuple(str(s) for s in self.setups) or ("1",) * R
        object.__setattr__(self, "added_inertia", added)
        object.__setattr__(self, "setups", setups)
        rel = tuple(float(t) for t in self.releases) or (self.hold + 0.5 / self.rate,) * R
        object.__setattr__(self, "releases", rel)
        object.__setattr__(self, "offsets", {s: float(self.offsets.get(s, 0.0))
                                             for s in dict.fromkeys(setups)})
        _validate(self)

    @property
    def n_runs(self) -> int:
        return len(self.amplitudes)

    @property
    def n_samples(self) -> int:
        """Samples per run."""
        return max(int(round(self.duration * self.rate)), 3)

    @property
    def counts_per_rev(self) -> float:
        return 2.0 * math.pi / self.resolution

    @property
    def setup_names(self) -> tuple[str, ...]:
        return tuple(dict.fromkeys(self.setups))

    @property
    def free_inertia(self) -> bool:
        """Runs of different known added inertia: the fit frees the inertia (hdid.fit's
        default), which fixes the absolute scale of every torque."""
        return max(self.added_inertia) > min(self.added_inertia)

    def describe(self) -> str:
        amps = sorted({round(abs(a), 6) for a in self.amplitudes})
        text = (f"{self.n_runs} runs, |amplitude| {', '.join(f'{a:.3g}' for a in amps)} rad, "
                f"{self.rate:g} Hz, {self.counts_per_rev:.0f} counts/rev")
        if self.free_inertia:
            text += f", added inertia up to {max(self.added_inertia):.3g} kg m^2"
        return text

    def to_dict(self) -> dict:
        return {
            "name": self.name, "amplitudes": list(self.amplitudes), "rate_hz": self.rate,
            "duration_s": self.duration, "hold_s": self.hold, "resolution_rad": self.resolution,
            "counts_per_rev": self.counts_per_rev, "added_inertia": list(self.added_inertia),
            "setups": list(self.setups), "offsets": dict(self.offsets),
            "n_runs": self.n_runs, "note": self.note, "releases": list(self.releases),
        }


def _validate(e: Experiment) -> None:
    where = f"candidate {e.name!r}"
    if not e.amplitudes:
        raise HdidError(f"{where}: give at least one release amplitude (amplitudes = [0.157, -0.157])")
    checks = [
        (all(math.isfinite(a) and a != 0.0 for a in e.amplitudes),
         "amplitudes must be finite and non-zero [rad, WG, from the spring zero]"),
        (math.isfinite(e.rate) and e.rate > 0, f"rate = {e.rate!r}: give a sample rate > 0 Hz"),
        (math.isfinite(e.duration) and e.duration > 0, f"duration = {e.duration!r}: give > 0 s"),
        (math.isfinite(e.hold) and 0 <= e.hold < e.duration,
         f"hold = {e.hold!r}: give 0 <= hold < duration ({e.duration:g} s)"),
        (math.isfinite(e.resolution) and e.resolution > 0,
         f"resolution = {e.resolution!r}: give the encoder step > 0 rad (or counts_per_rev)"),
        (len(e.added_inertia) == e.n_runs and all(math.isfinite(a) and a >= 0 for a in e.added_inertia),
         "added_inertia: one value >= 0 kg m^2 per run (or one for all)"),
        (len(e.setups) == e.n_runs, "setups: one name per run"),
        (len(e.releases) == e.n_runs and all(0 <= t < e.duration for t in e.releases),
         "releases: one instant per run inside the run"),
        (e.n_samples <= 20_000, f"{e.n_samples} samples per run: at most 20000 (shorten it)"),
    ]
    for ok, why in checks:
        if not ok:
            raise HdidError(f"{where}: {why}")


def baseline(fit) -> Experiment:
    """The experiment behind a fit (a :class:`~hdid.FitResult`, also one loaded from JSON):
    its runs' release angles, set-ups and offsets, rate, length, hold and encoder step."""
    rate = 1.0 / fit.sample_period if fit.sample_period > 0 else math.nan
    n = max(r.n_samples for r in fit.runs)
    release = statistics.median(r.release_time for r in fit.runs)
    run_times = [r.release_time for r in fit.runs]
    problem = getattr(fit, "problem", None)
    added = ([float(a) for a in problem.added_inertia] if problem is not None
             and hasattr(problem, "added_inertia") else [0.0] * len(fit.runs))
    return Experiment(
        name="this log",
        amplitudes=tuple(r.theta0 for r in fit.runs),
        rate=rate,
        duration=n / rate,
        hold=min(max(release - 0.5 / rate, 0.0), 0.5 * n / rate),
        resolution=fit.resolution_rad,
        added_inertia=tuple(added),
        setups=tuple(r.setup for r in fit.runs),
        offsets=dict(fit.setups),
        releases=tuple(run_times),
        note="the design of the fitted log (release instants "
             + ", ".join(f"{t:.4g}" for t in run_times) + " s)",
    )


#: Longest swing a default candidate asks for, relative to the log's largest: a test
#: engineer can twist further, but the model was only fitted over the log's range.
MAX_AMPLITUDE_FACTOR = 2.0


def default_candidates(base: Experiment, model) -> list[Experiment]:
    """The log's own design, then one knob changed at a time (each relative to the log)."""
    a = max(abs(x) for x in base.amplitudes)
    signs = (1.0, -1.0)
    R = base.n_runs
    inertia = float(model.float_values().get("inertia", 0.0))
    first = base.setup_names[0]

    def same(name, note, **changes):
        return dataclasses.replace(base, name=name, note=note, **changes)

    def runs(amps, note, name, *, rate=None, resolution=None, added=None, duration=None):
        amps = tuple(amps)
        return Experiment(
            name=name, amplitudes=amps, rate=rate or base.rate,
            duration=duration or base.duration, hold=base.hold,
            resolution=resolution or base.resolution,
            added_inertia=tuple(added) if added is not None else (0.0,) * len(amps),
            setups=(first,) * len(amps), offsets={first: base.offsets[first]}, note=note)

    def pm(levels):
        return [s * f * a for f in levels for s in signs]

    out = [base]
    for f in (0.5, 1.5, MAX_AMPLITUDE_FACTOR):
        out.append(same(f"amplitude x{f:g}", "every release scaled",
                        amplitudes=tuple(f * x for x in base.amplitudes)))
    out.append(runs(pm((0.5, 1.0, 1.5)), "three amplitudes, both signs", "amplitudes 0.5/1/1.5"))
    out.append(runs(pm((0.5, 1.0, 1.5, 2.0)), "four amplitudes, both signs",
                    "amplitudes 0.5/1/1.5/2"))
    out.append(runs(pm((1.0, 2.0)), "the log's and twice its amplitude", "amplitudes 1/2"))
    for k in (2, 4):
        out.append(same(f"repeats x{k}", f"every release done {k} times",
                        amplitudes=base.amplitudes * k, added_inertia=base.added_inertia * k,
                        setups=base.setups * k, releases=base.releases * k))
    for k in (2, 4):
        out.append(same(f"rate x{k}", "same releases, faster logger", rate=k * base.rate))
    for k in (4, 16):
        out.append(same(f"encoder x{k}", f"{k}x the counts per revolution",
                        resolution=base.resolution / k))
    out.append(same("rate x4 + encoder x4", "faster logger and finer encoder",
                    rate=4 * base.rate, resolution=base.resolution / 4))
    out.append(runs(pm((0.5, 1.0, 1.5, 2.0)), "four amplitudes at 4x the rate",
                    "amplitudes 0.5/1/1.5/2 + rate x4", rate=4 * base.rate))
    if inertia > 0:
        for k in (1.0, 3.0):
            amps = list(base.amplitudes) * 2
            added = [0.0] * R + [k * inertia] * R
            out.append(runs(amps, f"the log's releases again with {k:g}x the inertia added "
                            "(the fit frees the inertia: absolute torques)",
                            f"added inertia x{k:g}", added=added))
    period = _shortest_period(model)
    if period is not None:
        shifted = [x + math.copysign(0.25 * period, x) for x in base.amplitudes]
        out.append(runs(list(base.amplitudes) + shifted,
                        "the releases again a quarter period of the position-periodic term "
                        "further (another WG angle at the release)", "angle-shifted releases"))
    return out


def _shortest_period(model) -> float | None:
    """Period [rad, WG] of the model's highest-order position-periodic term, if any."""
    orders = [float(getattr(e, "order")) for e in model.effects if hasattr(e, "order")]
    orders = [o for o in orders if math.isfinite(o) and o > 0]
    return 2.0 * math.pi / max(orders) if orders else None


_KEYS = {"name", "amplitudes", "rate", "rate_hz", "duration", "duration_s", "hold", "hold_s",
         "resolution", "resolution_rad", "counts_per_rev", "added_inertia", "setups",
         "offsets", "repeats", "note"}


def load_candidates(source, base: Experiment) -> list[Experiment]:
    """User candidates: a TOML/JSON file (``[[candidate]]`` tables / a list under
    ``"candidates"`` or at the top), or an iterable of :class:`Experiment` or mappings.
    A mapping names what differs from the log's design (``rate``, ``amplitudes``,
    ``counts_per_rev`` or ``resolution``, ``repeats``, ``added_inertia``, ``duration``,
    ``hold``); the rest is the log's."""
    if isinstance(source, (str, os.PathLike)):
        items = _read_file(Path(source))
        where = str(source)
    else:
        items = list(source)
        where = "candidates"
    out = []
    for i, item in enumerate(items):
        if isinstance(item, Experiment):
            out.append(item)
            continue
        if not isinstance(item, Mapping):
            raise HdidError(f"{where}: candidate {i + 1} is a {type(item).__name__}; give a "
                            "table/mapping such as {name = 'fast', rate = 1000}")
        out.append(_from_mapping(dict(item), base, f"{where}: candidate {i + 1}"))
    if not out:
        raise HdidError(f"{where}: no candidates in it; give at least one, e.g. "
                        "[[candidate]] name = 'fast' rate = 1000")
    names = [e.name for e in out]
    dup = {n for n in names if names.count(n) > 1}
    if dup:
        raise HdidError(f"{where}: candidate name {sorted(dup)[0]!r} is used twice; give each its own")
    return out


def _read_file(path: Path) -> list:
    if not path.is_file():
        raise HdidError(f"{path}: no such candidates file (TOML or JSON)")
    text = path.read_text()
    try:
        if path.suffix.lower() == ".toml":
            import tomllib

            data = tomllib.loads(text)
        else:
            data = json.loads(text)
    except ValueError as exc:  # tomllib.TOMLDecodeError and JSONDecodeError are ValueErrors
        kind = "TOML" if path.suffix.lower() == ".toml" else "JSON"
        raise HdidError(f"{path}: not valid {kind}: "
                        f"{str(exc).splitlines()[0]}") from None
    if isinstance(data, Mapping):
        data = data.get("candidate", data.get("candidates"))
    if not isinstance(data, list):
        raise HdidError(f"{path}: expected a list of candidates ([[candidate]] tables in TOML, "
                        "or {\"candidates\": [...]} in JSON)")
    return data


def _from_mapping(d: dict, base: Experiment, where: str) -> Experiment:
    unknown = sorted(set(d) - _KEYS)
    if unknown:
        raise HdidError(f"{where}: unknown key {unknown[0]!r}; use {', '.join(sorted(_KEYS))}")

    def num(key, *alts):
        for k in (key, *alts):
            if k in d:
                v = d[k]
                if isinstance(v, bool) or not isinstance(v, (int, float)):
                    raise HdidError(f"{where}: {k} = {v!r} is not a number")
                return float(v)
        return None

    name = str(d.get("name", f"candidate {where.rsplit(' ', 1)[-1]}"))
    amps = d.get("amplitudes")
    if amps is not None:
        if not isinstance(amps, list) or not all(isinstance(x, (int, float)) for x in amps):
            raise HdidError(f"{where}: amplitudes must be a list of numbers [rad, WG]")
    repeats = num("repeats")
    if repeats is not None and (repeats < 1 or repeats != int(repeats)):
        raise HdidError(f"{where}: repeats = {repeats:g}: give a whole number >= 1")
    cpr = num("counts_per_rev")
    resolution = num("resolution", "resolution_rad")
    if cpr is not None:
        if not cpr > 0:
            raise HdidError(f"{where}: counts_per_rev = {cpr:g}: give a number > 0")
        resolution = 2.0 * math.pi / cpr
    k = int(repeats or 1)
    if amps is None:
        amps, setups, offsets = base.amplitudes, base.setups, base.offsets
    else:
        first = base.setup_names[0]
        setups, offsets = (first,) * len(amps), {first: base.offsets[first]}
    added = d.get("added_inertia", 0.0)
    added = [float(added)] * len(amps) if isinstance(added, (int, float)) else list(added)
    try:
        return Experiment(
            name=name, amplitudes=tuple(amps) * k,
            rate=num("rate", "rate_hz") or base.rate,
            duration=num("duration", "duration_s") or base.duration,
            hold=num("hold", "hold_s") if num("hold", "hold_s") is not None else base.hold,
            resolution=resolution or base.resolution,
            added_inertia=tuple(added) * k, setups=tuple(setups) * k, offsets=offsets,
            note=str(d.get("note", "user candidate")))
    except (TypeError, ValueError) as exc:
        raise HdidError(f"{where}: {exc}") from None


def as_list(candidates: Iterable | None) -> list | None:
    return None if candidates is None else list(candidates)
