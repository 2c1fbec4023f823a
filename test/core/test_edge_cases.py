"""
Edge cases of the safety gate, the trajectories, the QP solvers and the messages.

Each test pins down a behaviour that a one-line change (a mutant of ``make mutate``) altered
without any other test noticing: inclusive box bounds, the error messages that name the bad
input, the square's start point and direction, finite laps, repeated waypoints, the solvers'
status/iteration/ok fields and proxsuite's warm-started updates, the RViz markers.
"""

import math

from builtin_interfaces.msg import Time
from cbha_inverse.core.inverse.qp import (ActiveSetQP, projected_gauss_seidel, ProxsuiteQP,
                                          QPProblem)
from cbha_inverse.robot.robotino import robotino_bar_command, robotino_pressures
from cbha_inverse.robot.safety import (
    bounded_command, check_command, check_point, stale_action, StalenessWatch, WorkspaceBox)
from cbha_inverse.robot.trajectory import (
    circle_points, circle_trajectory, make_trajectory, polyline_points, square_trajectory,
    square_vertices, waypoint_trajectory)
from cbha_inverse.ros.common.conversions import backbone_markers
import numpy as np
import pytest
from visualization_msgs.msg import Marker


# safety -----------------------------------------------------------------------------------
def test_workspace_box_is_closed_and_stores_float_corners():
    box = WorkspaceBox([-1, -2, -3], np.array([1, 2, 3]))
    assert box.lower == (-1.0, -2.0, -3.0) and box.upper == (1.0, 2.0, 3.0)
    assert all(type(v) is float for v in box.lower + box.upper)
    assert box.contains(box.lower) and box.contains(box.upper)
    assert not box.contains(np.nextafter(box.lower, -np.inf))
    assert not box.contains(np.nextafter(box.upper, np.inf))
    assert check_point(box.lower, 'f', 'f', box).ok and check_point(box.upper, 'f', 'f', box).ok


@pytest.mark.parametrize('lower, upper, match', [
    ((0.0, 0.0), (1.0, 1.0, 1.0), '^workspace box corners must have 3 components each$'),
    ((0.0, 0.0, 0.0), (1.0, 1.0), '^workspace box corners must have 3 components each$'),
    ((0.0, 0.0, math.nan), (1.0, 1.0, 1.0), '^workspace box corners must be finite$'),
    ((0.0, 0.0, 0.0), (1.0, math.inf, 1.0), '^workspace box corners must be finite$'),
    ((0.0, 1.0, 0.0), (1.0, 1.0, 1.0),
     r'^workspace box lower \[0.0, 1.0, 0.0\] must be below upper \[1.0, 1.0, 1.0\] in'),
])
def test_workspace_box_rejects_bad_corners(lower, upper, match):
    with pytest.raises(ValueError, match=match):
        WorkspaceBox(lower, upper)


