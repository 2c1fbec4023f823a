"""
The trajectory goals' core (:mod:`cbha_inverse.robot.goals`): validation, approach, tolerances.

References: straight-line interpolation by hand, the approach time from the distance and the
speed bound, the control_msgs result codes, a reach whose hull is a known cube, rotations about
fixed axes (scipy's Rotation) and the great-circle formula of the slerp of two directions.
"""

from cbha_inverse.core.actuation.effectors import PointEffectors
from cbha_inverse.robot import goals
from cbha_inverse.scene.reach import ReachableSet
from control_msgs.action import FollowJointTrajectory
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

EFFECTORS = ('mid', 'tip')


def _goal(times=(1.0, 2.0), positions=None, **kwargs):
    if positions is None:
        positions = [[[0.1, 0.0, 0.0]], [[0.1, 0.02, 0.0]]]
    return goals.make_goal(EFFECTORS, ['tip'], times, positions, **kwargs)


def _cube_reach(half=0.05):
    """Return a reach whose hull is the cube |x|, |y|, |z| <= half [m]."""
    normals = np.vstack([np.eye(3), -np.eye(3)])
    halfspaces = np.hstack([normals, np.full((6, 1), -half)])
    return ReachableSet(effector='tip', actuations=np.zeros((0, 1)), points=np.zeros((0, 3)),
                        failed=0, box_min=-np.full(3, half), box_max=np.full(3, half),
                        center=np.zeros(3), radii={}, widest_plane=None, halfspaces=halfspaces,
                        flat_planes=())


def test_the_result_codes_are_those_of_control_msgs():
    result = FollowJointTrajectory.Result
    for code, name in goals.CODE_NAMES.items():
        assert getattr(result, name) == code


@pytest.mark.parametrize('names, code, words', [
    (['elbow'], goals.INVALID_JOINTS, "unknown effectors ['elbow']"),
    (['tip', 'tip'], goals.INVALID_JOINTS, 'named twice'),
    ([], goals.INVALID_JOINTS, 'names no effector')])
def test_effector_names_are_checked(names, code, words):
    with pytest.raises(goals.GoalError, match=words.replace('[', r'\[').replace(']', r'\]')) \
            as raised:
        goals.make_goal(EFFECTORS, names, [1.0], np.zeros((1, len(names), 3)))
    assert raised.value.code == code


@pytest.mark.parametrize('times, positions, words', [
    ((1.0, 1.0), None, 'waypoint 1: time_from_start 1 s does not come after'),
    ((2.0, 1.0), None, 'waypoint 1'),
    ((-1.0, 1.0), None, 'waypoint 0: time_from_start -1 s < 0'),
    ((1.0, np.nan), None, 'waypoint 1: time_from_start is not finite'),
    ((1.0, 2.0), [[[0.1, 0.0, 0.0]], [[0.1, np.nan, 0.0]]], 'waypoint 1: a position is not'),
    ((1.0, 2.0), np.zeros((2, 3)), 'shape'),
    ((), np.zeros((0, 1, 3)), 'no waypoint')])
def test_times_and_positions_are_checked(times, positions, words):
    with pytest.raises(goals.GoalError, match=words) as raised:
        _goal(times, positions)
    assert raised.value.code == goals.INVALID_GOAL


def test_a_waypoint_beyond_the_reach_is_named_with_its_distance():
    reach = [None, _cube_reach()]
    positions = [[[0.0, 0.0, 0.0]], [[0.03, 0.0, 0.0]], [[0.0, 0.0, 0.0725]]]
    with pytest.raises(goals.GoalError, match=r'waypoint 2: tip at \[0.0, 0.0, 0.0725\] m is '
                       r'22.5 mm beyond its reachable set') as raised:
        _goal((1.0, 2.0, 3.0), positions, reach=reach)
    assert raised.value.code == goals.INVALID_GOAL
    # within the margin: accepted
    _goal((1.0, 2.0, 3.0), positions, reach=reach, reach_margin=0.023)


