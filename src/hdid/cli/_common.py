"""What the commands share: one-line errors (exit 2), option parsing, output checks, the model\nthe options build, the report/JSON writer."""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

import click
import cloup


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
        from ._flags import to_flags

        # One line whatever the message quotes (a file name with a newline, …), naming
        # flags where the library's message names its Python arguments.
        msg = "".join(c if c.isprintable() else repr(c)[1:-1]
                      for c in to_flags(self.format_message()))
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


def _parse_priors(items: tuple[str, ...]) -> dict[str, tuple[float, float]]:
    """``--prior NAME=VALUE,SD`` (repeatable) as ``sample_posterior(prior=...)`` takes it."""
    out: dict[str, tuple[float, float]] = {}
    for item in items:
        name, _, rest = item.partition("=")
        parts = rest.split(",")
        if not name.strip() or len(parts) != 2:
            raise _Fail(f"--prior {item!r}: expected NAME=VALUE,SD (e.g. --prior tau_c=2.5e-3,0.3: "
                        "median 2.5 mN m, sd 0.3 in log, i.e. about ±30 %)")
        try:
            value, sd = float(parts[0]), float(parts[1])
        except ValueError:
            raise _Fail(f"--prior {item!r}: VALUE and SD must be numbers") from None
        if not (math.isfinite(value) and math.isfinite(sd) and sd > 0):
            raise _Fail(f"--prior {item!r}: give a finite VALUE and an SD > 0")
        out[name.strip()] = (value, sd)
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
    from .._models._model import Model

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
    if figure:
        from matplotlib.backend_bases import FigureCanvasBase

        formats = sorted(FigureCanvasBase.get_supported_filetypes())
        ext = p.suffix.lower().lstrip(".")
        if not ext:
            raise _Fail(f"{option} {path}: no file extension; end the name in .png, .pdf or .svg")
        if ext not in formats:
            raise _Fail(f"{option} {path}: cannot write a .{ext} figure; use one of "
                        + ", ".join("." + f for f in formats))
    _probe_write(str(path), option)


