"""Posterior sampling with emcee around a least-squares fit (``hdid.sample_posterior``).

One job per module:

- :mod:`.density` — the log-posterior (likelihood, priors, sampled coordinates), batched;
- :mod:`.modes` — local optima near the fit and their Laplace masses (where walkers start);
- :mod:`.limits` — the vanishing ends of value-flat parameters: limit fits, the warning;
- :mod:`.moves` — emcee moves, the t-mixture independence proposal, the start;
- :mod:`.diagnostics` — arviz convergence (R-hat, ESS), τ, posterior/prior widths;
- :mod:`.driver` — :func:`sample_posterior`;
- :mod:`.result` — :class:`PosteriorResult`.
"""

from .density import (
    PRIOR_HALF_WIDTH,
    SIGMA_BOUNDS,
    LogPosterior,
    _derived_batch,
    _predict_batch,
    derived_np,
    residual_autocorrelation,
)
from .diagnostics import (
    ESS_MIN,
    RHAT_MAX,
    TAU_MULTIPLE,
    Convergence,
    convergence,
    tau_pooled,
    width_ratios,
)
from .driver import BURN_IN_STAGES, MIN_TAU_MULTIPLE, sample_posterior
from .modes import _BOX_PRECISION, Mode, _laplace, _rj, find_modes
from .moves import START_SCALE, MixtureProposal, _mode_start, _reset_outliers, default_moves
from .result import PosteriorResult

__all__ = [
    "BURN_IN_STAGES", "Convergence", "ESS_MIN", "LogPosterior",
    "MIN_TAU_MULTIPLE", "MixtureProposal", "Mode", "PRIOR_HALF_WIDTH", "PosteriorResult",
    "RHAT_MAX", "SIGMA_BOUNDS", "START_SCALE", "TAU_MULTIPLE", "convergence",
    "default_moves", "derived_np", "find_modes", "residual_autocorrelation",
    "sample_posterior", "tau_pooled", "width_ratios",
]