def test_outside_distance_is_the_distance_to_the_nearest_face_of_a_cube():
    distance = _cube_reach().outside_distance([[0.0, 0.0, 0.0], [0.08, 0.01, 0.0],
                                               [0.0, -0.06, 0.0]])
    np.testing.assert_allclose(distance, [-0.05, 0.03, 0.01], atol=1e-15)


def test_tolerances_zero_default_negative_none_and_unknown_names():
    goal = _goal(path_tolerance={'tip': 0.0}, goal_tolerance={'tip': 0.002},
                 goal_time_tolerance=0.0, defaults=(0.004, 0.001, 0.7))
    assert goal.path_tolerance.tolist() == [0.004]
    assert goal.goal_tolerance.tolist() == [0.002]
    assert goal.goal_time_tolerance == 0.7
    assert _goal(path_tolerance={'tip': -1.0}).path_tolerance.tolist() == [np.inf]
    assert _goal(defaults=(0.0, 0.001, 1.0)).path_tolerance.tolist() == [np.inf]
    with pytest.raises(goals.GoalError, match='not effectors of the goal') as raised:
        _goal(goal_tolerance={'mid': 0.001})
    assert raised.value.code == goals.INVALID_JOINTS


def test_the_plan_interpolates_linearly_from_the_start_through_the_waypoints():
    goal = _goal((1.0, 2.0), [[[0.1, 0.0, 0.0]], [[0.1, 0.02, 0.0]]])
    start = np.array([[0.1, 0.0, -0.01]])
    plan = goals.plan_goal(goal, start, approach_speed=0.05)   # 10 mm in 1 s: no delay
    assert plan.delay == 0.0 and plan.end_time == 2.0
    np.testing.assert_allclose(plan.desired(-1.0), start)
    np.testing.assert_allclose(plan.desired(0.25), [[0.1, 0.0, -0.0075]])
    np.testing.assert_allclose(plan.desired(1.5), [[0.1, 0.01, 0.0]])
    np.testing.assert_allclose(plan.desired(5.0), [[0.1, 0.02, 0.0]])
    for t in np.linspace(0.0, 2.0, 201):    # at a 100 Hz solver's ticks: on the segments
        p = plan.desired(t)[0]
        if t <= 1.0:
            np.testing.assert_allclose(p, start[0] + t * (goal.positions[0, 0] - start[0]),
                                       atol=1e-15)
        else:
            np.testing.assert_allclose(p, [0.1, 0.02 * (t - 1.0), 0.0], atol=1e-15)


def test_a_fast_first_waypoint_is_delayed_so_that_the_approach_keeps_its_speed():
    goal = _goal((0.0, 1.0), [[[0.1, 0.0, 0.0]], [[0.1, 0.02, 0.0]]])
    start = np.array([[0.1, -0.03, 0.04]])     # 50 mm away
    plan = goals.plan_goal(goal, start, approach_speed=0.02)
    assert plan.delay == pytest.approx(2.5)
    ticks = np.arange(0.0, plan.end_time + 0.01, 0.01)
    path = np.array([plan.desired(t)[0] for t in ticks])
    speeds = np.linalg.norm(np.diff(path, axis=0), axis=1) / 0.01
    assert speeds[ticks[1:] <= 2.5].max() == pytest.approx(0.02)
    np.testing.assert_allclose(plan.desired(2.5), goal.positions[0])
    np.testing.assert_allclose(plan.desired(3.5), goal.positions[1])
    with pytest.raises(ValueError, match='approach_speed'):
        goals.plan_goal(goal, start, 0.0)
    with pytest.raises(ValueError, match='start'):
        goals.plan_goal(goal, np.zeros(3), 0.02)


