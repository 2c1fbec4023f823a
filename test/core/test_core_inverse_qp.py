"""The actuation QP (proxsuite and projected Gauss-Seidel) and the closed-loop target corrector."""

from typing import NamedTuple

from cbha_inverse.core.inverse.correction import MIN_BLOCKED_GAP
from cbha_inverse.core.inverse.qp import (ActiveSetQP, binding_bounds, projected_gauss_seidel,
                                          ProxsuiteQP, qp_matrices, qp_problem)
from cbha_inverse.core.inverse.solver import TargetCorrector
import numpy as np
import pytest


class Projection(NamedTuple):
    """The projected mechanics of a test problem (paper eq. 11-12)."""

    w_ea: np.ndarray
    w_aa: np.ndarray
    delta_free: np.ndarray
    solved: object


def actuation_qp(projection, previous, lower_bounds, upper_bounds, scale, rate_limit=None):
    """Build the tick's QP (default weights) from a projection, as the solver does."""
    matrices = qp_matrices(projection.w_ea, projection.w_aa, scale)
    return qp_problem(matrices, projection.delta_free, previous, lower_bounds, upper_bounds,
                      rate_limit=rate_limit)


def _problem(rng, k=3, m=8, gap=0.01, previous=None, rate=None):
    """Return a random projected problem with a redundant actuation (m > 3k possible)."""
    w_ea = 1e-3 * rng.standard_normal((3 * k, m))
    a = rng.standard_normal((m, m))
    w_aa = 1e-3 * (a @ a.T / m + np.eye(m))
    projection = Projection(w_ea, w_aa, gap * rng.standard_normal(3 * k), None)
    previous = np.zeros(m) if previous is None else previous
    return actuation_qp(projection, previous, np.zeros(m), np.full(m, 10.0), np.full(m, 10.0),
                        rate_limit=rate), projection


def test_proxsuite_and_gauss_seidel_agree():
    rng = np.random.default_rng(0)
    qp = ProxsuiteQP(8)
    for _ in range(5):
        problem, _ = _problem(rng)
        a = qp.solve(problem)
        b = projected_gauss_seidel(problem, max_iterations=20000, tolerance=1e-13)
        assert a.ok and a.status == 'solved'
        assert b.ok and b.status == 'converged'
        obj = [0.5 * x @ problem.hessian @ x + problem.gradient @ x for x in (a.x, b.x)]
        assert obj[0] == pytest.approx(obj[1], abs=1e-9 * max(1.0, abs(obj[1])))
        np.testing.assert_allclose(a.x, b.x, atol=1e-4)
        assert np.all(a.x >= problem.lower) and np.all(a.x <= problem.upper)


def test_reachable_problem_is_solved_exactly_without_saturation():
    rng = np.random.default_rng(1)
    m = 8
    w_ea = 1e-3 * rng.standard_normal((3, m))
    lam = rng.uniform(2.0, 8.0, m)
    projection = Projection(w_ea, 1e-3 * np.eye(m), -w_ea @ lam, None)
    problem = actuation_qp(projection, lam, np.zeros(m), np.full(m, 10.0), np.full(m, 10.0))
    solution = ProxsuiteQP(m).solve(problem)
    x = solution.x * problem.scale
    assert np.linalg.norm(w_ea @ x + projection.delta_free) < 1e-8
    assert not binding_bounds(problem, solution.x).any()


def test_unreachable_target_saturates_finitely():
    rng = np.random.default_rng(2)
    problem, projection = _problem(rng, gap=100.0)
    solution = ProxsuiteQP(8).solve(problem)
    assert solution.ok
    assert np.all(np.isfinite(solution.x))
    assert np.all(solution.x >= problem.lower) and np.all(solution.x <= problem.upper)
    assert binding_bounds(problem, solution.x).any()


