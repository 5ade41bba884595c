"""``hdid fit``: one log, several (a batch), a driven log or a joint fit; optional posterior."""

from __future__ import annotations

import functools
import json
from pathlib import Path

import click
import cloup

from . import _common
from ._flags import to_flags
from ._common import (
    EXIT_PARTIAL, MODEL_OPTIONS, _COUNTS_PER_REV, _FIX, _Command, _Fail, _Phases, _QUIET,
    _RELEASE_TIME, _RESOLUTION, _build_model, _check_output, _check_size, _emit, _finite,
    _options_used, _parse_fix, _parse_floats, _with_start_values,
    _write_text,
)


@cloup.command("fit", cls=_Command)
@click.argument("logs", nargs=-1, required=True, type=click.Path(dir_okay=False))
@cloup.option_group(
    "Input: the log",
    _COUNTS_PER_REV, _RESOLUTION, _RELEASE_TIME,
    click.option("--added-inertia", metavar="I1,I2,...", help="Known inertia added per run [kg m^2], in run order (or an added_inertia column)."),
)
@cloup.option_group(
    "Model",
    *MODEL_OPTIONS,
    click.option("--inertia", type=float, help="Total WG inertia [kg m^2] (default 7e-7, CSF-8 + small Maxon rotor)."),
    click.option("--free-inertia", is_flag=True, help="Fit the inertia (needs --added-inertia runs or --inertia-prior)."),
    click.option("--inertia-prior", metavar="MEAN,REL", help="Log-normal prior on the inertia, e.g. 7e-7,0.3."),
    _FIX,
)
@cloup.option_group(
    "Fit",
    click.option("--starts", type=click.IntRange(1, 32), metavar="N", help="Multi-starts (default: the library's, 6)."),
    click.option("--start", "start_values", multiple=True, metavar="NAME=VALUE", help="Initial guess for a parameter, e.g. --start k1=1200 (repeatable): one more start from these values, run beside the multi-start grid."),
)
@cloup.option_group(
    "Output",
    click.option("--json", "json_out", metavar="OUT.json", help="Write the results as JSON."),
    click.option("--plot", "plot_out", metavar="OUT.png", help="Measured vs model, residuals below."),
    _QUIET,
)
@cloup.option_group(
    "Posterior (one free-motion log)",
    click.option("--posterior", is_flag=True, help="Also sample the posterior (slow; see README)."),
    click.option("--sampler", type=click.Choice(["emcee", "smc"]), default="emcee", show_default=True, help="Posterior sampler: emcee (ensemble MCMC from the fit's optima, differential-evolution + independence moves; --steps/--walkers) or smc (tempered SMC alone; --particles; gives the log-evidence; its intervals were narrower than emcee's on the same logs). Calibration: benchmarks/results/posterior_sbc.md; the choice: docs/decisions/smc-vs-emcee.md."),
    click.option("--steps", type=click.IntRange(100, 10**6), metavar="N", help="emcee chain length (default: until 50 autocorrelation times, at most 20000)."),
    click.option("--walkers", type=click.IntRange(4, 4096), metavar="N", help="emcee walkers (default max(32, 2·dim))."),
    click.option("--particles", type=click.IntRange(50, 10**5), metavar="N", help="smc particles per run (default 300)."),
    click.option("--seed", type=int, default=0, show_default=True, help="Posterior seed."),
    click.option("--prior", "priors", multiple=True, metavar="NAME=VALUE,SD", help="A Gaussian prior of your own (a datasheet's) on a fitted parameter, replacing the default, e.g. --prior tau_c=2.5e-3,0.3 (median 2.5 mN m, sd 0.3 in log: about ±30 %; delta's sd is in its logit). Repeatable. Without it each positive scale has a weakly informative log-normal prior centred on a scale from the log's own physics (×10 either way at 95 %), listed with its source in the report."),
    click.option("--default-prior", type=click.Choice(["weak", "flat"]), default="weak", show_default=True, help="The prior of the parameters no --prior names. weak: log-normal around a scale of the log's physics (×10 either way at 95 %); flat: flat in log (in value for k2, tau_c, c_v) within a box around the fit — it puts mass on limits the data may not support, and chains mix slowly on it."),
    click.option("--chains", "chains_out", metavar="OUT.nc", help="Save the posterior chains (arviz NetCDF)."),
    click.option("--corner", "corner_out", metavar="OUT.png", help="Corner plot of the posterior."),
)
@cloup.option_group(
    "Batch (several logs, each fitted on its own)",
    click.option("--summary", "summary_out", metavar="OUT.csv", help="One row per log (parameters, std, band, RMS, warnings, error)."),
    click.option("--band-bracket/--no-band-bracket", default=None, help="Also compute the model-free stick-band bracket (an event-driven SciPy simulation per run; off by default in batch mode)."),
    click.option("--workers", type=click.IntRange(1, 256), metavar="N", help="Fit in this many local worker processes (one core each; pip install 'hdid[dask]'). Worth it from a few hundred logs; default 1."),
    click.option("--dask", "dask_address", metavar="ADDRESS", help="Fit on a dask.distributed scheduler at ADDRESS (pip install 'hdid[dask]')."),
)
@cloup.option_group(
    "Driven logs (a motor_torque or motor_current column)",
    click.option("--torque-constant", type=float, help="Motor torque constant [N m/A] of a motor_current column."),
    click.option("--output-counts-per-rev", type=float, help="theta_out/output_counts holds raw output-encoder counts with this many per revolution."),
    click.option("--order", type=click.IntRange(0, 32), metavar="N", help="Positional-error order (default: chosen by BIC up to 6)."),
    click.option("--input-hold", type=click.Choice(["zoh", "foh"]), help="The motor torque between samples. zoh: held from each sample to the next (a drive's command; the default for a motor_torque column); foh: linear between samples (a sampled analog signal; the default for a motor_current column)."),
    click.option("--joint", is_flag=True, help="Several logs of ONE gear (a driven log and free-motion logs): one set of physical parameters for all."),
)
def fit_cmd(logs, summary_out, json_out, plot_out, inertia, added_inertia, free_inertia,
            inertia_prior, fix, add_effects, remove_effects, effect_files, release_time,
            counts_per_rev, starts, posterior, steps, walkers, particles, sampler, seed, priors,
            default_prior, chains_out, corner_out, quiet, band_bracket, workers, dask_address,
            torque_constant, output_counts_per_rev, order, joint, ratio, resolution, start_values, input_hold):
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
    if particles and sampler != "smc":
        raise _Fail("--particles is smc's option; add --sampler smc, or leave it out")
    post_prior = _common._parse_priors(priors)
    if post_prior and not (posterior or chains_out or corner_out):
        raise _Fail("--prior is the posterior's: add --posterior (or --chains/--corner)")
    if default_prior != "weak" and not (posterior or chains_out or corner_out):
        raise _Fail("--default-prior is the posterior's: add --posterior (or --chains/--corner)")
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
    phases = _Phases(enabled=not quiet and _common._stderr_is_tty())
    phases.start("loading JAX")

    from .._fitting import _fit
    from .. import _log
    from .._errors import HdidError
    from .._results._plot import bare_figures, save_figure
    from .._results._saved import sha256

    try:
        phases.start(f"reading {log_path}")
        digest = sha256(log_path)
        data = _log.read_log(log_path, counts_per_rev=counts_per_rev, resolution=resolution)
        if added is not None:
            data = _with_added_inertia(data, added)
        _check_size(data)
        if guesses:
            model = _with_start_values(model, guesses)
        phases.start(f"fitting {len(data.runs)} run(s), {data.n_samples} samples "
                     f"({starts or 6} starts; a fresh environment compiles first, ~20 s)")
        fit_one = _fit.fit
        if getattr(getattr(model, "reading", None), "phases", 0) is None:  # --add reading_age
            from .._fitting._reading_age import fit_with_age

            fit_one = functools.partial(fit_with_age, fit=_fit.fit)
        result = fit_one(
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
        click.echo(to_flags(result.report()))
    summary = result.to_dict()
    if posterior or chains_out or corner_out:
        from .._posterior import sample_posterior

        try:
            post = sample_posterior(
                result, n_steps=steps, n_walkers=walkers, seed=seed, progress=not quiet,
                method=sampler, prior=post_prior or None, n_particles=particles,
                default_prior=default_prior,
            )
        except (HdidError, ValueError) as exc:  # a --prior naming no free parameter, …
            msg = str(exc)
            raise _Fail(("--" + msg if msg.startswith("prior") else msg).replace("\n", " ")) from None
        summary.update(post.to_dict())
        if not quiet:
            click.echo("")
            click.echo(to_flags(post.report()))
        if chains_out:
            post.save(chains_out)
        if corner_out:
            with bare_figures():
                save_figure(post.plot_corner(), corner_out, dpi=90)
    if json_out:
        _write_text(json_out, json.dumps(_finite(summary), indent=2) + "\n", "--json")
        if not quiet:
            click.echo(f"\nwrote {json_out}")
    if plot_out:
        phases.start(f"drawing {plot_out} (the model's band compiles once, ~10 s)")
        with bare_figures():
            save_figure(result.plot(), plot_out)
        phases.stop()
        if not quiet:
            click.echo(f"wrote {plot_out}")


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
    from .._fitting import _driven_fit
    from .. import _log
    from .._errors import HdidError
    from .._results._saved import sha256

    digests = {str(p): sha256(p) for p in paths}

    fix_arg = {k: v for k, v in fixed.items() if v is not None} | {
        k: None for k, v in fixed.items() if v is None} or None
    try:
        logs = [_log.read_log(p, counts_per_rev=counts_per_rev,
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
        from matplotlib.figure import Figure

        has_kin = result.data.has_output
        fig = Figure(figsize=(9, 9 if has_kin else 6))  # only saved: no pyplot, no backend
        axes = fig.subplots(3 if has_kin else 2, 1, squeeze=False,
                            gridspec_kw={"height_ratios": [2, 1, 2] if has_kin else [2, 1]})
        result.plot(ax=axes[:2, 0])
        if has_kin:
            result.plot_kinematic_error(ax=axes[2, 0])
        fig.tight_layout()
        fig.savefig(plot_out, dpi=120)
        if not quiet:
            click.echo(f"wrote {plot_out}")


def _fit_batch(logs, summary_out, json_out, plot_out, inertia, fix, release_time,
               counts_per_rev, starts, quiet, posterior, model, band_bracket=None,
               dask_address=None, workers=None, resolution=None):
    paths = [Path(p) for p in logs]
    if plot_out or posterior:
        raise _Fail("--plot and --posterior take one log; fit the logs one by one for those")
    _check_output(summary_out, paths, "--summary")
    _check_output(json_out, paths, "--json")
    fixed = _parse_fix(fix)
    from .._fitting._batch import fit_many

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
    for col in ("error", "warnings", "band_bracket"):  # the library's words as flags
        if col in flat:
            flat[col] = flat[col].map(lambda v: to_flags(v) if isinstance(v, str) else v)
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

    from .._errors import LogError

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
