"""``hdid diagnose``: which physical effect is missing, and what adding it changes."""

from __future__ import annotations

from pathlib import Path

import click
import cloup

from . import _common
from ._common import (
    MODEL_OPTIONS, _COUNTS_PER_REV, _FIX, _Command, _Fail, _QUIET, _RELEASE_TIME, _RESOLUTION,
    _build_model, _check_output, _check_size, _emit, _parse_fix, 
    _with_provenance,
)


@cloup.command("diagnose", cls=_Command)
@click.argument("log", type=click.Path(dir_okay=False))
@cloup.option_group("Input: the log", _COUNTS_PER_REV, _RESOLUTION, _RELEASE_TIME)
@cloup.option_group(
    "Model",
    *MODEL_OPTIONS,
    click.option("--inertia", type=float, help="Total WG inertia [kg m^2] (default 7e-7)."),
    _FIX,
)
@cloup.option_group(
    "Diagnosis",
    click.option("--candidates", metavar="A,B,...", help="Only these candidates (default: every library effect that applies)."),
    click.option("--selection-steps", type=click.IntRange(1, 5), metavar="N", default=1, show_default=True, help="Forward-selection steps: add the best candidate, diagnose again, this many times."),
)
@cloup.option_group(
    "Output",
    click.option("--json", "json_out", metavar="OUT.json", help="Write verdict, candidates (best first) and the model ladder as JSON."),
    click.option("--plot", "plot_out", metavar="OUT.png", help="Model ladder: RMS and BIC after each step."),
    click.option("--residuals", "residuals_out", metavar="OUT.png", help="Residual views of the current model (vs time, angle, velocity, twist; ACF, spectrum)."),
    _QUIET,
)
# The former name of --selection-steps, hidden: in `hdid fit`, --steps is the posterior's
# chain length. Still accepted, with a warning.
@click.option("--steps", "old_steps", type=click.IntRange(1, 5), metavar="N", hidden=True)
def diagnose_cmd(log, json_out, plot_out, residuals_out, candidates, selection_steps, old_steps,
                 inertia, fix, add_effects, remove_effects, effect_files, release_time,
                 counts_per_rev, quiet, ratio, resolution):
    """Fit the model to LOG.csv, then rank the effects that could be missing.

    Each candidate effect is added to the fitted model and refitted; candidates are ranked
    by ΔBIC. Verdicts: missing_effect (strong evidence and the residual then at the
    quantization floor), adequate (residual as white as the quantization allows),
    unexplained (structured residual no library effect fixes).
    """
    steps = _selection_steps(selection_steps, old_steps)
    log_path = Path(log)
    for opt, path in (("--json", json_out), ("--plot", plot_out), ("--residuals", residuals_out)):
        _check_output(path, [log_path], opt, figure=opt != "--json")
    model = _build_model(add_effects, remove_effects, effect_files, ratio)
    fixed = _parse_fix(fix)
    wanted = [c.strip() for c in candidates.split(",") if c.strip()] if candidates else None

    from .. import _log
    from .._diagnosis._diagnose import diagnose
    from .._errors import HdidError
    from .._results._plot import bare_figures, save_figure

    try:
        data = _log.read_log(log_path, counts_per_rev=counts_per_rev, resolution=resolution)
        _check_size(data)
        result = diagnose(
            data,
            model,
            candidates=wanted,
            steps=steps,
            # phases on a terminal only: redirected output gets the result alone
            progress=(lambda m: click.echo(f"hdid: {m}", err=True))
            if not quiet and _common._stderr_is_tty() else None,
            inertia=inertia,
            fix=fixed or None,
            release_time=release_time,
        )
    except (HdidError, ValueError, KeyError) as exc:
        raise _Fail.from_error(exc) from None
    _emit(result.report(), _with_provenance(result.to_dict(), result.base, log_path), json_out, quiet)
    if plot_out:
        with bare_figures():
            save_figure(result.plot_ladder(), plot_out, dpi=120)
        if not quiet:
            click.echo(f"wrote {plot_out}")
    if residuals_out:
        with bare_figures():
            save_figure(result.base.plot_residuals(), residuals_out)
        if not quiet:
            click.echo(f"wrote {residuals_out}")


def _selection_steps(selection_steps: int, old_steps: int | None) -> int:
    """--selection-steps, or the deprecated --steps (with a warning on stderr)."""
    if old_steps is None:
        return selection_steps
    ctx = click.get_current_context()
    given = ctx.get_parameter_source("selection_steps") != click.core.ParameterSource.DEFAULT
    if given and selection_steps != old_steps:
        raise _Fail(f"--steps {old_steps} and --selection-steps {selection_steps}: give "
                    "--selection-steps alone (--steps is its former name)")
    click.echo(f"hdid: warning: diagnose's --steps is now --selection-steps (--steps is the "
               f"posterior's chain length in `hdid fit`); use --selection-steps {old_steps}",
               err=True)
    # the JSON's options record it by its name
    ctx.params["selection_steps"] = ctx.params.pop("old_steps")
    ctx.set_parameter_source("selection_steps", click.core.ParameterSource.COMMANDLINE)
    return old_steps