def test_rate_limit_bounds_the_change():
    rng = np.random.default_rng(3)
    previous = np.full(8, 5.0)
    problem, _ = _problem(rng, gap=1.0, previous=previous, rate=np.full(8, 0.5))
    x = ProxsuiteQP(8).solve(problem).x * problem.scale
    assert np.all(np.abs(x - previous) <= 0.5 + 1e-12)


def test_redundant_qp_is_deterministic_and_unique():
    """
    8 actuators for 3 tracked coordinates: the regularised QP has one minimiser.

    Three different methods reach it: proxsuite, the exact active set and projected Gauss-Seidel
    started from three different corners of the box.
    """
    rng = np.random.default_rng(4)
    problem, _ = _problem(rng, k=1, m=8)
    assert np.linalg.eigvalsh(problem.hessian).min() > 0.0
    first = ProxsuiteQP(8).solve(problem).x
    second = ProxsuiteQP(8).solve(problem).x
    np.testing.assert_array_equal(first, second)
    exact = ActiveSetQP(8).solve(problem)
    assert exact.ok
    np.testing.assert_allclose(first, exact.x, atol=1e-6)
    for start in (problem.lower, problem.upper, 0.5 * (problem.lower + problem.upper)):
        sweeps = projected_gauss_seidel(problem, x0=start, max_iterations=200000,
                                        tolerance=1e-14)
        assert sweeps.ok
        np.testing.assert_allclose(sweeps.x, exact.x, atol=1e-6)


def test_target_corrector_integrates_clamps_and_stops_winding_up():
    corr = TargetCorrector(1, gain=0.5, max_correction=0.01)
    target = np.array([[0.1, 0.0, 0.0]])
    out = corr.update(target, target - [[0.0, 0.002, 0.0]])
    np.testing.assert_allclose(out, [[0.1, 0.001, 0.0]])
    for _ in range(50):
        out = corr.update(target, target - [[0.0, 0.004, 0.0]])
    assert np.linalg.norm(corr.correction) == pytest.approx(0.01)
    corr.reset()
    corr.update(target, target - [[0.0, 0.002, 0.0]])
    held = corr.correction.copy()
    corr.update(target, target - [[0.0, 0.002, 0.0]], saturated=True)
    np.testing.assert_array_equal(corr.correction, held)
    corr.update(target, target + [[0.0, 0.002, 0.0]], saturated=True)
    assert np.linalg.norm(corr.correction) < np.linalg.norm(held)
    corr.update(target, [[np.nan] * 3])
    assert np.all(np.isfinite(corr.correction))
    np.testing.assert_array_equal(TargetCorrector(1, gain=0.0).update(target, target + 1), target)


def test_target_corrector_drops_only_the_outward_part_along_a_predicted_gap():
    corr = TargetCorrector(2, gain=0.5, max_correction=0.01)
    target = np.array([[0.1, 0.0, 0.0], [0.2, 0.0, 0.0]])
    gap = np.array([[0.0, 0.005, 0.0], [0.0, MIN_BLOCKED_GAP / 2, 0.0]])
    # effector 0: the reach blocks +y, the x part integrates although |c| grows;
    # effector 1: its gap is too short to name a direction, conditional integration holds it
    corr.update(target, target - [[0.002, 0.004, 0.0], [0.002, 0.004, 0.0]], saturated=True,
                predicted_gap=gap)
    np.testing.assert_allclose(corr.correction, [[0.001, 0.0, 0.0], [0.0, 0.0, 0.0]],
                               atol=1e-15)
    # inward along the gap integrates in full
    corr.update(target, target + [[0.0, 0.002, 0.0], [0.0, 0.0, 0.0]], saturated=True,
                predicted_gap=gap)
    np.testing.assert_allclose(corr.correction[0], [0.001, -0.001, 0.0], atol=1e-15)
    # not held: the gap is ignored; a NaN gap row falls back to conditional integration
    corr.update(target, target - [[0.0, 0.002, 0.0], [0.0, 0.0, 0.0]], predicted_gap=gap)
    np.testing.assert_allclose(corr.correction[0], [0.001, 0.0, 0.0], atol=1e-15)
    corr.update(target, target - [[0.0, 0.002, 0.0], [0.0, 0.0, 0.0]], saturated=True,
                predicted_gap=[[np.nan] * 3, [0.0, 0.0, 0.0]])
    np.testing.assert_allclose(corr.correction[0], [0.001, 0.0, 0.0], atol=1e-15)


