"""The posterior's own error: a request it cannot sample, said in one line.

:class:`PosteriorError` is an :class:`~hdid.HdidError` (the command line prints it as one
line, exit 2, no traceback) and a :class:`ValueError` (what these errors were before, so
code that caught that still does). Each message names the Python argument and the
command-line flag, e.g. ``n_walkers (--walkers) = 4: ...``.
"""

from __future__ import annotations

import numpy as np

from .._errors import HdidError, _one_line


class PosteriorError(HdidError, ValueError):
    """A posterior that cannot be sampled as asked (bad option, no start of positive
    density, a numerical failure of the sampler); ``str(err)`` is one line."""

    def __init__(self, message: str):
        super().__init__(_one_line(message))


def one_line_failures(sampler):
    """``sampler`` with its numerical failures (a singular covariance of a mode or of the
    adapted proposal, a floating-point error) raised as one-line :class:`PosteriorError`
    naming the log and what to try; every other error passes unchanged."""
    import functools

    @functools.wraps(sampler)
    def wrapped(fit, *args, **kwargs):
        try:
            return sampler(fit, *args, **kwargs)
        except (np.linalg.LinAlgError, FloatingPointError, OverflowError) as exc:
            raise PosteriorError(
                f"{getattr(fit, 'source', '<fit>')}: the posterior sampler failed numerically "
                f"({type(exc).__name__}: {exc}); read the fit's warnings (a parameter the log "
                "does not determine: fix it, --fix / fix=), or try method='smc' (--sampler smc) "
                "or another seed (--seed / seed=)") from exc

    return wrapped


def walkers_enough(W: int | None, D: int) -> None:
    """Refuse fewer than ``2·D`` walkers (emcee's red-blue moves need them)."""
    if W is not None and W < 2 * D:
        raise PosteriorError(f"n_walkers (--walkers) = {W}: emcee needs at least 2 × {D} = "
                             f"{2 * D} walkers for this fit; raise n_walkers (--walkers) to "
                             f"{2 * D} or more, or leave it out (default max(32, 2·D))")
