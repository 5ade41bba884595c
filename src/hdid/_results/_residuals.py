"""Residual views of a fit: where does the model fail, and is what is left white noise?

Everything here starts from a :class:`~hdid.FitResult` and is read-only. The central
object is the *residual frame* (:func:`residual_frame`): one row per logged sample with
the measurement, the model, the model's state (WG angle from the spring zero, velocity,
output-side deflection) and the phase of the motion. On top of it:

* :func:`whiteness` — is the residual of the *moving* samples white and at the
  quantization floor (Ljung–Box on the pooled autocorrelation, RMS vs ``step/√12``)?
* :func:`spectrum` — pooled periodogram of the moving residual with a white-noise band.
* :func:`residual_features` — numbers describing the residual's *structure* (correlation
  with sign(ω), θ, |θ|, ω; energy near rest; rest-point error; a periodic term in θ) that
  point to the missing effect.
* :func:`plot_residuals`, :func:`plot_rest_approach` — figures.

The views live in three modules, re-exported here: the frame (:mod:`hdid._results._residual_frame`),
the whiteness test, spectrum and features (:mod:`hdid._results._whiteness`) and the figures
(:mod:`hdid._results._residual_plots`).

Why only the moving samples are tested: before the release and after the stick the
encoder reads one constant count, so every sample of such a stretch carries the *same*
rounding error — they are one observation repeated, not independent draws (the fit's
weights already count them as one, see :mod:`hdid._simulation._prepare`). Including them would make
any model look strongly autocorrelated.
"""

from __future__ import annotations

from ._residual_frame import (  # noqa: F401
    FINE_PER_SAMPLE, PARTS, PHASES, _parts, fine_times, residual_frame, stick_times,
)
from ._residual_plots import (  # noqa: F401
    MIN_ACF_LAGS, MIN_SPECTRUM_BINS, REST_WINDOW, plot_residuals, plot_rest_approach,
)
from ._whiteness import (  # noqa: F401
    AT_FLOOR_RATIO, WHITE_ALPHA, Spectrum, Whiteness, residual_features, spectrum, whiteness,
)

__all__ = [
    "FINE_PER_SAMPLE", "PARTS", "PHASES", "fine_times", "residual_frame", "stick_times",
    "MIN_ACF_LAGS", "MIN_SPECTRUM_BINS", "REST_WINDOW", "plot_residuals", "plot_rest_approach",
    "AT_FLOOR_RATIO", "WHITE_ALPHA", "Spectrum", "Whiteness", "residual_features", "spectrum",
    "whiteness",
]