def test_rejections_say_what_is_wrong():
    box = WorkspaceBox((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
    assert 'nan' in check_point((math.nan, 0.0, 0.0), 'f', 'f', box).detail
    assert "'g'" in check_point((0.5, 0.5, 0.5), 'g', 'f', box).detail
    assert '[2.0, 0.5, 0.5]' in check_point((2.0, 0.5, 0.5), 'f', 'f', box).detail
    assert check_command([1.0], 3, 10.0).detail == '1 values, expected 3'
    assert check_command([1.0, math.nan, 1.0], 3, 10.0).detail == 'non-finite pressure'
    assert check_command([1.0, 11.0, 1.0], 3, 10.0).detail == (
        'pressure outside [0, 10] Pa: [1.0, 11.0, 1.0]')
    with pytest.raises(ValueError, match='^command has 2 values, expected 3$'):
        bounded_command([1.0, 2.0], np.zeros(3), np.ones(3))
    with pytest.raises(ValueError, match='^command is not finite$'):
        bounded_command([1.0, math.inf, 2.0], np.zeros(3), np.ones(3))
    with pytest.raises(ValueError, match=r'timeout must be a finite number > 0, got -1\.0'):
        StalenessWatch(-1.0)
    with pytest.raises(ValueError, match=r"action must be one of \('hold', 'vent'\), got 'x'"):
        stale_action(False, False, 'x')


# the Robotino mapping ---------------------------------------------------------------------
def test_wrist_set_points_are_clipped_and_never_non_finite():
    arm = [1e4] * 6
    np.testing.assert_array_equal(robotino_bar_command(arm, wrist_bar=(-0.5, math.nan))[6:],
                                  [0.0, 0.0])
    np.testing.assert_array_equal(robotino_bar_command(arm, wrist_bar=(9.0, math.inf))[6:],
                                  [1.5, 0.0])
    np.testing.assert_array_equal(robotino_bar_command(arm, wrist_bar=(0.25, 1.0))[6:],
                                  [0.25, 1.0])


def test_driver_readings_need_every_named_channel():
    with pytest.raises(ValueError, match='^5 channels read, valve_names need 6$'):
        robotino_pressures([0.1] * 5)
    np.testing.assert_allclose(robotino_pressures([0.1, 0.2, 0.3, 0.4, 0.5, 0.6]),
                               [1e4, 2e4, 3e4, 4e4, 5e4, 6e4])


# trajectories -----------------------------------------------------------------------------
def test_square_starts_mid_side_and_runs_counter_clockwise():
    center = np.array([0.1, 0.2, 0.3])
    path = square_trajectory(center, 0.08, 'YZ', speed=0.04)
    assert path.shape == 'square' and path.plane == 'yz'
    np.testing.assert_array_equal(path.center, center)
    start, first_corner, second_corner = path.sample([0.0, 1.0, 3.0])
    np.testing.assert_allclose(start, center + [0.0, 0.04, 0.0], atol=1e-15)
    # half a side (0.04 m at 0.04 m/s) to the (+u, +v) corner, then one side to (-u, +v)
    np.testing.assert_allclose(first_corner, center + [0.0, 0.04, 0.04], atol=1e-15)
    np.testing.assert_allclose(second_corner, center + [0.0, -0.04, 0.04], atol=1e-15)


def test_circle_fields_and_start_point():
    path = circle_trajectory((0.0, 0.0, 0.0), 0.06, 'ZX', speed=0.025)
    assert path.shape == 'circle' and path.plane == 'zx' and path.radius == 0.06
    np.testing.assert_allclose(path.sample(0.0)[0], [0.0, 0.0, 0.06])
    # a quarter lap later the point is on the second axis (x): counter-clockwise about y
    np.testing.assert_allclose(path.sample(0.25 * path.lap_time)[0], [0.06, 0.0, 0.0],
                               atol=1e-15)


def test_one_lap_ends_on_the_start_point_and_holds_it():
    path = circle_trajectory((0.0, 0.0, 0.0), 0.06, 'yz', speed=0.05, laps=1, start_hold=0.5)
    assert path.duration == pytest.approx(0.5 + path.lap_time)
    half = path.sample(0.5 + 0.5 * path.lap_time)[0]
    np.testing.assert_allclose(half, [0.0, -0.06, 0.0], atol=1e-15)
    assert path.arc_length(path.duration)[0] == path.length
    assert path.arc_length(path.duration + 10.0)[0] == path.length
    np.testing.assert_allclose(path.sample(path.duration + 10.0)[0], [0.0, 0.06, 0.0],
                               atol=1e-15)
    assert path.finished(path.duration) and not path.finished(path.duration - 1e-9)


def test_repeated_waypoints_give_no_garbage():
    """A loop whose last waypoint already is the first: a zero-length closing piece."""
    square = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 0.0, 0.0)]
    path = waypoint_trajectory(square, 1.0, loop=True)
    assert path.shape == 'waypoints' and path.closed
    assert path.length == pytest.approx(2.0 + math.sqrt(2.0))
    np.testing.assert_array_equal(polyline_points(path.vertices, [path.length, 1e9]),
                                  np.zeros((2, 3)))
    repeated = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.0)]
    np.testing.assert_array_equal(polyline_points(repeated, [1.0, 1.5, 5.0]),
                                  [[1.0, 0.0, 0.0]] * 3)


@pytest.mark.parametrize('arguments, match', [
    ({'shape': 'circle', 'radius': 0.0}, '^radius must be a finite number > 0'),
    ({'shape': 'circle', 'center': (0.0, math.nan, 0.0)}, '^center must be finite'),
    ({'shape': 'square', 'side': -1.0}, '^side must be a finite number > 0'),
    ({'shape': 'square', 'center': (0.0, 0.0)}, '^center must have 3 components'),
    ({'shape': 'circle', 'speed': 0.0}, '^speed must be a finite number > 0'),
    ({'shape': 'circle', 'laps': -1}, r'^laps must be an integer >= 0'),
    ({'shape': 'circle', 'start_hold': -1.0}, '^start_hold must be a finite number >= 0'),
    ({'shape': 'waypoints', 'waypoints': [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]},
     r'^waypoints must be \(V, 3\) with V >= 2'),
    ({'shape': 'waypoints', 'waypoints': [0.0, 0.0, 0.0, 1.0]},
     '^a flat waypoint list needs 3 numbers per point'),
    ({'shape': 'waypoints', 'waypoints': [0.0, 0.0, 0.0, 1.0, math.inf, 0.0]},
     '^waypoints must be finite$'),
    ({'shape': 'waypoints', 'waypoints': [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]},
     '^waypoints span a path of zero length$'),
    ({'shape': 'triangle'}, '^shape must be one of'),
])
def test_bad_trajectory_arguments_name_the_argument(arguments, match):
    with pytest.raises(ValueError, match=match):
        make_trajectory(**arguments)