def test_the_monitor_path_tolerance_success_and_goal_time_tolerance():
    goal = _goal((1.0, 2.0), path_tolerance={'tip': 0.002}, goal_tolerance={'tip': 0.001},
                 goal_time_tolerance=0.5)
    plan = goals.plan_goal(goal, [[0.1, 0.0, 0.0]], 0.05)
    monitor = goals.GoalMonitor(goal, plan)
    assert monitor.check(1.5, plan.desired(1.5) + [0.0, 0.0015, 0.0]) is None
    outcome = monitor.check(1.5, plan.desired(1.5) + [0.0, 0.0, 0.0025])
    assert outcome.code == goals.PATH_TOLERANCE_VIOLATED
    assert 'tip 2.50 mm from its path at 1.50 s' in outcome.text
    end = plan.desired(2.0)
    assert monitor.check(2.2, end + [0.0015, 0.0, 0.0]) is None       # settling
    reached = monitor.check(2.3, end + [0.0008, 0.0, 0.0])
    assert reached.succeeded and reached.errors == pytest.approx([0.0008])
    late = monitor.check(2.51, end + [0.0015, 0.0, 0.0])
    assert late.code == goals.GOAL_TOLERANCE_VIOLATED and 'still 1.50 mm' in late.text


@pytest.mark.parametrize('shape', ['square', 'circle', 'waypoints'])
def test_a_trajectory_as_timed_waypoints_follows_its_path_in_time(shape):
    from cbha_inverse.robot.trajectory import make_trajectory
    trajectory = make_trajectory(shape, center=(0.2, 0.0, -0.03), radius=0.06, side=0.08,
                                 speed=0.03, laps=2, start_hold=0.5,
                                 waypoints=(0.2, 0.0, 0.0, 0.2, 0.03, 0.0, 0.2, 0.03, 0.02))
    times, points = trajectory.waypoints(max_chord_error=1e-5)
    assert times[0] == 0.0 and times[-1] == pytest.approx(trajectory.duration)
    assert np.all(np.diff(times) > 0.0)
    goal = goals.make_goal(['tip'], ['tip'], times, points[:, None])
    plan = goals.plan_goal(goal, points[:1], approach_speed=0.01)
    assert plan.delay == 0.0
    for t in np.linspace(0.0, trajectory.duration, 977):
        gap = np.linalg.norm(plan.desired(t)[0] - trajectory.sample(t)[0])
        assert gap <= (1.5e-5 if shape == 'circle' else 1e-12), (t, gap)
    with pytest.raises(ValueError, match='endless'):
        make_trajectory('circle', radius=0.06, laps=0).waypoints()


def _turn(axis, degrees):
    """Return the rotation matrix of ``degrees`` about a unit ``axis``."""
    return Rotation.from_rotvec(np.radians(degrees) * np.asarray(axis, dtype=float)).as_matrix()


def _quaternion(rotation):
    return Rotation.from_matrix(rotation).as_quat()         # (x, y, z, w), as ROS


ORIENTED = PointEffectors(('mid', 'tip'), [1, 2], np.zeros((2, 3)), 3, kinds=('pose', 'axis'),
                          axes=[[1.0, 0.0, 0.0], [0.0, 0.0, 1.0]],
                          orientation_lengths=[0.1, 0.05])
"""A pose effector and an axis effector whose axis is its frame's +z."""


def _oriented_goal(times, rotations, positions=None, **kwargs):
    """Return a goal of ``mid`` (pose) and ``tip`` (axis): (n, 2, 3, 3) rotations, fixed places."""
    rotations = np.asarray(rotations)
    if positions is None:
        positions = np.tile([[0.1, 0.0, 0.0], [0.2, 0.0, 0.0]], (len(times), 1, 1))
    return goals.make_goal(ORIENTED, ['mid', 'tip'], times, positions,
                           quaternions=_quaternion(rotations.reshape(-1, 3, 3)).reshape(
                               len(times), 2, 4), **kwargs)


