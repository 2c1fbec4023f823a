"""The compiled QP kernels: active-set box QP against independent oracles, the QP matrices."""

import itertools

from cbha_inverse.core.inverse.qp import (ActiveSetQP, binding_bounds, polish, qp_matrices,
                                          qp_problem, QPProblem)
import numpy as np
import pytest
from scipy.optimize import lsq_linear


def _box_qp(rng, m, condition=1e3):
    """Return a random normalised SPD box QP whose solution has lower and upper bounds active."""
    q, _ = np.linalg.qr(rng.standard_normal((m, m)))
    eigenvalues = np.geomspace(1.0, 1.0 / condition, m)
    hessian = (q * eigenvalues) @ q.T
    hessian = 0.5 * (hessian + hessian.T)
    hessian /= np.trace(hessian) / m
    gradient = 2.0 * rng.standard_normal(m)
    lower = -rng.uniform(0.1, 1.0, m)
    upper = rng.uniform(0.1, 1.0, m)
    previous = rng.uniform(-1.5, 1.5, m)
    return QPProblem(hessian, gradient, lower, upper, np.ones(m), previous, hessian, gradient)


def _enumerated_solution(problem):
    """
    Return the KKT point of a small box QP by trying all 3^m active sets (the oracle for m ≤ 6).

    For an SPD Hessian exactly one active set gives a point inside the box whose active
    multipliers have the right sign.
    """
    h, g = problem.hessian, problem.gradient
    m = g.size
    found = []
    for state in itertools.product((-1, 0, 1), repeat=m):
        state = np.array(state)
        free = state == 0
        x = np.where(state < 0, problem.lower, problem.upper).astype(float)
        if free.any():
            x[free] = np.linalg.solve(h[np.ix_(free, free)],
                                      -g[free] - h[np.ix_(free, ~free)] @ x[~free])
        grad = h @ x + g
        tolerance = 1e-10
        if (np.all(x >= problem.lower - tolerance) and np.all(x <= problem.upper + tolerance)
                and np.all(grad[state < 0] >= -tolerance)
                and np.all(grad[state > 0] <= tolerance)):
            found.append(x)
    assert found, 'no KKT point'
    for x in found[1:]:
        np.testing.assert_allclose(x, found[0], atol=1e-9)
    return found[0]


def _least_squares_solution(problem):
    """
    Return the box-QP solution from scipy's bounded-variable least squares (an exact method).

    With ``H = L Lᵀ``: ``½ xᵀ H x + gᵀ x = ½ ‖Lᵀ x + L⁻¹ g‖² + const``.
    """
    factor = np.linalg.cholesky(problem.hessian)
    result = lsq_linear(factor.T, -np.linalg.solve(factor, problem.gradient),
                        bounds=(problem.lower, problem.upper), method='bvls', tol=1e-14)
    assert result.success
    return result.x


def test_active_set_matches_enumeration_of_all_active_sets():
    rng = np.random.default_rng(11)
    n_lower = n_upper = 0
    for m in (1, 2, 3, 4, 5, 6):
        for _ in range(6):
            problem = _box_qp(rng, m)
            solution = ActiveSetQP(m).solve(problem)
            assert solution.ok and solution.status == 'solved'
            expected = _enumerated_solution(problem)
            np.testing.assert_allclose(solution.x, expected, rtol=0.0, atol=1e-9)
            n_lower += int(np.sum(expected <= problem.lower + 1e-12))
            n_upper += int(np.sum(expected >= problem.upper - 1e-12))
    assert n_lower > 10 and n_upper > 10


@pytest.mark.parametrize('m', [8, 12, 16, 24])
def test_active_set_matches_bounded_least_squares(m):
    rng = np.random.default_rng(m)
    for _ in range(10):
        problem = _box_qp(rng, m)
        solution = ActiveSetQP(m).solve(problem)
        assert solution.ok and solution.status == 'solved'
        expected = _least_squares_solution(problem)
        assert np.any(expected <= problem.lower) and np.any(expected >= problem.upper)
        np.testing.assert_allclose(solution.x, expected, rtol=0.0, atol=1e-9)


