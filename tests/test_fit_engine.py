"""The engine of :func:`hdid.fit` (issue 37): every start, limit fit and restart runs one
start at a time through the one-lane Levenberg–Marquardt program of the model's structure
(``hdid._fitting._one_lane``), where the stick-exact simulator's event branch stays a
branch; the vmapped form runs it as a select at every substep of every lane."""

from __future__ import annotations

import numpy as np
import pytest

import hdid
from hdid._fitting import _fit, _limits, _lm, _one_lane
from hdid._fitting._lm import LMState

from synthetic import ROOT

PAPER = ROOT / "data" / "synthetic" / "csf8_paper.csv"


class _Quadratic:
    """A stand-in problem for the schedule: only the shapes :func:`_one_lane._local_fits`
    reads (``times``, ``n_physical``)."""

    times = np.zeros((1, 3))
    n_physical = 2


def _counting_solve(seen):
    """A one-lane "program": each call halves the distance to the origin (cost |u|²) and
    reports its lane converged; it records every row it was given."""

    def solve(problem, U, active, k, state):
        seen.append(np.asarray(U)[0].copy())
        U2 = np.asarray(U) * 0.5
        cost = np.sum(U2**2, axis=1)
        st = LMState(*(np.asarray(f) for f in state))
        done = np.ones(len(U2), dtype=bool)
        return U2, cost, done, np.full(len(U2), int(k)), st._replace(
            have=np.ones(len(U2), bool), fresh=np.zeros(len(U2), bool))

    return solve


def test_identical_starts_are_computed_once_with_identical_results():
    # rows 0 and 2 are the same start (as the padding copies of a limit's short group):
    # a one-lane program gives them identical results, so one call serves both
    U0 = np.array([[1.0, 2.0], [3.0, -1.0], [1.0, 2.0]])
    seen = []
    U, costs, ok, steps, _ = _one_lane._local_fits(_Quadratic(), U0, 5,
                                                   solve=_counting_solve(seen))
    # phase 1 and phase 2 (all three continue, then converge): two calls each, not three
    assert len(seen) == 4
    np.testing.assert_array_equal(U[0], U[2])
    assert costs[0] == costs[2] and steps[0] == steps[2] and ok[0] == ok[2]


def test_groups_keep_a_schedule_each():
    # ``group``: rows scheduled ``group`` at a time, each group padded with copies of its
    # first row — the same as running each padded group alone
    U0 = np.arange(10.0).reshape(5, 2) + 1.0
    a = _one_lane._local_fits(_Quadratic(), U0, 5, solve=_counting_solve([]), group=3)
    pad = np.concatenate([U0[3:], U0[3:4]])
    b0 = _one_lane._local_fits(_Quadratic(), U0[:3], 5, solve=_counting_solve([]))
    b1 = _one_lane._local_fits(_Quadratic(), pad, 5, solve=_counting_solve([]))
    np.testing.assert_array_equal(a[0][:3], b0[0])
    np.testing.assert_array_equal(a[0][3:], b1[0][:2])


@pytest.fixture(scope="module")
def paper_setup():
    return _fit._setup(hdid.read_log(PAPER))


def test_limit_starts_are_set_on_whole_columns_as_row_by_row(paper_setup):
    # the limit's starts: every grid row held at the limit (the Coulomb limit also takes
    # tau_s from the row's own tau_c); one NumPy pass must equal the former row-by-row form
    s = paper_setup
    U, _ = _fit._grid_candidates(s.problem, s.prep, s.model, False)
    from hdid._fitting._starts import log_scales

    scales = log_scales(s.prep, s.model, np.asarray(s.problem.offset0))
    values = s.problem.values_np(U[0])
    for limit in _limits.limits_of(s.model, s.fixed):
        pins = limit.pins(values, scales)
        rows = _limits.with_values_rows(s.problem, s.model, U,
                                        lambda v: limit.start(v, scales), pins)
        one = np.stack([_limits.with_values(s.problem, s.model, u,
                                            {**limit.start(s.problem.values_np(u), scales),
                                             **pins})
                        for u in U])
        # the same transforms on the same numbers: equal to the last bit
        np.testing.assert_array_equal(rows, one)


def test_fit_never_runs_the_vmapped_starts(monkeypatch):
    # the vmapped multi-start program (a select of the event branch per substep per lane)
    # is not what hdid.fit runs: its starts and its limit checks go one lane at a time
    def refuse(*a, **k):
        raise AssertionError("hdid.fit ran the vmapped multi-start program")

    monkeypatch.setattr(_lm, "_solve_lanes", refuse)
    r = hdid.fit(PAPER, nested=True)
    assert np.isfinite(r.rms_residual_rad) and r.limits


def test_solve_fresh_one_lane_is_the_fits_program(paper_setup):
    # the posterior's drop-in: a fresh LM per row through the fit's one-lane program; with
    # no iterations it returns each row's cost, which must be the χ² the grid computes (the
    # same residuals, summed in another program: agreement to rounding, 1e-9 relative)
    from hdid._fitting._starts import grid_costs

    s = paper_setup
    grid, _ = _fit._grid_candidates(s.problem, s.prep, s.model, False)
    U = grid[:3]
    got_U, cost, done, k = _one_lane.solve_fresh(s.problem, U, [True, False, True], 0)
    # (the whole grid: the program hdid.fit already runs)
    np.testing.assert_allclose(cost[[0, 2]], grid_costs(s.problem, grid)[[0, 2]], rtol=1e-9)
    assert cost[1] == np.inf  # an inactive row is not run
    np.testing.assert_array_equal(got_U, U)
    assert not done.any() and k.tolist() == [1, 0, 1]
    # a few iterations lower each active row's χ² (LM accepts only decreasing steps)
    _, cost5, _, _ = _one_lane.solve_fresh(s.problem, U, [True, True, True], 5)
    assert np.all(cost5 <= cost)


def test_a_verdict_stops_starts_a_clearly_worse_basin_above_its_line():
    # A limit at the floor only asks whether its optimum lies below a line (the fit's cost
    # plus the limit's likelihood-ratio bound). At a phase-2 check, starts DROP_DCHI2 (50,
    # ~7 standard errors) or more above that line stop, as starts that far above the best
    # do; a start within 50 of it goes on. Costs fed by hand: no fit.
    def schedule(line, phase2_costs):
        s = _lm._Schedule(4, 300, verdict_line=line)
        s.next()
        s.update(np.array([900.0, 950.0, 980.0, 990.0]), np.zeros(4, bool), np.full(4, 12))
        # the end of phase 1 keeps the CONTINUED_STARTS best whatever the line (a start 50
        # above after 12 iterations can still end below it)
        assert s.active.sum() == _lm.CONTINUED_STARTS
        s.next()
        s.update(np.asarray(phase2_costs, float), np.zeros(4, bool), np.full(4, 25))
        return s.next()

    far = [400.0, 420.0, 440.0, np.inf]  # every continued start > 50 above a line at 20
    assert schedule(np.inf, far) is not None  # no line: they go on to convergence
    assert schedule(20.0, far) is None  # the verdict is settled: the limit stops
    near = [60.0, 420.0, 440.0, np.inf]  # one start within 50 of the line: it alone goes on
    active, _, _ = schedule(20.0, near)
    assert active.tolist() == [True, False, False, False]
