"""
The QP solvers' result fields: status, iterations, ``ok``, warm starts and the fallback value.

:class:`~cbha_inverse.core.inverse.qp.ProxsuiteQP` (proxsuite) must solve each new problem of a
warm-started sequence (only the gradient and the box sent, or a new Hessian), repeat a solved one
without iterations, and keep the previous actuation when it does not converge;
:func:`~cbha_inverse.core.inverse.qp.projected_gauss_seidel` and
:class:`~cbha_inverse.core.inverse.qp.ActiveSetQP` report their sweeps, their budget and their
failure. The active-set solver is the exact reference.
"""

from cbha_inverse.core.inverse.qp import (ActiveSetQP, projected_gauss_seidel, ProxsuiteQP,
                                          QPProblem)
import numpy as np


def _problem(hessian, gradient, lower, upper, previous=None):
    m = len(gradient)
    hessian, gradient = np.asarray(hessian, dtype=float), np.asarray(gradient, dtype=float)
    previous = np.zeros(m) if previous is None else np.asarray(previous, dtype=float)
    return QPProblem(hessian, gradient, np.asarray(lower, dtype=float),
                     np.asarray(upper, dtype=float), np.ones(m), previous, hessian, gradient)


def _exact(problem):
    solution = ActiveSetQP(problem.gradient.size).solve(problem)
    assert solution.ok is True and solution.status == 'solved'
    return solution.x


