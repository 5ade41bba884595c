"""``hdid simulate``: write a synthetic log (from a model, or re-simulating a fit's JSON)."""

from __future__ import annotations

import json
import math
from pathlib import Path

import click
import cloup

from ._common import _Command, _Fail, _QUIET, _check_output, _finite, _parse_floats, _write_text


#: The parameter values `hdid simulate` uses by default: those of the README's example logs
#: (``data/synthetic/truth.json``, CSF-8-100-like). They differ from the fit's catalog start
#: values (``hdid.Model.default()``), which a fit must not be handed as the truth.
EXAMPLE_TRUTH = {"k1": 940.0, "k2": 6.5e7, "tau_c": 2.5e-3, "tau_s": 4.5e-3, "v_s": 5.0,
                 "delta": 1.0, "c_v": 1.8e-5, "inertia": 7e-7}


def truth_path(out) -> Path:
    """Where `hdid simulate OUT.csv` stores the parameters and design it used:
    ``OUT.truth.json`` beside the log."""
    return Path(out).with_suffix(".truth.json") if Path(out).suffix else Path(f"{out}.truth.json")


@cloup.command("simulate", cls=_Command)
@click.argument("out", type=click.Path(dir_okay=False))
@cloup.option_group(
    "Model",
    click.option("--set", "values", multiple=True, metavar="NAME=VALUE", help="Model parameter, e.g. --set k1=1200 (repeatable). Default: the README's example truth (data/synthetic/truth.json): " + ", ".join(f"{k}={v:g}" for k, v in EXAMPLE_TRUTH.items()) + "."),
    click.option("--from", "from_json", metavar="FIT.json", help="Re-simulate a fitted model (the JSON of `hdid fit --json`): its effects and values, and by default its log's design (release angles, rate, length, encoder step, offset); options given here override."),
)
@cloup.option_group(
    "Design: the releases",
    click.option("--amplitudes", default="0.157,-0.157,0.12,-0.12,0.08,-0.08,0.05,-0.05", show_default=True, help="Release angles [rad, WG], one run each."),
    click.option("--rate", type=float, default=1000.0, show_default=True, help="Sample rate [Hz]."),
    click.option("--duration", type=float, default=0.3, show_default=True, help="Length of each run [s]."),
    click.option("--hold", type=float, default=0.04, show_default=True, help="Pre-release hold [s]."),
)
@cloup.option_group(
    "Encoder and noise",
    click.option("--offset", type=float, default=0.0, show_default=True, help="Encoder reading at the spring zero [rad]."),
    click.option("--counts-per-rev", type=int, default=4000, show_default=True, help="Encoder resolution (0: no quantization)."),
    click.option("--noise", type=float, default=0.0, show_default=True, help="Gaussian noise before quantization [rad]."),
    click.option("--seed", type=int, default=0, show_default=True, help="Seed for sub-sample release instants and noise."),
)
@cloup.option_group(
    "Output",
    click.option("--counts", is_flag=True, help="Write theta as integer counts."),
    click.option("--overwrite", is_flag=True, help="Replace OUT (and OUT.truth.json) if they exist."),
    _QUIET,
)
def simulate_cmd(out, amplitudes, rate, duration, hold, offset, counts_per_rev, noise, seed,
                 values, counts, overwrite, from_json, quiet):
    """Write a synthetic free-motion log (same format as `hdid fit` reads), print the
    parameter values it used and store them, with the design, in OUT.truth.json.

    \b
    The default design is the one whose recovery is measured (README, "A short tour";
    data/synthetic/csf8_rich_1khz.csv; docs/decisions/experiment-design.md): 8 releases
    at four amplitudes (±0.157, ±0.12, ±0.08, ±0.05 rad) sampled at 1 kHz. It determines
    the stiffness, tau_c and tau_s to a few percent and brackets the stick band from both
    sides. The paper's design (--amplitudes 0.157,-0.157,0.157,-0.157 --rate 250
    --duration 0.5) resolves the transient with only 4-5 moving samples per run: it fixes
    k1 and the natural frequency, but not the friction shape (v_s, delta, k2 vs c_v); with
    only two runs (the former default), one fit in five had every std undetermined.
    """
    amps = _parse_floats(amplitudes, "--amplitudes") or []
    params = {}
    for item in values:
        name, _, value = item.partition("=")
        try:
            params[name.strip()] = float(value)
        except ValueError:
            raise _Fail(f"--set {item!r}: expected NAME=VALUE with a number") from None
    if rate <= 0 or duration <= 0 or hold < 0:
        raise _Fail("--rate and --duration must be > 0 and --hold >= 0")
    if counts and not counts_per_rev:
        raise _Fail("--counts needs --counts-per-rev > 0")
    _check_output(out, [], "OUT")
    try:
        truth = truth_path(out)
    except ValueError as exc:  # a name Path cannot give a suffix (checked above: rare)
        raise _Fail(f"OUT {out!r}: not a usable file name ({exc})") from None
    for path in (Path(out), truth):
        if not overwrite and path.exists():
            raise _Fail(f"{path} exists; add --overwrite to replace it (or choose another file)")
    _check_output(str(truth), [Path(out)], "OUT's parameter file")

    from .._errors import HdidError
    from .._models._model import Model
    from .._simulation._synthetic import synthesize

    model = None
    if from_json:
        src = Path(from_json)
        if not src.is_file():
            raise _Fail(f"--from {from_json}: no such file")
        from .._results._result import FitResult

        try:
            fitted = FitResult.load(src)
        except (HdidError, ValueError, KeyError, TypeError) as exc:
            raise _Fail(f"--from: {exc}") from None
        model = fitted.model
        given = lambda name: (click.get_current_context().get_parameter_source(name)  # noqa: E731
                              != click.core.ParameterSource.DEFAULT)
        design = _design_of(fitted)
        amps = amps if given("amplitudes") else design["amplitudes"]
        rate = rate if given("rate") else design["rate"]
        duration = duration if given("duration") else design["duration"]
        hold = hold if given("hold") else design["hold"]
        offset = offset if given("offset") else design["offset"]
        if not given("counts_per_rev"):
            counts_per_rev = design["counts_per_rev"]
        if counts and not counts_per_rev:
            raise _Fail("--counts needs --counts-per-rev > 0 (the fitted log had no encoder grid)")
    try:
        if model is None:
            model = Model.default().replace(**EXAMPLE_TRUTH)
        unknown = [n for n in params if n not in model.parameter_specs()]
        if unknown:
            raise _Fail(f"--set {unknown[0]}: the model has no such parameter; it has "
                        + ", ".join(model.parameter_specs()))
        model = model.replace(**params)
        synthesize(
            out, amplitudes=amps, rate=rate, duration=duration, hold=hold, offset=offset,
            counts_per_rev=counts_per_rev or None, noise=noise, seed=seed, values=None,
            model=model, as_counts=counts, overwrite=overwrite,
        )
    except (HdidError, ValueError, KeyError) as exc:
        raise _Fail.from_error(exc) from None
    design = {"amplitudes": amps, "rate": rate, "duration": duration, "hold": hold,
              "offset": offset, "counts_per_rev": counts_per_rev, "noise": noise, "seed": seed}
    _write_text(str(truth), json.dumps(_truth(model, out, design, from_json), indent=2) + "\n",
                "OUT's parameter file")
    if not quiet:
        click.echo(f"wrote {out}: {len(amps)} run(s) at {rate:g} Hz, {duration:g} s each")
        click.echo(_parameter_lines(model))
        click.echo(f"wrote {truth}: these values and the design")