def test_warm_start_gives_the_cold_start_solution():
    rng = np.random.default_rng(3)
    m = 10
    problem = _box_qp(rng, m)
    warm = ActiveSetQP(m)
    first = warm.solve(problem)
    again = warm.solve(problem)
    assert again.ok and again.iterations == 1
    np.testing.assert_allclose(again.x, first.x, rtol=0.0, atol=1e-12)
    # a tracking sequence: the gradient drifts, each solve starts from the previous active set
    for step in range(20):
        gradient = problem.gradient + 0.05 * step * rng.standard_normal(m)
        drifted = QPProblem(problem.hessian, gradient, problem.lower, problem.upper,
                            problem.scale, problem.previous, problem.hessian, gradient)
        warm_solution = warm.solve(drifted)
        cold_solution = ActiveSetQP(m).solve(drifted)
        assert warm_solution.ok and cold_solution.ok
        np.testing.assert_allclose(warm_solution.x, cold_solution.x, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize('hessian', [
    np.diag([1.0, -1.0, 2.0]),
    np.zeros((3, 3)),
    np.full((3, 3), np.nan),
    np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.0], [0.0, 0.0, 1.0]]),
], ids=['indefinite', 'zero', 'nan', 'indefinite_coupled'])
def test_singular_hessian_fails_cleanly(hessian):
    g = np.array([0.3, -0.2, 0.1])
    lower, upper = -np.ones(3), np.ones(3)
    previous = np.array([2.0, -0.5, 0.25])
    problem = QPProblem(hessian, g, lower, upper, np.ones(3), previous, hessian, g)
    solver = ActiveSetQP(3)
    solution = solver.solve(problem)
    assert not solution.ok and solution.status == 'singular'
    np.testing.assert_array_equal(solution.x, np.clip(previous, lower, upper))
    # the warm start was reset: a good problem is solved as from scratch
    good = QPProblem(np.eye(3), g, lower, upper, np.ones(3), previous, np.eye(3), g)
    assert solver.solve(good).iterations == ActiveSetQP(3).solve(good).iterations


def test_iteration_limit_is_reported():
    rng = np.random.default_rng(5)
    problem = _box_qp(rng, 8)
    needed = ActiveSetQP(8).solve(problem).iterations
    assert needed > 1
    solution = ActiveSetQP(8, max_iterations=needed - 1).solve(problem)
    assert not solution.ok and solution.status == 'max_iterations'
    assert solution.iterations == needed - 1
    np.testing.assert_array_equal(solution.x, np.clip(problem.previous, problem.lower,
                                                      problem.upper))


def test_polish_recovers_the_exact_solution():
    rng = np.random.default_rng(8)
    for m in (4, 8, 16):
        problem = _box_qp(rng, m)
        exact = _least_squares_solution(problem)
        # an interior-point-like iterate: the active variables a little inside the box
        approximate = np.clip(exact, problem.lower + 1e-6, problem.upper - 1e-6)
        np.testing.assert_allclose(polish(problem, approximate), exact, rtol=0.0, atol=1e-9)
        interior = 0.5 * (problem.lower + problem.upper)
        assert polish(problem, interior) is interior


def test_binding_bounds_matches_its_definition():
    rng = np.random.default_rng(9)
    for m in (6, 16):
        problem = _box_qp(rng, m)
        x = ActiveSetQP(m).solve(problem).x
        tolerance = 1e-6
        grad = problem.tracking_hessian @ x + problem.tracking_gradient
        expected = (((x <= problem.lower + tolerance) & (grad > tolerance))
                    | ((x >= problem.upper - tolerance) & (grad < -tolerance)))
        assert expected.any()
        np.testing.assert_array_equal(binding_bounds(problem, x), expected)


def _reference_matrices(w_ea, w_aa, scale, energy_weight, proximal_weight):
    """Return (H, T, W) of the module docstring of cbha_inverse.core.inverse.qp (numpy)."""
    m = scale.size
    sigma = np.diag(scale)
    tracking = sigma @ w_ea.T @ w_ea @ sigma
    energy = sigma @ w_aa @ sigma
    s_proximal = np.trace(tracking) / m
    s_energy = np.trace(tracking) / np.trace(energy)
    # objective in x = λ / σ divided by the normalisation s_P
    hessian = (tracking + energy_weight * s_energy * 0.5 * (energy + energy.T)
               + proximal_weight * s_proximal * np.eye(m)) / s_proximal
    return hessian, tracking / s_proximal, w_ea @ sigma / s_proximal


