"""The weights a search for the optimum uses (grid, local fits, limit checks): a stuck tail
counted as one observation where the readings lie on no grid (:func:`search_weight`)."""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from ._tails import oscillates

if TYPE_CHECKING:
    from ._prepare import Prepared

#: Samples right after the last motion that keep full weight (they time the stop).
FULL_WEIGHT_TAIL = 3


def search_weight(prep: Prepared) -> np.ndarray:
    """Observation weights for *searching* an optimum (grid, local fits, limit checks);
    ``prep.weight`` itself where the readings lie on a grid (the same object).

    A stuck tail's readings all measure one number, the rest point, and where the gear
    stops depends discontinuously on the parameters (one more or one fewer stop, a stop a
    few samples earlier): with independent noise each of its ``n`` readings keeps full
    weight in the likelihood, so the rest point's error enters the cost ``n`` times and
    turns it into a staircase of local minima around the optimum (a 127 Hz plant logged
    at 1 kHz with noise, ~400 tail samples a run: fits from every start and from the
    truth ended 35× the noise, the same log on an encoder grid at the floor). The search
    therefore weights a stuck tail — and a run that never moves — as one observation, as
    an encoder log does (:func:`prepare`); the fit then polishes its optimum with
    ``prep.weight``, the likelihood (:func:`hdid.fit`)."""
    if prep.quantized or prep.tail_start is None:
        return prep.weight
    w = np.array(prep.weight, dtype=float)
    stopped = (np.ones(prep.n_runs, dtype=bool) if prep.ends_moving is None
               else ~np.asarray(prep.ends_moving, dtype=bool))
    for i in range(prep.n_runs):
        n = int(prep.lengths[i])
        if prep.still is not None and prep.still[i]:  # one reading, one observation
            w[i, :n] = 1.0 / math.sqrt(n)
            continue
        free_tail = min(int(prep.tail_start[i]) + FULL_WEIGHT_TAIL, n)
        # (a tail that goes on swinging at the log's frequency is a viscous ring-down under
        # the noise, not a stop: full weight, :func:`._tails.oscillates`)
        if stopped[i] and n > free_tail and not oscillates(
                prep.times[i, prep.tail_start[i]:n], prep.theta[i, prep.tail_start[i]:n],
                prep.frequency_hz):
            w[i, free_tail:n] = 1.0 / math.sqrt(n - free_tail)
    return w
