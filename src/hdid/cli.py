"""Command line: ``hdid fit``, ``hdid diagnose`` and ``hdid simulate``.

The commands only parse arguments, call the library, print a report and write files;
all science lives in the library. Heavy imports (jax) happen inside the commands so
that ``hdid --help`` answers at once.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import click


#: Exit status of a batch (``hdid fit a.csv b.csv …``) in which some logs failed and the
#: others were fitted (their rows written). 0: all fitted; 2: bad usage or every log failed.
EXIT_PARTIAL = 3

#: Longest run (samples) `hdid fit` takes; longer logs are refused with a hint to crop or
#: decimate. Fit time and memory grow with the samples: benchmarks/results/long_log.md.
MAX_SAMPLES_PER_RUN = 5_000


class _Fail(click.ClickException):
    """One-line error, exit status 2, no traceback."""

    exit_code = 2

    def show(self, file=None):
        # One line whatever the message quotes (a file name with a newline, …).
        msg = "".join(c if c.isprintable() else repr(c)[1:-1] for c in self.format_message())
        click.echo(f"hdid: error: {msg}", err=True, file=file)

    @classmethod
    def from_error(cls, exc: Exception) -> _Fail:
        """The library's error as one line (a KeyError's message without its quotes)."""
        msg = exc.args[0] if isinstance(exc, KeyError) and exc.args else str(exc)
        return cls(str(msg).replace("\n", " "))


def _parse_floats(text: str | None, what: str) -> list[float] | None:
    if text is None:
        return None
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise _Fail(f"{what}: expected comma-separated numbers, got {text!r}") from None


def _parse_fix(items: tuple[str, ...], option: str = "--fix") -> dict[str, float | None]:
    out: dict[str, float | None] = {}
    for item in items:
        name, _, value = item.partition("=")
        name = name.strip()
        if not name or (option == "--start" and not value):
            raise _Fail(f"{option} {item!r}: expected "
                        + ("NAME=VALUE (e.g. --start k1=1200)" if option == "--start"
                           else "NAME or NAME=VALUE (e.g. --fix k2=6.5e7)"))
        try:
            out[name] = float(value) if value else None
        except ValueError:
            raise _Fail(f"{option} {item!r}: {value!r} is not a number") from None
        if option == "--start" and not math.isfinite(out[name]):
            raise _Fail(f"{option} {item!r}: give a finite number")
    return out


def _check_size(data) -> None:
    """Refuse at once a log whose runs are too long to fit in minutes (see
    benchmarks/results/long_log.md): say how to crop or decimate it."""
    longest = max(r.n_samples for r in data.runs)
    if longest > MAX_SAMPLES_PER_RUN:
        period = getattr(data, "sample_period", None) or 0.0
        factor = -(-longest // MAX_SAMPLES_PER_RUN)
        rate = f" (now {1 / period:.0f} Hz)" if period > 0 else ""
        raise _Fail(
            f"{data.source}: a run has {longest} samples, more than the "
            f"{MAX_SAMPLES_PER_RUN} per run hdid fits in minutes; crop each run to the "
            f"release and the settling (a few hundred ms), or keep one row in {factor}"
            f"{rate}; hdid.fit() in Python fits it anyway"
        )


def _with_start_values(model, guesses: dict):
    """The model to fit, with the --start values as its own (the warm start)."""
    from ._model import Model

    model = Model.default() if model is None else model
    specs = model.parameter_specs()
    unknown = [n for n in guesses if n not in specs]
    if unknown:
        raise _Fail(f"--start {unknown[0]}: the model has no such parameter; it has "
                    + ", ".join(specs))
    try:
        return model.replace(**guesses)
    except (ValueError, TypeError) as exc:
        raise _Fail(f"--start: {exc}") from None


def _options_used(ctx) -> dict:
    """The fit options as given (defaults and output paths left out), for the JSON."""
    skip = {"logs", "log", "json_out", "plot_out", "summary_out", "chains_out", "corner_out",
            "residuals_out", "quiet"}
    out = {}
    for name, value in ctx.params.items():
        if name in skip or value is None or value is False or value == () or value == "":
            continue
        if ctx.get_parameter_source(name) == click.core.ParameterSource.DEFAULT:
            continue
        out[name] = list(value) if isinstance(value, tuple) else value
    return out


def _stderr_is_tty() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


class _Phases:
    """On a terminal, say on stderr what hdid is doing and how long each phase took:
    ``hdid: reading log.csv … 0.1 s``. Silent when stderr is redirected or with -q."""

    def __init__(self, enabled: bool):
        self.enabled = enabled
        self.t0: float | None = None

    def start(self, what: str) -> None:
        import time

        self.stop()
        if self.enabled:
            click.echo(f"hdid: {what} …", err=True, nl=False)
            self.t0 = time.perf_counter()

    def stop(self) -> None:
        import time

        if self.enabled and self.t0 is not None:
            click.echo(f" {time.perf_counter() - self.t0:.1f} s", err=True)
        self.t0 = None


def _check_output(path: str | None, inputs: list[Path], option: str, *, figure: bool = False) -> None:
    """Refuse, before any work, an output path that cannot be written: an input log, a
    folder, a missing or read-only folder, a figure format matplotlib cannot write."""
    if path is None:
        return
    import os

    if not str(path).strip():
        raise _Fail(f"{option}: empty file name; give one such as fit.json")
    try:
        p = Path(path).resolve()
        exists, is_dir = p.exists(), p.is_dir()
    except (OSError, ValueError) as exc:  # a name too long, a NUL byte, a loop of links
        raise _Fail(f"{option} {path!r}: not a usable file name ({exc})") from None
    if any(p == i.resolve() for i in inputs):
        raise _Fail(f"{option} {path}: would overwrite an input log; choose another file")
    if is_dir:
        raise _Fail(f"{option} {path}: is a directory; give a file name inside it")
    if not p.parent.exists():
        raise _Fail(f"{option} {path}: folder {p.parent} does not exist")
    if not p.parent.is_dir():
        raise _Fail(f"{option} {path}: {p.parent} is not a folder")
    if not os.access(p.parent, os.W_OK) or (exists and not os.access(p, os.W_OK)):
        raise _Fail(f"{option} {path}: cannot write there (permission denied)")
    if figure:
        from matplotlib.backend_bases import FigureCanvasBase

        formats = sorted(FigureCanvasBase.get_supported_filetypes())
        ext = p.suffix.lower().lstrip(".")
        if not ext:
            raise _Fail(f"{option} {path}: no file extension; end the name in .png, .pdf or .svg")
        if ext not in formats:
            raise _Fail(f"{option} {path}: cannot write a .{ext} figure; use one of "
                        + ", ".join("." + f for f in formats))


def _write_text(path: str, text: str, option: str) -> None:
    """Write an output file; a failure (disk full, …) as one line, not a traceback."""
    try:
        Path(path).write_text(text)
    except OSError as exc:
        raise _Fail(f"{option} {path}: cannot write ({exc.strerror or exc})") from None


# Options shared by `fit` and `diagnose`.
_FIX = click.option("--fix", multiple=True, metavar="NAME[=VALUE]", help="Hold a parameter fixed (repeatable).")
_RELEASE_TIME = click.option("--release-time", type=float, help="Known release instant [s] in each run's time axis.")
_COUNTS_PER_REV = click.option("--counts-per-rev", type=float, help="theta holds raw encoder counts with this many per revolution.")
_RESOLUTION = click.option("--resolution", type=float, metavar="STEP", help="Encoder step (sensor resolution) of theta in the log's units. Default: found from the readings' grid, or, for readings on no grid (analog, interpolated), the noise is estimated and the report says so.")
_QUIET = click.option("--quiet", "-q", is_flag=True, help="No report on stdout.")


def _MODEL_OPTIONS(fn):
    """--add / --remove / --effect-file: the model to start from."""
    for opt in reversed((
        click.option("--add", "add_effects", multiple=True, metavar="EFFECT", help="Add a library effect (repeatable; ripple:ORDER sets the order): asymmetric_friction, asymmetric_viscous, backlash, coulomb, gravity, hysteresis, kinematic_error, linear_stiffness, load_friction, ripple, soft_windup, stiffness, stribeck, torque_offset, viscous."),
        click.option("--remove", "remove_effects", multiple=True, metavar="EFFECT", help="Remove an effect of the base model (repeatable), e.g. viscous."),
        click.option("--effect-file", "effect_files", multiple=True, metavar="FILE.py", help="Your own effect: a Python file defining AbstractEffect instances (repeatable)."),
        click.option("--ratio", type=click.FloatRange(min=0, min_open=True), help="Gear ratio N between the logged axis and the output (default 100; 1: the logged angle is the output's, no gear)."),
    )):
        fn = opt(fn)
    return fn


class _Group(click.Group):
    """Usage errors (unknown option, value out of range, …) as one line, exit status 2."""

    def make_context(self, info_name, args, parent=None, **extra):
        try:
            return super().make_context(info_name, args, parent=parent, **extra)
        except click.UsageError as exc:
            raise _usage_fail(exc) from None

    def invoke(self, ctx):
        try:
            return super().invoke(ctx)
        except click.UsageError as exc:
            raise _usage_fail(exc) from None


def _usage_fail(exc: click.UsageError) -> _Fail:
    where = exc.ctx.command_path if exc.ctx is not None else "hdid"
    return _Fail(f"{exc.format_message()} (see '{where} --help')")


@click.group(cls=_Group, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="hdid")
def main():
    """hdid — identify harmonic-drive physics (stiffness, Stribeck friction, stick band,
    inertia) from encoder logs of the elastic-slide-free-motion test."""


@main.command("fit")
@click.argument("logs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--summary", "summary_out", metavar="OUT.csv", help="Several logs: one row per log (parameters, std, band, RMS, warnings, error).")
@click.option("--band-bracket/--no-band-bracket", default=None, help="Several logs: also compute the model-free stick-band bracket (an event-driven SciPy simulation per run; off by default in batch mode).")
@click.option("--workers", type=click.IntRange(1, 256), help="Several logs: fit in this many local worker processes (one core each; pip install 'hdid[dask]'). Worth it from a few hundred logs; default 1.")
@click.option("--dask", "dask_address", metavar="ADDRESS", help="Several logs: fit on a dask.distributed scheduler at ADDRESS (pip install 'hdid[dask]').")
@click.option("--json", "json_out", metavar="OUT.json", help="Write the results as JSON.")
@click.option("--plot", "plot_out", metavar="OUT.png", help="Measured vs model, residuals below.")
@click.option("--inertia", type=float, help="Total WG inertia [kg m^2] (default 7e-7, CSF-8 + small Maxon rotor).")
@click.option("--added-inertia", metavar="I1,I2,...", help="Known inertia added per run [kg m^2], in run order (or an added_inertia column).")
@click.option("--free-inertia", is_flag=True, help="Fit the inertia (needs --added-inertia runs or --inertia-prior).")
@click.option("--inertia-prior", metavar="MEAN,REL", help="Log-normal prior on the inertia, e.g. 7e-7,0.3.")
@_FIX
@_MODEL_OPTIONS
@_RELEASE_TIME
@_COUNTS_PER_REV
@_RESOLUTION
@click.option("--starts", type=click.IntRange(1, 32), help="Multi-starts (default: the library's, 6).")
@click.option("--start", "start_values", multiple=True, metavar="NAME=VALUE", help="Initial guess for a parameter, e.g. --start k1=1200 (repeatable): one more start from these values, run beside the multi-start grid.")
@click.option("--posterior", is_flag=True, help="Also sample the posterior with emcee (slow; see README).")
@click.option("--steps", type=click.IntRange(100, 10**6), help="Posterior chain length (default: until 50 autocorrelation times, at most 20000).")
@click.option("--walkers", type=click.IntRange(4, 4096), help="emcee walkers (default max(32, 2·dim)).")
@click.option("--sampler", type=click.Choice(["emcee", "smc"]), default="emcee", show_default=True, help="Posterior sampler: emcee (ensemble MCMC from the fit's optima, differential-evolution + independence moves; --steps/--walkers) or smc (tempered SMC alone; gives the log-evidence; its intervals were narrower than emcee's on the same logs). Calibration: benchmarks/README.md, Posterior.")
@click.option("--seed", type=int, default=0, show_default=True, help="Posterior seed.")
@click.option("--chains", "chains_out", metavar="OUT.nc", help="Save the posterior chains (arviz NetCDF).")
@click.option("--corner", "corner_out", metavar="OUT.png", help="Corner plot of the posterior.")
@click.option("--torque-constant", type=float, help="Driven log with a motor_current column: motor torque constant [N m/A].")
@click.option("--output-counts-per-rev", type=float, help="Driven log: theta_out/output_counts holds raw output-encoder counts with this many per revolution.")
@click.option("--order", type=click.IntRange(0, 32), help="Driven log: positional-error order (default: chosen by BIC up to 6).")
@click.option("--input-hold", type=click.Choice(["zoh", "foh"]), help="Driven log: the motor torque between samples. zoh: held from each sample to the next (a drive's command; the default for a motor_torque column); foh: linear between samples (a sampled analog signal; the default for a motor_current column).")
@click.option("--joint", is_flag=True, help="Several logs of ONE gear (a driven log and free-motion logs): one set of physical parameters for all.")
@_QUIET
def fit_cmd(logs, summary_out, json_out, plot_out, inertia, added_inertia, free_inertia,
            inertia_prior, fix, add_effects, remove_effects, effect_files, release_time,
            counts_per_rev, starts, posterior, steps, walkers, sampler, seed, chains_out, corner_out,
            quiet, band_bracket, workers, dask_address, torque_constant,
            output_counts_per_rev, order, joint, ratio, resolution, start_values, input_hold):
    """Fit stiffness, friction (and inertia) jointly to all runs of LOG.csv.

    LOG.csv has a header with columns time [s] and theta [rad, WG/motor angle]; optional
    run, setup, added_inertia. A log with a motor_torque (or motor_current) column is a
    driven (input/output) log: the fit then also identifies the output friction and,
    with a theta_out column, the stiffness from the twist and the positional error
    (paper eqs. 3, 8, 9). With several logs (or --summary) each is fitted on its own and
    tabulated; a bad file is reported in its row and the others complete. With --joint,
    a driven log and free-motion logs of one gear share one set of parameters.
    """
    if sampler == "smc" and (steps or walkers):
        raise _Fail("--steps/--walkers are emcee's options; leave them out with --sampler smc")
    model = _build_model(add_effects, remove_effects, effect_files, ratio)
    driven_options = {"torque_constant": torque_constant, "resolution": resolution,
                      "output_counts_per_rev": output_counts_per_rev}
    fit_options = {"input_hold": input_hold} if input_hold else {}
    if joint:
        if len(logs) < 2:
            raise _Fail("--joint: give a driven log and at least one free-motion log of the same gear")
        if posterior or chains_out or corner_out or summary_out:
            raise _Fail("--joint: --posterior/--chains/--corner/--summary are not available for joint fits")
        return _fit_driven([Path(p) for p in logs], model, json_out, plot_out, fix,
                           counts_per_rev, driven_options, order, release_time, quiet,
                           fit_options)
    if len(logs) == 1 and not summary_out and _is_driven(Path(logs[0])):
        if posterior or chains_out or corner_out:
            raise _Fail(f"{logs[0]}: --posterior is not available for driven logs yet; fit without it")
        return _fit_driven([Path(logs[0])], model, json_out, plot_out, fix, counts_per_rev,
                           driven_options, order, release_time, quiet, fit_options)
    if input_hold:
        what = (f"{logs[0]} has" if len(logs) == 1 else
                "a batch fits free-motion logs, which have")
        raise _Fail(f"--input-hold: {what} no motor_torque or motor_current column (a "
                    "free-motion log has no input to hold); leave --input-hold out, or give "
                    "it with one driven log (or --joint)")
    if start_values and (len(logs) > 1 or summary_out or joint):
        raise _Fail("--start takes one free-motion log; fit the logs one by one for it")
    if len(logs) > 1 or summary_out:
        return _fit_batch(logs, summary_out, json_out, plot_out, inertia, fix, release_time,
                          counts_per_rev, starts, quiet, posterior or chains_out or corner_out,
                          model, band_bracket, dask_address, workers, resolution)
    log_path = Path(logs[0])
    _check_output(json_out, [log_path], "--json")
    _check_output(plot_out, [log_path], "--plot", figure=True)
    _check_output(chains_out, [log_path], "--chains")
    _check_output(corner_out, [log_path], "--corner", figure=True)
    prior = _parse_floats(inertia_prior, "--inertia-prior")
    if prior is not None and len(prior) != 2:
        raise _Fail("--inertia-prior: expected MEAN,REL (e.g. 7e-7,0.3)")
    added = _parse_floats(added_inertia, "--added-inertia")
    fixed = _parse_fix(fix)
    guesses = _parse_fix(start_values, "--start")
    options = _options_used(click.get_current_context())
    phases = _Phases(enabled=not quiet and _stderr_is_tty())
    phases.start("loading JAX")

    from . import _fit, _io
    from ._errors import HdidError
    from ._saved import sha256

    try:
        phases.start(f"reading {log_path}")
        digest = sha256(log_path)
        data = _io.read_log(log_path, counts_per_rev=counts_per_rev, resolution=resolution)
        if added is not None:
            data = _with_added_inertia(data, added)
        _check_size(data)
        if guesses:
            model = _with_start_values(model, guesses)
        phases.start(f"fitting {len(data.runs)} run(s), {data.n_samples} samples "
                     f"({starts or 6} starts; a fresh environment compiles first, ~20 s)")
        result = _fit.fit(
            data,
            model,
            inertia=inertia,
            fix={k: v for k, v in fixed.items() if v is not None}
            | {k: None for k, v in fixed.items() if v is None} or None,
            free_inertia=True if free_inertia else None,
            inertia_prior=tuple(prior) if prior else None,
            release_time=release_time,
            start_from_model=bool(guesses),
            **({"n_starts": starts} if starts else {}),
        )
    except (HdidError, ValueError, KeyError) as exc:
        phases.stop()
        raise _Fail.from_error(exc) from None
    phases.stop()
    result.input_sha256, result.options = digest, options
    if not quiet:
        click.echo(result.report())
    summary = result.to_dict()
    if posterior or chains_out or corner_out:
        from ._posterior import sample_posterior

        post = sample_posterior(
            result, n_steps=steps, n_walkers=walkers, seed=seed, progress=not quiet,
            method=sampler,
        )
        summary.update(post.to_dict())
        if not quiet:
            click.echo("")
            click.echo(post.report())
        if chains_out:
            post.save(chains_out)
        if corner_out:
            post.plot_corner(corner_out)
    if json_out:
        _write_text(json_out, json.dumps(_finite(summary), indent=2) + "\n", "--json")
        if not quiet:
            click.echo(f"\nwrote {json_out}")
    if plot_out:
        phases.start(f"drawing {plot_out} (the model's band compiles once, ~10 s)")
        result.plot(plot_out)
        phases.stop()
        if not quiet:
            click.echo(f"wrote {plot_out}")


def _emit(report: str, summary: dict, json_out: str | None, quiet: bool) -> None:
    """Print the report (unless quiet) and write the JSON summary (if asked)."""
    if not quiet:
        click.echo(report)
    if json_out:
        _write_text(json_out, json.dumps(_finite(summary), indent=2) + "\n", "--json")
        if not quiet:
            click.echo(f"\nwrote {json_out}")


def _with_provenance(summary: dict, fit, path: Path) -> dict:
    """A diagnosis's JSON with the fields the fit JSON has for reuse (version, input and
    its SHA-256, options as given, the model and covariance of the base fit)."""
    from ._saved import provenance, sha256

    fit.input_sha256 = sha256(path)
    fit.options = _options_used(click.get_current_context())
    return {**provenance(fit), **summary}


def _is_driven(path: Path) -> bool:
    """Does the CSV's header name a motor-torque column? (cheap: reads one line)."""
    import re

    try:
        with open(path, "rb") as fh:
            header = fh.readline(65536).decode("utf-8-sig")
    except (OSError, ValueError):  # ValueError: not UTF-8 text
        return False  # read_log gives the proper one-line error
    names = {c.strip().strip('"').lower() for c in re.split(r"[,;\t]", header)}
    return bool(names & {"motor_torque", "motor_current"})