def _probe_write(path: str, option: str) -> None:
    """Open ``path`` for writing, as the command will after its work, and close it: a file
    system that refuses (``/proc``, read-only, full of inodes, a name the OS rejects)
    answers now, not after the fit. An existing regular file is opened to append
    (nothing truncated, nothing written, its time stamps kept); a new one is created and
    removed. Devices and pipes (``/dev/null``, ``/dev/stdout``) are not opened: opening a
    pipe may wait for its reader."""
    import os
    import stat

    try:
        if os.path.exists(path):
            if not stat.S_ISREG(os.stat(path).st_mode):
                if not os.access(path, os.W_OK):
                    raise PermissionError(13, "permission denied")
                return
            os.close(os.open(path, os.O_WRONLY | os.O_APPEND))
        elif os.path.islink(path):  # a link to a file not yet there: its folder decides
            if not os.access(Path(path).resolve().parent, os.W_OK):
                raise PermissionError(13, "permission denied")
        else:
            os.close(os.open(path, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            try:
                os.unlink(path)
            except OSError:
                pass
    except OSError as exc:
        raise _Fail(f"{option} {path}: cannot write there ({exc.strerror or exc}); choose "
                    "a file in a folder you can write to") from None


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


class _AddOption(click.Option):
    """``--add``: its help lists the effects that can be added, worked out only when the
    help is shown (it imports the effects, and with them JAX: ``hdid --help`` stays fast)."""

    def get_help_record(self, ctx):
        self.help = _add_help()
        return super().get_help_record(ctx)


def _addable() -> tuple[dict[str, list[str]], list[str]]:
    """``({slot: [keys]}, base keys)``: the registry's effects that ``--add`` offers, by
    the base-model effect each replaces (``""``: none, it adds a term), and the keys of
    the base model's own effects, which are in already and not offered."""
    from .._models._model import Model
    from ..effects import registry

    base = Model.default()
    base_keys = [type(e).key for e in base.effects]
    base_classes = {type(e) for e in base.effects}
    values = base.float_values()
    slots: dict[str, list[str]] = {}
    for cls in dict.fromkeys(registry().values()):  # an alias key maps to its class once
        if cls in base_classes:
            continue
        try:
            name = cls.start_from(values).name
        except Exception:  # a plugin that cannot start from the base values: offer it plain
            name = ""
        slot = name if name in base.effect_names else ""
        slots.setdefault(slot, []).append(cls.key)
    return {k: sorted(v) for k, v in slots.items()}, base_keys


def _add_help() -> str:
    slots, base_keys = _addable()
    parts = [f"replacing {slot}: {', '.join(keys)}" for slot, keys in sorted(slots.items()) if slot]
    new = slots.get("", [])
    text = ("Add an effect to the model (repeatable; ripple:ORDER sets the order). "
            f"The base model's {', '.join(base_keys)} are in already (--remove takes one "
            "out). New terms: " + ", ".join(new) + ". ")
    return text + ("Alternative laws, " + "; ".join(parts) + "." if parts else "")


def _effect_to_add(model, item: str):
    """The effect ``--add ITEM`` adds to ``model`` (``EFFECT`` or ``EFFECT:ORDER``)."""
    from ..effects import library

    name, _, order = item.partition(":")  # ripple:24, kinematic_error:2 (cycles per WG rev)
    values = model.float_values()
    if order:
        try:
            values["order"] = float(order)
        except ValueError:
            raise _Fail(f"--add {item}: expected EFFECT or EFFECT:ORDER, e.g. ripple:24") from None
    lib = library(values)  # every key of the registry, aliases of renamed effects included
    slots, base_keys = _addable()
    offered = sorted(k for keys in slots.values() for k in keys)
    if name not in lib:
        raise _Fail(f"--add {name}: unknown effect; choose from {', '.join(offered)}")
    effect = lib[name]
    if any(type(e) is type(effect) for e in model.effects):
        raise _Fail(f"--add {name}: the model has it already (the base model is "
                    f"{', '.join(base_keys)}); --add takes {', '.join(offered)}")
    return effect


_ADD = click.option("--add", "add_effects", multiple=True, metavar="EFFECT", cls=_AddOption,
                    help="Add an effect to the model (repeatable).")
_REMOVE = click.option("--remove", "remove_effects", multiple=True, metavar="EFFECT", help="Remove an effect of the base model (repeatable), e.g. viscous.")
_EFFECT_FILE = click.option("--effect-file", "effect_files", multiple=True, metavar="FILE.py", help="Your own effect: a Python file defining AbstractEffect instances (repeatable).")
_RATIO = click.option("--ratio", type=click.FloatRange(min=0, min_open=True), help="Gear ratio N between the logged axis and the output (default 100; 1: the logged angle is the output's, no gear).")

#: --add / --remove / --effect-file / --ratio: the model to start from, in help order.
MODEL_OPTIONS = (_ADD, _REMOVE, _EFFECT_FILE, _RATIO)


def _MODEL_OPTIONS(fn):
    """--add / --remove / --effect-file / --ratio as one decorator."""
    for opt in reversed(MODEL_OPTIONS):
        fn = opt(fn)
    return fn


class _Command(cloup.Command):
    """A command whose ``--help`` lists its options under headings (cloup's option groups,
    in the order input, model, fit, output, then the optional parts)."""


class _Group(click.Group):
    """Usage errors (unknown option, value out of range, …) as one line, exit status 2. As the
    ``hdid`` process (called with no arguments), it leaves without the interpreter's teardown."""

    def __call__(self, *args, **kwargs):
        if args or kwargs:  # called by a program (``main([...])``): as click's
            return super().__call__(*args, **kwargs)
        try:
            super().__call__()
            code = 0
        except SystemExit as exc:
            code = exc.code
        _leave(code)

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


def _leave(code) -> None:
    """End the ``hdid`` process with ``code`` as the interpreter would — threads' exit hooks and
    other threads joined, exit handlers run, output flushed — but without freeing every module,
    JAX's compiled programs and XLA's client one by one (measured on the shipped paper log with a
    warm cache: 0.5 s of the command's 4.1 s of CPU, ≈ 1 s of wall time on a loaded core). Where
    the Python has no ``threading._shutdown``: exits normally."""
    import atexit
    import os
    import threading

    if code is not None and not isinstance(code, int):  # as SystemExit("message")
        print(code, file=sys.stderr)
        code = 1
    if not callable(shutdown := getattr(threading, "_shutdown", None)):
        sys.exit(code)
    shutdown()  # what the interpreter runs first at exit: executors' hooks, non-daemon threads joined
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed pipe or stream: nothing left to write
            pass
    os._exit(code or 0)


def _usage_fail(exc: click.UsageError) -> _Fail:
    where = exc.ctx.command_path if exc.ctx is not None else "hdid"
    return _Fail(f"{exc.format_message()} (see '{where} --help')")


def _emit(report: str, summary: dict, json_out: str | None, quiet: bool) -> None:
    """Print the report (unless quiet; the library's argument names as flags) and write
    the JSON summary (if asked)."""
    from ._flags import to_flags

    if not quiet:
        click.echo(to_flags(report))
    if json_out:
        _write_text(json_out, json.dumps(_finite(summary), indent=2) + "\n", "--json")
        if not quiet:
            click.echo(f"\nwrote {json_out}")


def _with_provenance(summary: dict, fit, path: Path) -> dict:
    """A diagnosis's JSON with the fields the fit JSON has for reuse (version, input and
    its SHA-256, options as given, the model and covariance of the base fit)."""
    from .._results._saved import provenance, sha256

    fit.input_sha256 = sha256(path)
    fit.options = _options_used(click.get_current_context())
    return {**provenance(fit), **summary}


def _build_model(add, remove, files, ratio=None):
    """The base model with effects removed, library effects added, and user effects."""
    if not (add or remove or files or ratio):
        return None
    from .._models._model import Model
    from ..effects import AbstractEffect

    model = Model.default() if ratio is None else Model.default().with_ratio(ratio)
    for name in remove:
        if name not in model.effect_names:
            raise _Fail(f"--remove {name}: the model has {', '.join(model.effect_names)}")
        model = model.without(name)
    for item in add:
        model = model.with_effect(_effect_to_add(model, item))
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
    before = time.time()  # (the program store trusts the file unless modified after this)
    try:
        spec.loader.exec_module(module)
    except Exception as exc:  # a user's file: report any failure in one line
        raise _Fail(f"--effect-file {path}: {type(exc).__name__}: {exc}") from None
    from .._problems import _program_deps

    _program_deps.loaded(path, before)
    found = [v for v in vars(module).values() if isinstance(v, base)]
    if not found:
        raise _Fail(
            f"--effect-file {path}: defines no effect instance; add one at module level, "
            "e.g. `effect = MyEffect(amplitude=1e-4)` (starting values)"
        )
    return found


def _finite(obj):
    """JSON has no NaN/inf: write them as null (the library's rule, ``_saved.finite``)."""
    from .._results._saved import finite

    return finite(obj)