@pytest.mark.parametrize('k, m', [(1, 6), (2, 8), (4, 16)])
def test_qp_matrices_match_the_docstring_formula(k, m):
    rng = np.random.default_rng(k * m)
    w_ea = 1e-3 * rng.standard_normal((3 * k, m))
    a = rng.standard_normal((m, m))
    w_aa = 1e-3 * (a @ a.T / m + np.eye(m) + 0.1 * rng.standard_normal((m, m)))
    scale = rng.uniform(1.0, 10.0, m)
    matrices = qp_matrices(w_ea, w_aa, scale, energy_weight=1e-2, proximal_weight=1e-3)
    hessian, tracking, weighted_w = _reference_matrices(w_ea, w_aa, scale, 1e-2, 1e-3)
    np.testing.assert_allclose(matrices.hessian, hessian, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(matrices.tracking_hessian, tracking, rtol=1e-12, atol=1e-14)
    np.testing.assert_allclose(matrices.weighted_w, weighted_w, rtol=1e-12, atol=1e-14)
    np.testing.assert_array_equal(matrices.hessian, matrices.hessian.T)
    assert matrices.proximal_weight == 1e-3 and matrices.scale is scale
    # a strided W_ea (a column slice, as the controller passes it) gives the same matrices
    padded = np.zeros((3 * k, m + 1))
    padded[:, 1:] = w_ea
    strided = qp_matrices(padded[:, 1:], w_aa, scale, energy_weight=1e-2, proximal_weight=1e-3)
    np.testing.assert_array_equal(strided.hessian, matrices.hessian)
    # without the energy term, and with no tracking (normalisation falls back to 1)
    plain = qp_matrices(w_ea, w_aa, scale, energy_weight=0.0, proximal_weight=1e-3)
    np.testing.assert_allclose(plain.hessian, tracking + 1e-3 * np.eye(m), rtol=1e-12,
                               atol=1e-14)
    blind = qp_matrices(np.zeros_like(w_ea), w_aa, scale, energy_weight=0.0,
                        proximal_weight=1e-3)
    np.testing.assert_array_equal(blind.hessian, 1e-3 * np.eye(m))


def test_qp_problem_matches_the_docstring_formula():
    rng = np.random.default_rng(4)
    k, m = 2, 8
    w_ea = 1e-3 * rng.standard_normal((3 * k, m))
    w_aa = 1e-3 * np.eye(m)
    scale = rng.uniform(1.0, 10.0, m)
    matrices = qp_matrices(w_ea, w_aa, scale, proximal_weight=1e-3)
    delta_free = 0.01 * rng.standard_normal(3 * k)
    previous = rng.uniform(0.0, 10.0, m)
    lower_bounds, upper_bounds = np.zeros(m), np.full(m, 10.0)
    rate = np.full(m, 0.5)
    x_prev = previous / scale
    tracking_gradient = matrices.weighted_w.T @ delta_free
    for rate_limit in (None, rate):
        problem = qp_problem(matrices, delta_free, previous, lower_bounds, upper_bounds,
                             rate_limit=rate_limit)
        lower, upper = lower_bounds / scale, upper_bounds / scale
        if rate_limit is not None:
            lower = np.maximum(lower, x_prev - rate / scale)
            upper = np.minimum(upper, x_prev + rate / scale)
        np.testing.assert_allclose(problem.gradient, tracking_gradient - 1e-3 * x_prev,
                                   rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(problem.tracking_gradient, tracking_gradient, rtol=1e-12,
                                   atol=1e-15)
        np.testing.assert_array_equal(problem.lower, lower)
        np.testing.assert_array_equal(problem.upper, upper)
        np.testing.assert_array_equal(problem.previous, x_prev)
        assert problem.hessian is matrices.hessian