def _fit_driven(paths, model, json_out, plot_out, fix, counts_per_rev, driven_options,
                order, release_time, quiet, fit_options=None):
    for option, out in (("--json", json_out), ("--plot", plot_out)):
        _check_output(out, paths, option, figure=option == "--plot")
    fixed = _parse_fix(fix)
    options = _options_used(click.get_current_context())
    from . import _driven_fit, _io
    from ._errors import HdidError
    from ._saved import sha256

    digests = {str(p): sha256(p) for p in paths}

    fix_arg = {k: v for k, v in fixed.items() if v is not None} | {
        k: None for k, v in fixed.items() if v is None} or None
    try:
        logs = [_io.read_log(p, counts_per_rev=counts_per_rev,
                             **{k: v for k, v in driven_options.items() if v is not None})
                for p in paths]
        if len(logs) == 1:
            result = _driven_fit.fit_driven(logs[0], model, order=order, fix=fix_arg,
                                            **(fit_options or {}))
        else:
            result = _driven_fit.fit_joint(logs, model, order=order, fix=fix_arg,
                                           release_time=release_time, **(fit_options or {}))
    except (HdidError, ValueError, KeyError) as exc:
        raise _Fail.from_error(exc) from None
    result.input_sha256, result.options = digests, options
    _emit(result.report(), result.to_dict(), json_out, quiet)
    if plot_out:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        has_kin = result.data.has_output
        fig, axes = plt.subplots(3 if has_kin else 2, 1, figsize=(9, 9 if has_kin else 6),
                                 squeeze=False,
                                 gridspec_kw={"height_ratios": [2, 1, 2] if has_kin else [2, 1]})
        result.plot(ax=axes[0, 0], residual_ax=axes[1, 0])
        if has_kin:
            result.plot_kinematic_error(ax=axes[2, 0])
        fig.tight_layout()
        fig.savefig(plot_out, dpi=120)
        plt.close(fig)
        if not quiet:
            click.echo(f"wrote {plot_out}")