def _parameter_lines(model) -> str:
    """The model's effects and parameter values with their units, one per line."""
    specs = model.parameter_specs()
    lines = [f"model: {' + '.join(model.effect_names)}, gear ratio {float(model.ratio):g}"]
    for name, value in model.float_values().items():
        unit = specs[name].unit if specs[name].unit not in ("1", "") else ""
        lines.append(f"  {name:<10} {value:<12.6g} {unit}".rstrip())
    return "\n".join(lines)


def _truth(model, out, design: dict, from_json) -> dict:
    """What OUT.truth.json holds: the values (``params``, as data/synthetic/truth.json
    names them), the full model (``model``: what ``FitResult.load`` rebuilds models
    from) and the design."""
    from .._results._saved import hdid_version, model_structure

    return _finite({
        "log": Path(out).name,
        "hdid_version": hdid_version(),
        "params": model.float_values(),
        "ratio": float(model.ratio),
        "model": model_structure(model),
        "fs": design["rate"],
        "duration": design["duration"],
        "hold": design["hold"],
        "counts_per_rev": design["counts_per_rev"] or None,
        "noise_std": design["noise"],
        "seed": design["seed"],
        "offsets": {"1": design["offset"]},
        "runs": [{"run": str(i + 1), "setup": "1", "theta0": a}
                 for i, a in enumerate(design["amplitudes"])],
        "from": str(from_json) if from_json else None,
    })


def _design_of(fitted) -> dict:
    """The experiment behind a fit: release angles, rate, run length, hold, encoder step."""
    import statistics

    rate = 1.0 / fitted.sample_period if fitted.sample_period > 0 else 250.0
    n = max(r.n_samples for r in fitted.runs)
    release = statistics.median(r.release_time for r in fitted.runs)
    step = fitted.resolution_rad
    cpr = (round(2 * math.pi / step) if fitted.resolution_known and step > 0
           and abs(2 * math.pi / step - round(2 * math.pi / step)) < 1e-6 * (2 * math.pi / step)
           else 0)
    return {
        "amplitudes": [r.theta0 for r in fitted.runs],
        "rate": rate,
        "duration": n / rate,
        "hold": min(max(release - 0.5 / rate, 0.0), 0.5 * n / rate),
        "offset": next(iter(fitted.setups.values()), 0.0),
        "counts_per_rev": cpr,
    }