def test_directional_anti_windup_reaches_the_plants_nearest_point_beyond_the_reach():
    """
    A model that reaches y <= 0 (it returns the goal's projection), a plant offset from it.

    The plant reaches y <= 1 mm; the target lies 9 mm beyond that: the closed loop with the
    predicted gap ends at the plant's nearest point (9 mm away), the conditional integration,
    held from the first tick, at the model's mismatch from it.
    """
    offset = np.array([0.002, 0.001, 0.0])
    target = np.array([[0.0, 0.010, 0.0]])
    for with_gap in (True, False):
        corr = TargetCorrector(1, gain=0.2, max_correction=0.03)
        measured, model, goal = None, None, None
        for _ in range(200):
            gap = None if model is None or not with_gap else goal - model
            goal = corr.update(target, measured, saturated=model is not None, predicted_gap=gap)
            model = goal * [1.0, 0.0, 1.0] + np.minimum(goal, 0.0) * [0.0, 1.0, 0.0]
            measured = model + offset
        distance = np.linalg.norm(measured - target)
        if with_gap:
            assert distance == pytest.approx(0.009, abs=1e-9)
        else:
            assert distance == pytest.approx(np.hypot(0.002, 0.009), abs=1e-9)


def test_corrected_target_adds_the_integral_without_integrating():
    corr = TargetCorrector(2, gain=0.5, max_correction=0.01)
    target = np.array([[0.1, 0.0, 0.0], [0.2, 0.05, 0.0]])
    corr.update(target, target - [[0.0, 0.002, 0.0], [0.001, 0.0, -0.003]])
    integral = corr.correction.copy()
    np.testing.assert_allclose(corr.corrected(target), target + [[0.0, 0.001, 0.0],
                                                                 [0.0005, 0.0, -0.0015]])
    np.testing.assert_array_equal(corr.correction, integral)
    # a single point is not spread over two effectors, a transposed target is not read
    for wrong in (np.zeros(3), np.zeros((3, 2))):
        with pytest.raises(ValueError, match='shape'):
            corr.corrected(wrong)
    one = TargetCorrector(1, gain=0.5)
    one.update(target[:1], target[:1] - [[0.0, 0.0, 0.004]])
    np.testing.assert_allclose(one.corrected(target[0]), [[0.1, 0.0, 0.002]])


def test_active_set_qp_is_exact_and_agrees_with_proxsuite():
    rng = np.random.default_rng(6)
    for k, m, gap in ((1, 6, 0.01), (2, 16, 0.01), (1, 8, 100.0), (3, 8, 0.001)):
        solver = ActiveSetQP(m)
        for _ in range(4):
            problem, _ = _problem(rng, k=k, m=m, gap=gap)
            exact = solver.solve(problem)
            reference = ProxsuiteQP(m).solve(problem)
            assert exact.ok and exact.status == 'solved' and reference.ok
            x = exact.x
            assert np.all(x >= problem.lower) and np.all(x <= problem.upper)
            grad = problem.hessian @ x + problem.gradient
            inside = (x > problem.lower + 1e-12) & (x < problem.upper - 1e-12)
            assert np.abs(grad[inside]).max(initial=0.0) < 1e-10
            obj = [0.5 * y @ problem.hessian @ y + problem.gradient @ y for y in (x, reference.x)]
            assert obj[0] <= obj[1] + 1e-12 * max(1.0, abs(obj[1]))
            np.testing.assert_allclose(x, reference.x, atol=1e-6)