def _build_model(add, remove, files, ratio=None):
    """The base model with effects removed, library effects added, and user effects."""
    if not (add or remove or files or ratio):
        return None
    from ._model import Model
    from .effects import AbstractEffect, library

    model = Model.default() if ratio is None else Model.default().with_ratio(ratio)
    for name in remove:
        if name not in model.effect_names:
            raise _Fail(f"--remove {name}: the model has {', '.join(model.effect_names)}")
        model = model.without(name)
    for item in add:
        name, _, order = item.partition(":")  # ripple:24, kinematic_error:2 (cycles per WG rev)
        values = model.float_values()
        if order:
            try:
                values["order"] = float(order)
            except ValueError:
                raise _Fail(f"--add {item}: expected EFFECT or EFFECT:ORDER, e.g. ripple:24") from None
        lib = library(values)
        if name not in lib:
            raise _Fail(f"--add {name}: unknown effect; choose from {', '.join(sorted(lib))}")
        model = model.with_effect(lib[name])
    for path in files:
        effects = _load_effect_file(Path(path), AbstractEffect)
        for effect in effects:
            model = model.with_effect(effect)
    return model


def _load_effect_file(path: Path, base):
    import importlib.util

    if not path.is_file():
        raise _Fail(f"--effect-file {path}: no such file")
    spec = importlib.util.spec_from_file_location(f"hdid_user_effect_{path.stem}", path)
    module = importlib.util.module_from_spec(spec)
    try:
        spec.loader.exec_module(module)
    except Exception as exc:  # a user's file: report any failure in one line
        raise _Fail(f"--effect-file {path}: {type(exc).__name__}: {exc}") from None
    found = [v for v in vars(module).values() if isinstance(v, base)]
    if not found:
        raise _Fail(
            f"--effect-file {path}: defines no effect instance; add one at module level, "
            "e.g. `effect = MyEffect(amplitude=1e-4)` (starting values)"
        )
    return found


