"""
The compiled QP with slackened rows (``rows_qp``) against proxsuite's ``RowsQP`` and its KKT.

The problem: ``min ½ xᵀ H x + gᵀ x + ½ p Σ max(0, -(A x + b))²`` over a box, the slack of
``RowsQP`` eliminated (``t = max(0, -(A x + b)) / ℓ``, ``p = 1 / ℓ²``). Its KKT conditions are
checked directly on the penalised gradient, independently of the solver's row states.
"""

from cbha_inverse.core._kernels.qp import (MAX_ITERATIONS, rows_qp, ROWS_UNSETTLED, SINGULAR,
                                           SOLVED)
from cbha_inverse.core.inverse.qp import QPProblem, RowsQP
from hypothesis import given, HealthCheck, settings, strategies as st
import numpy as np
import pytest

PROPERTY = settings(max_examples=60, deadline=None, derandomize=True,
                    suppress_health_check=[HealthCheck.too_slow])


def _problem(rng, m, r, penalty):
    """
    Return a random normalised box QP with ``r`` rows in metres, as the obstacle rows are.

    The rows move by centimetres over the box (``A`` ~ 0.05 m per unit of ``x``); their
    constants lie from 15 cm violated to 5 cm clear, so some rows are held, some cannot hold
    within the box (slack), some are inactive.
    """
    q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    hessian = (q * np.geomspace(1.0, 1e-3, m)) @ q.T
    hessian = 0.5 * (hessian + hessian.T)
    hessian /= np.trace(hessian) / m
    gradient = 2.0 * rng.standard_normal(m)
    lower, upper = -rng.uniform(0.1, 1.0, m), rng.uniform(0.1, 1.0, m)
    previous = np.clip(rng.uniform(-1.5, 1.5, m), lower, upper)
    problem = QPProblem(hessian, gradient, lower, upper, np.ones(m), previous, hessian,
                        gradient)
    rows = 0.05 * rng.standard_normal((r, m))
    constant = rng.uniform(-0.15, 0.05, r)
    return problem, rows, constant, penalty


def _solve(problem, rows, constant, penalty, max_rounds=50, state=None, row_on=None):
    """Run the compiled solver cold (or from the given warm start)."""
    m, r = problem.gradient.size, constant.size
    state = np.zeros(m, dtype=np.int8) if state is None else state
    row_on = np.zeros(r, dtype=np.bool_) if row_on is None else row_on
    return rows_qp(problem.hessian, problem.gradient, problem.lower, problem.upper, rows,
                   constant, penalty, state, row_on, 4 * m + 10, max_rounds)


def _kkt_violation(problem, rows, constant, penalty, x):
    """
    Return how far ``x`` is from the KKT point of the penalised problem (relative, 0 at it).

    The gradient ``H x + g + p Aᵀ min(0, A x + b)`` must vanish on the free variables, be
    >= 0 at a lower bound and <= 0 at an upper one; ``x`` must lie in the box.
    """
    values = rows @ x + constant
    pull = penalty * rows.T @ np.minimum(values, 0.0)
    gradient = problem.hessian @ x + problem.gradient + pull
    size = 1.0 + np.abs(problem.gradient).max() + penalty * np.abs(rows).max() * np.abs(
        values).max()
    at_lower = x <= problem.lower + 1e-12
    at_upper = x >= problem.upper - 1e-12
    residual = np.where(at_lower, np.minimum(gradient, 0.0),
                        np.where(at_upper, np.maximum(gradient, 0.0), gradient))
    outside = np.maximum(problem.lower - x, 0.0) + np.maximum(x - problem.upper, 0.0)
    return max(np.abs(residual).max() / size, outside.max())


@PROPERTY
@given(st.integers(2, 10), st.integers(1, 6), st.sampled_from([1e2, 1e4, 1e6]),
       st.integers(0, 2 ** 32 - 1))