def test_orientations_follow_the_slerp_of_their_knots():
    """A pose's frame: the geodesic; an axis: the great circle (a twist about u is free)."""
    z, y, x = [0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [1.0, 0.0, 0.0]
    # mid: Rz(40°) at 1 s, then Ry(30°) Rz(40°) at 2 s; tip (axis +z): tilted 60° toward +x at
    # 1 s (its frame also twisted 90° about its own axis), then back to +z at 2 s
    first = [_turn(z, 40.0), _turn(y, 60.0) @ _turn(z, 90.0)]
    second = [_turn(y, 30.0) @ _turn(z, 40.0), _turn(x, 35.0)]
    goal = _oriented_goal((1.0, 2.0), [first, second])
    start = np.tile(np.eye(3), (2, 1, 1))
    plan = goals.plan_goal(goal, goal.positions[0], approach_speed=1.0, start_rotations=start)
    assert plan.delay == 0.0
    for f in np.linspace(0.0, 1.0, 11):
        rotations = plan.desired_rotations(f)
        np.testing.assert_allclose(rotations[0], _turn(z, 40.0 * f), atol=1e-12)
        np.testing.assert_allclose(rotations[1] @ z, [np.sin(np.radians(60.0 * f)), 0.0,
                                                      np.cos(np.radians(60.0 * f))], atol=1e-12)
        rotations = plan.desired_rotations(1.0 + f)
        np.testing.assert_allclose(rotations[0], _turn(y, 30.0 * f) @ _turn(z, 40.0), atol=1e-12)
        # from 60° toward +x to 35° toward -y: the great circle between the two directions
        a, b = first[1] @ z, second[1] @ z
        omega = np.arccos(a @ b)
        arc = (np.sin((1.0 - f) * omega) * a + np.sin(f * omega) * b) / np.sin(omega)
        np.testing.assert_allclose(rotations[1] @ z, arc, atol=1e-12)
    np.testing.assert_allclose(plan.desired_rotations(5.0)[0], second[0], atol=1e-12)


def test_the_approach_takes_an_angle_as_its_orientation_length():
    """A turn of 0.5 rad at 0.1 m/rad is a 50 mm approach: 2.5 s at 20 mm/s."""
    turn = _turn([0.0, 0.0, 1.0], np.degrees(0.5))
    goal = _oriented_goal((0.0, 1.0), [[turn, np.eye(3)], [turn, np.eye(3)]])
    plan = goals.plan_goal(goal, goal.positions[0], 0.02, np.tile(np.eye(3), (2, 1, 1)))
    assert plan.delay == pytest.approx(2.5)
    # the axis effector: 0.5 rad of tilt at 0.05 m/rad is 25 mm, 1.25 s
    tilt = _turn([1.0, 0.0, 0.0], np.degrees(0.5))
    goal = _oriented_goal((0.0, 1.0), [[np.eye(3), tilt], [np.eye(3), tilt]])
    plan = goals.plan_goal(goal, goal.positions[0], 0.02, np.tile(np.eye(3), (2, 1, 1)))
    assert plan.delay == pytest.approx(1.25)
    # a twist about the axis only: no turn to approach
    twist = _turn([0.0, 0.0, 1.0], 80.0)
    goal = _oriented_goal((0.0, 1.0), [[np.eye(3), twist], [np.eye(3), twist]])
    assert goals.plan_goal(goal, goal.positions[0], 0.02,
                           np.tile(np.eye(3), (2, 1, 1))).delay == 0.0


def test_the_monitor_checks_angles_beside_distances():
    goal = _oriented_goal((1.0, 2.0), np.tile(np.eye(3), (2, 2, 1, 1)),
                          path_angle_tolerance={'tip': np.radians(3.0)},
                          goal_angle_tolerance={'mid': np.radians(1.0), 'tip': np.radians(1.0)},
                          goal_time_tolerance=0.5)
    plan = goals.plan_goal(goal, goal.positions[0], 0.05, np.tile(np.eye(3), (2, 1, 1)))
    monitor = goals.GoalMonitor(goal, plan)
    at = goal.positions[0]
    # a twist of the axis effector about its own axis (+z) is free; a tilt is not
    twisted = np.array([_turn([0.0, 1.0, 0.0], 0.5), _turn([0.0, 0.0, 1.0], 50.0)])
    assert monitor.check(1.5, at, twisted) is None
    tilted = np.array([np.eye(3), _turn([1.0, 1.0, 0.0] / np.sqrt(2.0), 4.0)])
    outcome = monitor.check(1.5, at, tilted)
    assert outcome.code == goals.PATH_TOLERANCE_VIOLATED
    assert 'tip turned 4.00° from its path at 1.50 s (path angle tolerance 3.00°)' in outcome.text
    reached = monitor.check(2.2, at, twisted)
    assert reached.succeeded and reached.angles == pytest.approx(np.radians([0.5, 0.0]))
    assert 'mid 0.00 mm 0.50°, tip 0.00 mm 0.00°' in reached.text
    off = np.array([_turn([0.3, 0.4, np.sqrt(0.75)], 1.5), np.eye(3)])
    assert monitor.check(2.2, at, off) is None                         # settling
    late = monitor.check(2.6, at, off)
    assert late.code == goals.GOAL_TOLERANCE_VIOLATED
    assert 'mid still turned 1.50°' in late.text and '(goal angle tolerance 1.00°)' in late.text


@pytest.mark.parametrize('quaternion, words', [
    ([np.nan, 0.0, 0.0, 1.0], 'waypoint 1: rotation of tip must be finite'),
    ([0.0, 0.0, 0.0, 0.0], 'waypoint 1: rotation of tip must be a unit quaternion .* norm is 0'),
    ([0.0, 0.0, 0.0, 0.5], 'waypoint 1: rotation of tip must be a unit quaternion')])
def test_a_rotation_that_is_not_a_unit_quaternion_is_refused_with_its_waypoint(quaternion,
                                                                               words):
    quaternions = np.tile([0.0, 0.0, 0.0, 1.0], (2, 2, 1))
    quaternions[1, 1] = quaternion
    with pytest.raises(goals.GoalError, match=words) as raised:
        goals.make_goal(ORIENTED, ['mid', 'tip'], (1.0, 2.0), np.zeros((2, 2, 3)),
                        quaternions=quaternions)
    assert raised.value.code == goals.INVALID_GOAL
    quaternions[1, 1] = [0.0, 0.0, 0.0, 1.0005]        # within 1e-3: normalised
    goal = goals.make_goal(ORIENTED, ['mid', 'tip'], (1.0, 2.0), np.zeros((2, 2, 3)),
                           quaternions=quaternions)
    np.testing.assert_allclose(goal.rotations[1, 1], np.eye(3), atol=1e-15)


def test_angle_tolerances_defaults_free_orientations_and_point_effectors():
    goal = _oriented_goal((1.0,), np.tile(np.eye(3), (1, 2, 1, 1)),
                          goal_angle_tolerance={'tip': -1.0}, angle_defaults=(0.0, 0.02))
    assert goal.oriented.tolist() == [True, False]      # tip's orientation is free
    assert goal.goal_angle_tolerance.tolist() == [0.02, np.inf]
    assert goal.path_angle_tolerance.tolist() == [np.inf, np.inf]
    plan = goals.plan_goal(goal, goal.positions[0], 0.05,
                           [np.eye(3), _turn([1.0, 0.0, 0.0], 90.0)])
    # the free tip is never off: its turn counts neither on the approach nor at the goal
    assert plan.delay == 0.0
    assert goals.GoalMonitor(goal, plan).check(
        1.0, goal.positions[0], [np.eye(3), _turn([1.0, 0.0, 0.0], 90.0)]).succeeded
    # a point effector ignores rotations; a bound on its angle is refused
    point = _goal(goal_angle_tolerance={'tip': -1.0}, path_angle_tolerance={'tip': 0.0})
    assert point.oriented.tolist() == [False]
    with pytest.raises(goals.GoalError, match='goal angle tolerance of tip: a point effector has '
                       'no orientation to bound') as raised:
        _goal(goal_angle_tolerance={'tip': 0.01})
    assert raised.value.code == goals.INVALID_GOAL


def test_a_frame_transform_moves_positions_and_turns_orientations():
    frame = _turn([0.0, 0.0, 1.0], 90.0), np.array([0.01, 0.02, 0.03])
    tilt = _turn([0.0, 1.0, 0.0], 20.0)
    goal = _oriented_goal((1.0,), [[tilt, tilt]], frame_transform=frame)
    np.testing.assert_allclose(goal.positions[0], [[0.01, 0.12, 0.03], [0.01, 0.22, 0.03]],
                               atol=1e-15)
    np.testing.assert_allclose(goal.rotations[0, 0], frame[0] @ tilt, atol=1e-15)