def _fit_batch(logs, summary_out, json_out, plot_out, inertia, fix, release_time,
               counts_per_rev, starts, quiet, posterior, model, band_bracket=None,
               dask_address=None, workers=None, resolution=None):
    paths = [Path(p) for p in logs]
    if plot_out or posterior:
        raise _Fail("--plot and --posterior take one log; fit the logs one by one for those")
    _check_output(summary_out, paths, "--summary")
    _check_output(json_out, paths, "--json")
    fixed = _parse_fix(fix)
    from ._batch import fit_many

    client = None
    if workers and workers > 1 and not dask_address:
        try:
            import distributed  # noqa: F401
        except ImportError:
            raise _Fail(f"--workers {workers} needs dask.distributed: pip install 'hdid[dask]' "
                        "(or leave --workers out)") from None
    if dask_address:
        try:
            from distributed import Client
        except ImportError:
            raise _Fail("--dask needs dask.distributed: pip install 'hdid[dask]'") from None
        try:
            client = Client(dask_address, timeout="10s")
        except OSError as exc:
            raise _Fail(f"--dask {dask_address}: cannot reach the scheduler ({exc})") from None
    table = fit_many(
        [str(p) for p in paths],
        progress=not quiet,
        band_bracket=band_bracket,
        client=client,
        workers=workers,
        model=model,
        inertia=inertia,
        fix={k: v for k, v in fixed.items()} or None,
        release_time=release_time,
        counts_per_rev=counts_per_rev,
        **({"n_starts": starts} if starts else {}),
        **({"resolution": resolution} if resolution else {}),
    )
    flat = table.drop(columns=["result"])
    timing = table.attrs.get("timing", {})
    if not quiet and "total_s" in timing:
        compile_s = timing.get("compile_s")
        click.echo(
            f"{len(flat)} log(s) in {timing['total_s']:.1f} s"
            + (f" (compile {compile_s:.1f} s, run {timing['run_s']:.1f} s)"
               if compile_s is not None else ""),
            err=True,
        )
    if not quiet:
        cols = [c for c in ("log", "k1", "k1_std", "tau_c", "tau_s", "stick_band_halfwidth_rad",
                            "rms_residual_counts", "n_warnings", "error") if c in flat]
        with __import__("pandas").option_context("display.width", 200, "display.max_colwidth", 60):
            click.echo(flat[cols].to_string(index=False))
    if summary_out:
        flat.to_csv(summary_out, index=False)
        if not quiet:
            click.echo(f"wrote {summary_out}")
    if json_out:
        rows = [r.result.to_dict() if r.result is not None else {"source": r.log, "error": r.error}
                for r in table.itertuples()]
        _write_text(json_out, json.dumps(_finite(rows), indent=2) + "\n", "--json")
    failed = int(flat["error"].notna().sum())
    if failed:
        click.echo(f"hdid: {failed} of {len(flat)} log(s) failed; see the error column"
                   + (f" of {summary_out}" if summary_out else ""), err=True)
    if failed == len(flat):
        raise SystemExit(2)
    if failed:
        raise SystemExit(EXIT_PARTIAL)


