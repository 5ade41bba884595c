"""``hdid design``: rank candidate experiments by what they would determine."""

from __future__ import annotations

from pathlib import Path

import click
import cloup

from ._common import _Command, _Fail, _QUIET, _check_output, _emit


@cloup.command("design", cls=_Command)
@click.argument("source", metavar="FIT.json|LOG.csv", type=click.Path(dir_okay=False))
@cloup.option_group(
    "Candidates and ranking",
    click.option("--target", "targets", metavar="NAMES", help="Rank by the std of these (comma-separated parameters or derived quantities; 'band' = stick-band half-width, 'frequency' = natural frequency), e.g. --target tau_c,band. Default: D-optimality."),
    click.option("--criterion", type=click.Choice(["targets", "d", "separate"]), help="'targets' (default with --target), 'd' (D-optimality on the free parameters) or 'separate' (default with --separate)."),
    click.option("--separate", metavar="A.json,B.json", help="Two fits of the same log by rival models (hdid fit --json with different --add): rank by the expected 2 ln LR that tells them apart, computed as diagnose computes its separating experiments (the rival refitted locally, then the largest fitted globally by hdid.fit until the top is a value)."),
    click.option("--experiments", "experiments_file", metavar="FILE", type=click.Path(dir_okay=False), help="Your own candidate experiments (TOML [[candidate]] tables or JSON list): each names what differs from the log (rate, amplitudes, counts_per_rev, repeats, added_inertia, duration, hold)."),
)
@cloup.option_group(
    "Check",
    click.option("--check", "check_n", type=click.IntRange(min=0), default=0, metavar="N", help="Simulate N logs of the top candidate at the current fit, fit them and print their spread beside the prediction."),
    click.option("--check-candidate", metavar="NAME", help="Check this candidate instead of the top one."),
    click.option("--seed", type=int, default=0, show_default=True, help="Seed of the check's simulated logs."),
)
@cloup.option_group(
    "Output",
    click.option("--json", "json_out", metavar="OUT.json", type=click.Path(dir_okay=False), help="Write the result as JSON (schema hdid/schema/design.schema.json)."),
    _QUIET,
)
# The former name of --experiments, hidden: `hdid diagnose --candidates` names effects, not
# experiments. Still accepted, with a warning.
@click.option("--candidates", "old_candidates", metavar="FILE", type=click.Path(dir_okay=False), hidden=True)
def design_cmd(source, targets, criterion, separate, experiments_file, check_n, check_candidate,
               seed, json_out, quiet, old_candidates):
    """Which experiment would determine what this log cannot: predicted standard errors of
    every parameter and derived quantity for candidate release tests (amplitudes and their
    number, repeats, sample rate, encoder, added inertia), from the linearised Fisher
    information of the exact simulator at the current fit, ranked.

    \b
    Examples:
      hdid fit log.csv --json fit.json && hdid design fit.json --target tau_c,band
      hdid design log.csv --experiments mine.toml --check 30 --json design.json
    """
    path = Path(source)
    if not path.is_file():
        raise _Fail(f"{source}: no such file (give a fit JSON from hdid fit --json, or a log CSV)")
    experiments_file = _experiments_file(experiments_file, old_candidates)
    if experiments_file and not Path(experiments_file).is_file():
        raise _Fail(f"--experiments {experiments_file}: no such file (TOML or JSON)")
    if check_candidate and not check_n:
        raise _Fail("--check-candidate needs --check N (how many logs to simulate)")
    pair = None
    if separate is not None:
        pair = [p.strip() for p in separate.split(",") if p.strip()]
        if len(pair) != 2:
            raise _Fail(f"--separate {separate!r}: give two fit JSONs, A.json,B.json")
        for p in pair:
            if not Path(p).is_file():
                raise _Fail(f"--separate {p}: no such file (a fit JSON from hdid fit --json)")
    if json_out:
        _check_output(json_out, [path], "--json")
    from .._design._design import design
    from .._errors import HdidError

    try:
        result = design(str(path), experiments_file, targets=targets, criterion=criterion,
                        check=check_n, check_candidate=check_candidate, seed=seed,
                        separate=pair)
    except (HdidError, ValueError, KeyError) as exc:
        raise _Fail.from_error(exc) from None
    _emit(result.report(), result.to_dict(), json_out, quiet)


def _experiments_file(experiments_file, old_candidates):
    """--experiments, or its former name --candidates (with a warning on stderr)."""
    if old_candidates is None:
        return experiments_file
    if experiments_file is not None and experiments_file != old_candidates:
        raise _Fail(f"--candidates {old_candidates} and --experiments {experiments_file}: give "
                    "--experiments alone (--candidates is its former name)")
    click.echo("hdid: warning: design's --candidates is now --experiments (diagnose's "
               f"--candidates names effects); use --experiments {old_candidates}", err=True)
    ctx = click.get_current_context()
    ctx.params["experiments_file"] = ctx.params.pop("old_candidates")
    return old_candidates
