"""``sample_posterior``: emcee around a least-squares fit, until converged (arviz)."""

from __future__ import annotations

import sys
import time

from .density import PRIOR_HALF_WIDTH, gaussian_prior
from .ensemble import (  # noqa: F401 (the constants re-exported: the package, the docs)
    BURN_IN, BURN_IN_STAGES, CHECK_GROWTH, MIN_TAU_MULTIPLE, MODE_GAP, _Ensemble, default_burn_in)
from .ensemble import _short_of_tau  # noqa: F401 (re-exported for the diagnostics tests)
from .errors import PosteriorError, one_line_failures, walkers_enough
from .priors import finish
from .result import PosteriorResult


@one_line_failures
def sample_posterior(
    fit,
    *,
    n_walkers: int | None = None,
    n_steps: int | None = None,
    max_steps: int = 20000,
    burn_in: int | None = None,
    chunk: int = 500,
    seed: int = 0,
    progress: bool | None = None,
    likelihood: str = "auto",
    moves=None,
    sigma_floor: float | None = None,
    modes="auto",
    linear_prior: tuple[str, ...] | None = None,
    sample_linear: tuple[str, ...] | None = None,
    method: str = "emcee",
    n_particles: int | None = None,
    prior: dict | None = None,
    log=None,
    default_prior: str = "weak",
) -> PosteriorResult:
    """Sample the posterior of ``fit``'s parameters with emcee, until converged.

    ``method="emcee"`` (default, the engine of the reported draws): an ensemble of walkers
    started from the optima's Laplace approximations, differential-evolution moves plus an
    independence Metropolis–Hastings move from a t-mixture over the optima (below); the
    verdict is arviz's on its chain. Measured side by side on the same logs
    (docs/decisions/smc-vs-emcee.md) it mixed better than emcee started
    from a tempered-SMC pilot with a proposal fitted to the SMC particles (retired).

    ``method="smc"``: tempered sequential Monte Carlo alone from the optima's Laplace
    mixture (:func:`~hdid._posterior.smc.sample_smc`: 4 independent runs whose agreement is
    its convergence test; gives the log-evidence); ``n_particles`` per run. It passes its
    own test in seconds, but on the shipped paper log its intervals are narrower than the
    emcee chains' (v_s, tau_c) and widen with its particle count
    (docs/decisions/smc-vs-emcee.md): kept for comparison and the evidence,
    not as the default. The options from ``n_walkers`` to ``sample_linear`` other than
    ``prior`` are emcee's.

    Modes: with ``modes="auto"`` (default) :func:`find_modes` restarts the local fit
    around ``fit`` — started also at the aliases ``k·fs ± f`` of the fit's swing whose k1
    the prior finds plausible (:mod:`~hdid._posterior.aliases`: a log that does not resolve
    its swing may be fitted on the wrong alias) — and keeps every distinct optimum with
    its Laplace mass; the walkers
    start spread over them in proportion to that mass; it adds the *limit fits* of the
    parameters whose prior is flat in value (each held near zero, the rest refitted:
    :mod:`~hdid._posterior.limits`), which keep a share of the independence proposal, and
    the result warns ``LOWER END NOT MEASURED`` when the data allow values below a chain's
    95 % interval (``BOUNDED ABOVE ONLY`` when the chain reaches the vanishing end); under
    the weak default priors (nothing flat in value) the same continuations give starts down
    those ridges instead (``ridge:NAME``, at most 10 % of the weight, SMC's only: emcee's
    walkers stall there, ``modes.RIDGE_SAMPLERS``; :func:`~hdid._posterior.modes.seek_ridges`), and a continuation that finds a better
    basin adds its optimum. ``modes="fit"`` uses the fit's optimum only (the limit fits are still sought, for the
    warning); a list of :class:`Mode` is used as given.

    Burn-in (discarded): ``burn_in`` steps of differential evolution plus independence
    Metropolis–Hastings from a t-mixture over the optima (:class:`MixtureProposal`),
    refitted after each of ``BURN_IN_STAGES`` stages; the kept chain uses the last mixture,
    fixed. Default (:func:`~hdid._posterior.ensemble.default_burn_in`): ``BURN_IN`` = 8000
    steps for a chain grown until converged — the walkers start at the optima's Laplace
    width, narrower than the posterior along the friction law's ridge, and need that long
    to spread over it (docs/decisions/emcee-burn-in.md) — and ``n_steps`` clipped to
    [400, 8000] for a chain of fixed length. (A normalizing flow fitted to the burn-in draws in its place was measured and
    lost: docs/decisions/normalizing-flow.md; so did emcee in the latent space of a flow
    fitted to an SMC pilot, and that flow as the independence move, under the physical
    priors: the same record.)

    Priors (:mod:`~hdid._posterior.priors`, issue 34's decision (a)): every positive
    physical scale an effect declares (``k1``, ``k2``, ``tau_c``, ``tau_s``, ``c_v``, any
    effect's amplitudes) is log-normal around a scale of the log in hand, its central 95 %
    a factor 10.5 either way; ``v_s`` and ``delta`` keep the Stribeck law's physical priors;
    ``prior=`` (``--prior``) replaces the default of the parameters it names;
    ``default_prior="flat"`` restores the earlier flat priors (flat in log, in value for
    ``k2``, ``tau_c``, ``c_v``; not recommended: mass on limits the data do not support).
    The result's ``priors`` (JSON ``posterior_prior``) gives each parameter's prior centre,
    95 % range, where its scale came from and its posterior/prior width ("set by the prior"
    above 0.5).

    The kept chain grows (checked after ``chunk`` steps, then at every growth by
    ``CHECK_GROWTH``) until it converges — every sampled quantity and the stick-band
    half-width has bulk and tail ESS ≥ 400 and either a rank-normalised R-hat ≤ 1.01
    (arviz, walkers as chains) or the chain is ≥ 50 τ long (the ensemble rule; τ about the
    ensemble mean; :func:`~hdid._posterior.diagnostics.convergence`) — or reaches
    ``max_steps``; ``n_steps`` fixes its length instead. A chain that falls short carries a
    ``NOT CONVERGED`` warning that says what to do.

    Parameters
    ----------
    fit:
        A :class:`~hdid.FitResult`.
    n_walkers:
        Default ``max(32, 2·D)`` (emcee's red-blue moves need at least twice the dimension).
    progress:
        Progress bar (tqdm); shown only when standard error is a terminal (default: then).
    likelihood:
        ``"auto"`` / ``"gaussian"``: Gaussian with the ``q²/12`` rounding variance added when
        the encoder step is known (the interval likelihood was retired, see
        docs/decisions/interval-likelihood.md).
    moves:
        emcee moves (a move, a list of moves or of ``(move, weight)``), or a callable
        ``(log_posterior, proposal) -> moves``; default :func:`default_moves`. A move with
        a ``burn_in_update(acceptance, draws)`` method is given its acceptance rate and the
        stage's draws after each burn-in stage.
    prior:
        Gaussian priors of your own, replacing the default (flat box, weak priors) of the
        parameters named: ``{name: (centre value, sd)}``, the sd in the parameter's
        transformed space — log for positive parameters (``{"v_s": (5.0, 0.3)}`` is a
        log-normal of median 5 rad/s and ±30 %), logit for ``delta``. With both ``tau_c``
        and ``tau_s`` given, ``tau_s ≥ tau_c`` is imposed. What the data then narrowed is
        in ``widths`` (posterior / prior sd).
    sample_linear:
        Log-transformed parameters the walkers move in the *value* of (default: those
        whose declaration says ``sample_in_value``); the density carries the Jacobian, so
        only the mixing changes.
    log:
        The fit's log (a path or :class:`~hdid.Log`), for the basin check below when the
        fit did not run its limit checks (default: ``fit.source`` when it is a file). A fit
        of a DataFrame has no file: without ``log=`` a check it needs cannot refit, and
        the result's warnings say so (``BASIN NOT CHECKED``).

    Notes
    -----
    Never around a poorer basin (:mod:`~hdid._posterior.basin`): before any sampling, a
    fit whose residual is above ``BASIN_FACTOR`` (1.5) × its noise floor (the quantization floor, or the scatter at rest if larger) goes
    through the fit's limit and restart checks (reused when the fit ran them); if it is
    still above, one line saying that the intervals would describe the wrong basin is
    printed to standard error at once and leads the result's warnings and report
    (``basin`` in the JSON).
    """
    from .basin import basin_check

    if method == "smc":
        return _sample_smc(fit, n_walkers, n_steps, moves, n_particles, seed, progress,
                           sigma_floor, modes, prior, default_prior, log)
    if method != "emcee":
        raise PosteriorError(f"method (--sampler) must be 'smc' or 'emcee', not {method!r}")
    if likelihood not in ("auto", "gaussian"):
        raise PosteriorError(f"likelihood must be 'auto' or 'gaussian', not {likelihood!r} (the "
                             "interval likelihood was retired: docs/decisions/interval-likelihood.md)")
    t0 = time.perf_counter()
    # options that cannot work are refused before anything runs (one line, exit 2)
    walkers_enough(n_walkers, fit.problem.n_unknowns + 1)
    gaussian_prior(fit.problem, prior, default_prior)
    fit, basin = basin_check(fit, log)
    progress = (sys.stderr.isatty() if progress is None else bool(progress)) and sys.stderr.isatty()
    run = _Ensemble.start(fit, n_walkers, seed, sigma_floor, linear_prior, sample_linear,
                          prior, default_prior, modes, moves)
    t_burn = time.perf_counter()
    burn_in = default_burn_in(n_steps) if burn_in is None else int(burn_in)
    n_reset = run.burn_in(burn_in, progress)
    t_burn = time.perf_counter() - t_burn
    done, conv, t_kept, t_diag = run.grow(n_steps, max_steps, chunk, progress)
    post = run.result(done, conv, burn_in, n_reset, seed, t0,
                      {"burn_in": t_burn, "kept_chain": t_kept, "diagnostics": t_diag})
    return finish(post, basin, prior, default_prior, PRIOR_HALF_WIDTH)


def _sample_smc(fit, n_walkers, n_steps, moves, n_particles, seed, progress, sigma_floor,
                modes, prior, default_prior, log):
    """``method="smc"``: emcee's options refused, the basin check, then tempered SMC."""
    from .basin import basin_check
    from .smc import N_PARTICLES, sample_smc

    given = [k for k, v in (("n_walkers", n_walkers), ("n_steps", n_steps), ("moves", moves))
             if v is not None]
    if given:
        raise PosteriorError(
            f"{', '.join(given)} (--steps/--walkers): emcee's options; leave them out with "
            "method='smc' (--sampler smc), or sample with method='emcee' (the default)")
    progress = (sys.stderr.isatty() if progress is None else bool(progress)) and sys.stderr.isatty()
    gaussian_prior(fit.problem, prior, default_prior)  # refused before anything runs
    fit, basin = basin_check(fit, log)
    return finish(sample_smc(fit, n_particles=n_particles or N_PARTICLES, seed=seed,
                              progress=progress, sigma_floor=sigma_floor, modes=modes,
                              prior=prior, default_prior=default_prior), basin,
                  prior, default_prior, PRIOR_HALF_WIDTH)