def _with_added_inertia(data, added):
    from dataclasses import replace

    from ._errors import LogError

    if len(added) != len(data.runs):
        raise LogError(
            f"--added-inertia gives {len(added)} values but the log has {len(data.runs)} "
            "runs; give one value per run, in run order",
            path=data.source,
        )
    if any(not (a >= 0) for a in added):
        raise LogError("--added-inertia: values must be >= 0 kg m^2", path=data.source)
    runs = tuple(replace(r, added_inertia=float(a)) for r, a in zip(data.runs, added))
    return replace(data, runs=runs)


def _finite(obj):
    """JSON has no NaN/inf: write them as null (the library's rule, ``_saved.finite``)."""
    from ._saved import finite

    return finite(obj)


@main.command("diagnose")
@click.argument("log", type=click.Path(dir_okay=False))
@click.option("--json", "json_out", metavar="OUT.json", help="Write verdict, candidates (best first) and the model ladder as JSON.")
@click.option("--plot", "plot_out", metavar="OUT.png", help="Model ladder: RMS and BIC after each step.")
@click.option("--residuals", "residuals_out", metavar="OUT.png", help="Residual views of the current model (vs time, angle, velocity, twist; ACF, spectrum).")
@click.option("--candidates", metavar="A,B,...", help="Only these candidates (default: every library effect that applies).")
@click.option("--steps", type=click.IntRange(1, 5), default=1, show_default=True, help="Forward-selection steps (add the best, diagnose again).")
@click.option("--inertia", type=float, help="Total WG inertia [kg m^2] (default 7e-7).")
@_FIX
@_MODEL_OPTIONS
@_RELEASE_TIME
@_COUNTS_PER_REV
@_RESOLUTION
@_QUIET
def diagnose_cmd(log, json_out, plot_out, residuals_out, candidates, steps, inertia, fix,
                 add_effects, remove_effects, effect_files, release_time, counts_per_rev, quiet,
                 ratio, resolution):
    """Fit the model to LOG.csv, then rank the effects that could be missing.

    Each candidate effect is added to the fitted model and refitted; candidates are ranked
    by ΔBIC. Verdicts: missing_effect (strong evidence and the residual then at the
    quantization floor), adequate (residual as white as the quantization allows),
    unexplained (structured residual no library effect fixes).
    """
    log_path = Path(log)
    for opt, path in (("--json", json_out), ("--plot", plot_out), ("--residuals", residuals_out)):
        _check_output(path, [log_path], opt, figure=opt != "--json")
    model = _build_model(add_effects, remove_effects, effect_files, ratio)
    fixed = _parse_fix(fix)
    wanted = [c.strip() for c in candidates.split(",") if c.strip()] if candidates else None

    from . import _io
    from ._diagnose import diagnose
    from ._errors import HdidError

    try:
        data = _io.read_log(log_path, counts_per_rev=counts_per_rev, resolution=resolution)
        _check_size(data)
        result = diagnose(
            data,
            model,
            candidates=wanted,
            steps=steps,
            # phases on a terminal only: redirected output gets the result alone
            progress=(lambda m: click.echo(f"hdid: {m}", err=True))
            if not quiet and _stderr_is_tty() else None,
            inertia=inertia,
            fix=fixed or None,
            release_time=release_time,
        )
    except (HdidError, ValueError, KeyError) as exc:
        raise _Fail.from_error(exc) from None
    _emit(result.report(), _with_provenance(result.to_dict(), result.base, log_path), json_out, quiet)
    if plot_out:
        result.plot_ladder(plot_out)
        if not quiet:
            click.echo(f"wrote {plot_out}")
    if residuals_out:
        result.base.plot_residuals(residuals_out)
        if not quiet:
            click.echo(f"wrote {residuals_out}")