def test_rows_qp_matches_proxsuite_and_its_kkt_conditions(m, r, penalty, seed):
    """The solution and the slack agree with proxsuite's; the KKT conditions hold to round-off."""
    problem, rows, constant, penalty = _problem(np.random.default_rng(seed), m, r, penalty)
    x, status, _, _, _, row_on, values = _solve(problem, rows, constant, penalty)
    assert status == SOLVED
    assert _kkt_violation(problem, rows, constant, penalty, x) < 1e-11
    np.testing.assert_allclose(values, rows @ x + constant, rtol=0.0, atol=1e-15)
    # the rows' states are the signs of their values
    assert np.all(values[row_on] <= 1e-14) and np.all(values[~row_on] >= -1e-14)
    reference, slack = RowsQP(m, eps_abs=1e-12).solve(problem, rows, constant, 1.0, penalty)
    assert reference.ok
    # proxsuite stops at its tolerance: compare at its accuracy
    np.testing.assert_allclose(x, reference.x, rtol=0.0, atol=2e-5)
    np.testing.assert_allclose(np.maximum(-values, 0.0), slack, rtol=0.0, atol=2e-6)


def test_infeasible_rows_and_rows_on_bounds_are_covered():
    """Over seeded problems: held rows with slack, rows that hold, variables at both bounds."""
    rng = np.random.default_rng(2)
    slack_rows = clear_rows = at_bounds = 0
    for _ in range(40):
        problem, rows, constant, penalty = _problem(rng, 6, 4, 1e6)
        x, status, _, _, _, row_on, values = _solve(problem, rows, constant, penalty)
        assert status == SOLVED
        assert _kkt_violation(problem, rows, constant, penalty, x) < 1e-11
        reference, slack = RowsQP(6, eps_abs=1e-12).solve(
            problem, rows, constant, 1.0, penalty)
        np.testing.assert_allclose(x, reference.x, rtol=0.0, atol=2e-5)
        # a row that cannot hold in the box: its slack is far above the tracking pull's (1e-6 m)
        slack_rows += int(np.sum(slack > 1e-4))
        clear_rows += int(np.sum(values > 1e-4))
        at_bounds += int(np.sum((x <= problem.lower) | (x >= problem.upper)))
        if np.any(values > 1e-4):
            # the rows that hold: the problem without them has the same solution
            kept = values <= 1e-4
            without = _solve(problem, rows[kept], constant[kept], penalty)[0]
            np.testing.assert_allclose(without, x, rtol=0.0, atol=1e-12)
    assert slack_rows > 10 and clear_rows > 10 and at_bounds > 40


@pytest.mark.parametrize('mutation', ['wrong_sign', 'dropped_row'])
def test_a_wrong_row_sign_or_a_dropped_row_fails_the_checks(mutation):
    """The checks above see a row solved with its sign flipped or left out."""
    rng = np.random.default_rng(7)
    caught = 0
    for _ in range(10):
        problem, rows, constant, penalty = _problem(rng, 6, 4, 1e6)
        x = _solve(problem, rows, constant, penalty)[0]
        if mutation == 'wrong_sign':
            mutated = _solve(problem, -rows, -constant, penalty)[0]
        else:
            mutated = _solve(problem, rows[1:], constant[1:], penalty)[0]
        if not np.allclose(mutated, x, rtol=0.0, atol=1e-9):
            assert _kkt_violation(problem, rows, constant, penalty, mutated) > 1e-6
            caught += 1
    assert caught >= 5


def test_warm_start_gives_the_cold_solution_in_one_round():
    rng = np.random.default_rng(4)
    problem, rows, constant, penalty = _problem(rng, 8, 5, 1e6)
    x, status, _, rounds, state, row_on, _ = _solve(problem, rows, constant, penalty)
    assert status == SOLVED and rounds > 1 and row_on.any()
    again = _solve(problem, rows, constant, penalty, state=state, row_on=row_on)
    assert again[1] == SOLVED and again[2] == 1 and again[3] == 1
    np.testing.assert_allclose(again[0], x, rtol=0.0, atol=1e-13)


def test_failures_are_reported():
    """Too few rounds, too few box iterations, an indefinite Hessian: a failure code."""
    rng = np.random.default_rng(4)
    problem, rows, constant, penalty = _problem(rng, 8, 5, 1e6)
    rounds = _solve(problem, rows, constant, penalty)[3]
    assert _solve(problem, rows, constant, penalty, max_rounds=rounds - 1)[1] == ROWS_UNSETTLED
    m, r = 8, 5
    status = rows_qp(problem.hessian, problem.gradient, problem.lower, problem.upper, rows,
                     constant, penalty, np.zeros(m, dtype=np.int8), np.zeros(r, dtype=np.bool_),
                     1, 10)[1]
    assert status == MAX_ITERATIONS
    indefinite = QPProblem(-problem.hessian, *problem[1:])
    assert _solve(indefinite, rows, constant, penalty)[1] == SINGULAR