def test_proxsuite_warm_started_updates_solve_each_new_problem():
    """
    Same Hessian (only g and the box sent), then a new Hessian: each answer is its own QP's.

    The gradients are large, so both bounds of every box are active somewhere: a gradient or a
    bound that was not sent gives a different solution.
    """
    rng = np.random.default_rng(3)
    m = 6
    a = rng.standard_normal((m, m))
    hessian = a @ a.T + np.eye(m)
    signs = np.array([1.0, -1.0] * (m // 2))
    first = _problem(hessian, 50.0 * signs, -np.ones(m), np.ones(m))
    solver = ProxsuiteQP(m)
    b = rng.standard_normal((m, m))
    problems = [
        (first, False),
        (first._replace(gradient=-50.0 * signs), True),
        (first._replace(gradient=-50.0 * signs, lower=-0.3 * np.ones(m)), True),
        (first._replace(gradient=-50.0 * signs, lower=-0.3 * np.ones(m),
                        upper=0.2 * np.ones(m)), True),
        (first._replace(hessian=b @ b.T + 0.1 * np.eye(m), gradient=40.0 * signs,
                        lower=-0.7 * np.ones(m), upper=0.6 * np.ones(m)), False),
        (first._replace(hessian=hessian, gradient=-40.0 * signs, lower=-0.4 * np.ones(m),
                        upper=0.5 * np.ones(m)), False),
    ]
    previous = None
    for problem, same_hessian in problems:
        solution = solver.solve(problem, same_hessian=same_hessian)
        assert solution.ok is True and solution.status == 'solved'
        assert type(solution.iterations) is int and solution.iterations >= 0
        exact = _exact(problem)
        np.testing.assert_allclose(solution.x, exact, atol=1e-8)
        assert np.any(exact == problem.lower) and np.any(exact == problem.upper)
        assert previous is None or not np.allclose(exact, previous)
        previous = exact


def test_proxsuite_warm_start_repeats_a_solved_problem_without_iterations():
    rng = np.random.default_rng(6)
    m = 6
    a = rng.standard_normal((m, m))
    problem = _problem(a @ a.T + np.eye(m), 5.0 * rng.standard_normal(m), -np.ones(m),
                       np.ones(m))
    solver = ProxsuiteQP(m)
    cold = solver.solve(problem)
    warm = solver.solve(problem, same_hessian=True)
    assert cold.iterations > 0 and warm.iterations == 0
    np.testing.assert_allclose(warm.x, cold.x, atol=1e-12)
    solver.reset()
    assert solver.solve(problem).iterations == cold.iterations


def test_proxsuite_not_converged_keeps_the_previous_actuation():
    rng = np.random.default_rng(4)
    m = 6
    q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    hessian = (q * np.geomspace(1.0, 1e-6, m)) @ q.T
    problem = _problem(hessian, rng.standard_normal(m), -np.ones(m), np.ones(m),
                       previous=rng.uniform(-2.0, 2.0, m))
    solution = ProxsuiteQP(m, max_iterations=1).solve(problem)
    assert solution.status == 'max_iterations' and solution.ok is False
    np.testing.assert_array_equal(solution.x, np.clip(problem.previous, -1.0, 1.0))
    # and the next solve starts afresh (init again) and succeeds
    again = ProxsuiteQP(m)
    assert again.solve(problem).ok is True


def test_projected_gauss_seidel_statuses_start_and_sweeps():
    # a diagonal Hessian: one sweep is exact, the second sees no change and stops
    diagonal = _problem(np.diag([2.0, 4.0]), [-1.0, 8.0], [-1.0, -1.0], [1.0, 1.0])
    solution = projected_gauss_seidel(diagonal)
    assert (solution.status, solution.iterations, solution.ok) == ('converged', 2, True)
    np.testing.assert_array_equal(solution.x, [0.5, -1.0])
    coupled = _problem([[2.0, 1.9], [1.9, 2.0]], [1.0, -1.0], [-9.0, -9.0], [9.0, 9.0],
                       previous=[5.0, 5.0])
    stopped = projected_gauss_seidel(coupled, max_iterations=3)
    assert (stopped.status, stopped.iterations, stopped.ok) == ('max_iterations', 3, False)
    assert np.all(np.isfinite(stopped.x))
    # the start: from x0 (clipped into the box), not from previous
    one_sweep = projected_gauss_seidel(coupled, x0=np.array([100.0, 0.0]), max_iterations=1)
    x_first = -(1.0 + 1.9 * 0.0) / 2.0 + 0.0 * 9.0
    x_second = -(-1.0 + 1.9 * x_first) / 2.0
    np.testing.assert_allclose(one_sweep.x, [x_first, x_second], atol=1e-15)
    from_previous = projected_gauss_seidel(coupled, max_iterations=1)
    np.testing.assert_allclose(from_previous.x[0], -(1.0 + 1.9 * 5.0) / 2.0, atol=1e-15)
    # a start outside the box is clipped into it first (both sides)
    outside = coupled._replace(lower=np.array([-1.0, 2.0]), upper=np.array([1.0, 3.0]),
                               previous=np.array([-7.0, 7.0]))
    clipped_sweep = projected_gauss_seidel(outside, max_iterations=1).x
    x_first = min(max(-1.0 - (2.0 * -1.0 + 1.9 * 3.0 + 1.0) / 2.0, -1.0), 1.0)
    x_second = min(max(3.0 - (1.9 * x_first + 2.0 * 3.0 - 1.0) / 2.0, 2.0), 3.0)
    np.testing.assert_allclose(clipped_sweep, [x_first, x_second], atol=1e-15)
    # a step of exactly 1 is taken like any other
    unit = projected_gauss_seidel(_problem([[1.0]], [-1.0], [-5.0], [5.0]))
    assert unit.x.tolist() == [1.0] and unit.ok


def test_active_set_iteration_budget_and_failure_flag():
    assert ActiveSetQP(5).max_iterations == 30 and ActiveSetQP(5, 7).max_iterations == 7
    rng = np.random.default_rng(5)
    m = 8
    a = rng.standard_normal((m, m))
    problem = _problem(a @ a.T + 1e-3 * np.eye(m), 10.0 * rng.standard_normal(m),
                       -np.ones(m) * 0.01, np.ones(m) * 0.01, previous=np.full(m, 3.0))
    solution = ActiveSetQP(m, max_iterations=0).solve(problem)
    assert solution.ok is False and solution.status == 'max_iterations'
    np.testing.assert_array_equal(solution.x, np.full(m, 0.01))