@main.command("simulate")
@click.argument("out", type=click.Path(dir_okay=False))
@click.option("--amplitudes", default="0.157,-0.157,0.12,-0.12,0.08,-0.08,0.05,-0.05", show_default=True, help="Release angles [rad, WG], one run each.")
@click.option("--rate", type=float, default=1000.0, show_default=True, help="Sample rate [Hz].")
@click.option("--duration", type=float, default=0.3, show_default=True, help="Length of each run [s].")
@click.option("--hold", type=float, default=0.04, show_default=True, help="Pre-release hold [s].")
@click.option("--offset", type=float, default=0.0, show_default=True, help="Encoder reading at the spring zero [rad].")
@click.option("--counts-per-rev", type=int, default=4000, show_default=True, help="Encoder resolution (0: no quantization).")
@click.option("--noise", type=float, default=0.0, show_default=True, help="Gaussian noise before quantization [rad].")
@click.option("--seed", type=int, default=0, show_default=True, help="Seed for sub-sample release instants and noise.")
@click.option("--set", "values", multiple=True, metavar="NAME=VALUE", help="Model parameter, e.g. --set k1=1200 (repeatable).")
@click.option("--counts", is_flag=True, help="Write theta as integer counts.")
@click.option("--overwrite", is_flag=True, help="Replace OUT if it exists.")
@_QUIET
@click.option("--from", "from_json", metavar="FIT.json", help="Re-simulate a fitted model (the JSON of `hdid fit --json`): its effects and values, and by default its log's design (release angles, rate, length, encoder step, offset); options given here override.")
def simulate_cmd(out, amplitudes, rate, duration, hold, offset, counts_per_rev, noise, seed,
                 values, counts, overwrite, from_json, quiet):
    """Write a synthetic free-motion log (same format as `hdid fit` reads).

    \b
    The default design is the one whose recovery is measured (README, "A short tour";
    data/synthetic/csf8_rich_1khz.csv; benchmarks/results/posterior_design.md): 8 releases
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
    if not overwrite and Path(out).exists():
        raise _Fail(f"{out} exists; add --overwrite to replace it (or choose another file)")

    from ._errors import HdidError
    from ._synthetic import synthesize

    model = None
    if from_json:
        src = Path(from_json)
        if not src.is_file():
            raise _Fail(f"--from {from_json}: no such file")
        from ._saved import load

        try:
            fitted = load(src)
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
        synthesize(
            out, amplitudes=amps, rate=rate, duration=duration, hold=hold, offset=offset,
            counts_per_rev=counts_per_rev or None, noise=noise, seed=seed, values=params,
            model=model, as_counts=counts, overwrite=overwrite,
        )
    except (HdidError, ValueError, KeyError) as exc:
        raise _Fail.from_error(exc) from None
    if not quiet:
        click.echo(f"wrote {out}: {len(amps)} run(s) at {rate:g} Hz")


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


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