@pytest.mark.parametrize('call, match', [
    (lambda: circle_points((0.0, math.inf, 0.0), 0.06, 'yz', [0.0]), '^center must be finite'),
    (lambda: circle_points((0.0, 0.0, 0.0), -0.06, 'yz', [0.0]),
     '^radius must be a finite number > 0'),
    (lambda: square_vertices((0.0, 0.0), 0.08, 'yz'), '^center must have 3 components'),
    (lambda: square_vertices((0.0, 0.0, 0.0), 0.0, 'yz'), '^side must be a finite number > 0'),
])
def test_path_point_functions_validate_their_own_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_last_lap_ends_exactly_at_the_path_length():
    # exact binary numbers: side 0.25 m (length 1 m) at 0.5 m/s, the lap ends at t = 2 s
    path = square_trajectory((0.0, 0.0, 0.0), 0.25, 'yz', speed=0.5, laps=1)
    assert path.duration == 2.0
    assert path.arc_length([1.0, 2.0, 3.0]).tolist() == [0.5, 1.0, 1.0]
    endless = square_trajectory((0.0, 0.0, 0.0), 0.25, 'yz', speed=0.5)
    assert endless.arc_length([1.0, 2.0, 3.0]).tolist() == [0.5, 0.0, 0.5]


def test_path_constructor_defaults_are_the_papers():
    """Bosman et al. 2015, section V: circle at 2.5 cm/s, square at 3.1 cm/s, in the y-z plane."""
    circle = circle_trajectory((0.0, 0.0, 0.0), 0.06)
    assert (circle.plane, circle.speed, circle.laps, circle.start_hold) == ('yz', 0.025, 0, 0.0)
    square = square_trajectory((0.0, 0.0, 0.0), 0.08)
    assert (square.plane, square.speed, square.laps, square.start_hold) == ('yz', 0.031, 0, 0.0)
    line = waypoint_trajectory([(0.0, 0.0, 0.0), (0.0, 0.0, 0.5)], 0.1)
    assert (line.closed, line.laps, line.start_hold) == (False, 0, 0.0)
    assert make_trajectory('square').length == pytest.approx(4 * 0.08)


def test_make_trajectory_defaults_are_the_papers_and_pass_every_argument():
    circle = make_trajectory('circle')
    assert (circle.speed, circle.radius, circle.plane, circle.laps, circle.start_hold) == (
        0.025, 0.06, 'yz', 0, 0.0)
    square = make_trajectory('square', center=(1.0, 2.0, 3.0), side=0.1, plane='xy',
                             speed=0.031, laps=2, start_hold=1.5)
    assert (square.length, square.plane, square.speed, square.laps, square.start_hold) == (
        pytest.approx(0.4), 'xy', 0.031, 2, 1.5)
    np.testing.assert_array_equal(square.center, [1.0, 2.0, 3.0])
    line = make_trajectory('waypoints', waypoints=(0.0, 0.0, 0.0, 0.0, 0.0, 0.5), speed=0.1,
                           laps=3, start_hold=2.0)
    assert not line.closed and line.length == 0.5 and line.duration == pytest.approx(7.0)
    loop = make_trajectory('waypoints', waypoints=(0.0, 0.0, 0.0, 0.0, 0.0, 0.5), loop=True,
                           laps=3)
    assert loop.closed and loop.length == 1.0 and loop.duration == pytest.approx(3.0 / 0.025)


# QP solvers -------------------------------------------------------------------------------
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


# messages ---------------------------------------------------------------------------------
def test_backbone_markers_draw_the_frames_and_the_target():
    positions = np.array([[0.0, 0.0, 0.0], [0.1, 0.0, 0.0], [0.2, 0.01, -0.02]])
    stamp = Time(sec=12, nanosec=34)
    markers = backbone_markers(positions, (0.3, 0.1, -0.1), stamp, 'cbha_base').markers
    assert [m.type for m in markers] == [Marker.LINE_STRIP, Marker.SPHERE_LIST, Marker.SPHERE]
    assert [m.id for m in markers] == [0, 1, 2]
    for marker in markers:
        assert marker.header.frame_id == 'cbha_base' and marker.header.stamp == stamp
        assert marker.ns == 'backbone' and marker.action == Marker.ADD
        assert marker.pose.orientation.w == 1.0 and marker.color.a == 1.0
        assert marker.scale.x == marker.scale.y == marker.scale.z > 0.0
    for marker in markers[:2]:
        np.testing.assert_array_equal([[p.x, p.y, p.z] for p in marker.points], positions)
    goal = markers[2].pose.position
    assert (goal.x, goal.y, goal.z) == (0.3, 0.1, -0.1)
    assert [(m.color.r, m.color.g, m.color.b) for m in markers] == [
        (0.2, 0.5, 1.0), (0.9, 0.9, 0.9), (1.0, 0.3, 0.1)]
    assert [m.scale.x for m in markers] == [0.004, 0.008, 0.01]
    no_target = backbone_markers(positions, None, stamp, 'map', namespace='model').markers
    assert len(no_target) == 2 and {m.ns for m in no_target} == {'model'}
