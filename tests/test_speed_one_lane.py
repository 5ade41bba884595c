"""The one-lane driver's host work per call (issue 37): a start's Levenberg–Marquardt state
goes from one program call to the next as the program returned it — its Jacobian (rows ×
unknowns) is not copied to the host and back between calls — with the results of the same
calls."""

from __future__ import annotations

import numpy as np

from hdid._fitting import _one_lane
from hdid._fitting._lm import LMState


class _Quadratic:
    """A stand-in problem: only the shapes the driver reads."""

    times = np.zeros((1, 3))
    n_physical = 2


def _halving_solve(given, returned):
    """A one-lane "program": halves the distance to the origin (cost |u|²) and reports its
    lane converged; records the Jacobian object each call got and the one it returned."""

    def solve(problem, U, active, k, state):
        given.append(state.J)
        J = np.asarray(state.J) + 1.0
        returned.append(J)
        U2 = np.asarray(U) * 0.5
        st = LMState(*state)._replace(J=J, have=np.ones(1, bool), fresh=np.zeros(1, bool))
        return U2, np.sum(U2**2, axis=1), np.ones(1, bool), np.full(1, int(k)), st

    return solve


def test_a_start_gets_back_the_state_its_last_call_returned():
    given, returned = [], []
    U0 = np.array([[1.0, 2.0], [3.0, -1.0]])
    U, costs, ok, steps, _ = _one_lane._local_fits(_Quadratic(), U0, 60,
                                                   solve=_halving_solve(given, returned))
    # phase 1 (both starts), phase 2 (both, converged): 4 calls; the second call of each
    # start gets the very array its first returned, not a copy
    assert len(given) == 4
    assert all(np.all(J == 0.0) for J in given[:2])  # the empty state
    assert given[2] is returned[0] and given[3] is returned[1]
    np.testing.assert_array_equal(U, U0 * 0.25)
    np.testing.assert_array_equal(costs, np.sum((U0 * 0.25) ** 2, axis=1))
    assert ok.all() and (steps == 12 + 25).all()
