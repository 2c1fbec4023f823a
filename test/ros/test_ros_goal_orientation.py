"""
``~/follow_trajectory`` with orientations over real DDS, open loop on ``cbha_approach``.

The tip is an ``axis`` effector (its approach axis, the backbone +x of the last vertebra): a
waypoint's rotation turns that axis to where it carries +x. A goal to the workspace centre
with the axis turned 20° about the vertical ends SUCCESSFUL with the model's axis within the
goal angle tolerance of that direction, 20° from the axis a goal without rotation leaves (+x,
the rest target); a position-only goal (goal angle tolerance < 0) then keeps the axis. A NaN or
zero quaternion is INVALID_GOAL naming its waypoint. A ``pose`` tip (the same arm) turns its
whole frame to a pose of the forward model. ``cbha_goto --axis`` reaches the direction, and
refuses ``--axis`` on a scene whose tip is a point effector in one line.
"""

import subprocess
import sys

from cbha_inverse.robot import goals
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointComponentTolerance
import numpy as np
from rclpy.action import ActionClient
from rclpy.node import Node
from ros_goal_helpers import send_goal, trajectory_goal, wait_result
from ros_helpers import child_env, make_node, REPO_ROOT, spin_until, spinning
from scipy.spatial.transform import Rotation

ACTION = 'inverse_solver/follow_trajectory'
SUCCEEDED, ABORTED = 4, 6
"""action_msgs/GoalStatus values."""
CENTER = np.array([0.2308, 0.0, -0.0292])
"""The tip with every bellows at 75 kPa [m] (docs/effectors.md: the axis 8-9° below +x)."""
TURN = Rotation.from_euler('z', 20.0, degrees=True)
"""The waypoint's orientation: the approach axis +x turned 20° toward +y."""
DIRECTION = TURN.apply([1.0, 0.0, 0.0])


def _solver(context, scene='cbha_approach'):
    return make_node(InverseSolverNode, context, scene=scene, mode='open', reach_samples=0)


def _angle(a, b):
    return np.degrees(np.arctan2(np.linalg.norm(np.cross(a, b)), np.dot(a, b)))


def _oriented(points, times, quaternions, angle_tolerance=0.0):
    """Return a goal of the tip through ``points``, its rotations, a goal angle tolerance [rad]."""
    goal = trajectory_goal('tip', points, times, goal_tolerance=0.0005)
    for waypoint, (x, y, z, w) in zip(goal.multi_dof_trajectory.points, quaternions):
        rotation = waypoint.transforms[0].rotation
        rotation.x, rotation.y, rotation.z, rotation.w = (float(v) for v in (x, y, z, w))
    goal.component_goal_tolerance = [JointComponentTolerance(
        joint_name='tip', component=JointComponentTolerance.ROTATION,
        position=float(angle_tolerance))]
    return goal


def test_a_waypoint_rotation_turns_the_approach_axis_and_a_free_one_keeps_it(rclpy_context):
    solver = _solver(rclpy_context)
    client = Node('goal_client', context=rclpy_context, namespace='/cbha')
    action = ActionClient(client, FollowJointTrajectory, ACTION)
    feedback = []
    tolerance = np.radians(0.5)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, action.server_is_ready, 10.0)
        status, result = wait_result(executor, send_goal(executor, action, _oriented(
            [CENTER], [0.0], [TURN.as_quat()], tolerance), feedback.append))
        turned = solver.solver.effector_directions()[0].copy()
        reached = solver.solver.effector_positions()[0].copy()
        # position only: the orientation free, the axis target stays where the goal left it
        moved = CENTER + [0.0, 0.005, 0.0]
        free_status, free = wait_result(executor, send_goal(executor, action, _oriented(
            [moved], [0.0], [[0.0, 0.0, 0.0, 1.0]], -1.0)))
        kept = solver.solver.effector_directions()[0].copy()
        target = solver.solver.orientation_targets[0][0].copy()
        # the identity rotation (+x), the default angle tolerance: back to the rest axis
        rest_status, rest = wait_result(executor, send_goal(executor, action, _oriented(
            [CENTER], [0.0], [[0.0, 0.0, 0.0, 1.0]])))
        straight = solver.solver.effector_directions()[0].copy()
    assert status == SUCCEEDED and result.error_code == goals.SUCCESSFUL, result.error_string
    assert result.error_string.startswith('reached: tip ') and '°' in result.error_string
    assert _angle(turned, DIRECTION) <= np.degrees(tolerance), turned
    assert np.linalg.norm(reached - CENTER) <= 0.0005
    # ignoring the rotation would leave the axis near +x, 20° from where it is
    assert _angle(straight, [1.0, 0.0, 0.0]) <= 1.0 and _angle(straight, turned) > 18.0
    assert rest_status == SUCCEEDED, rest.error_string
    assert free_status == SUCCEEDED, free.error_string
    np.testing.assert_allclose(target, DIRECTION, atol=1e-9)
    assert _angle(kept, DIRECTION) <= 1.0
    # the feedback: the model frame's rotation and the axis' error shrinking to the end
    actual = [f.feedback.multi_dof_actual.transforms[0].rotation for f in feedback]
    errors = [f.feedback.multi_dof_error.transforms[0].rotation for f in feedback]
    error_angles = [np.degrees(Rotation.from_quat([q.x, q.y, q.z, q.w]).magnitude())
                    for q in errors]
    last = actual[-1]
    axis = Rotation.from_quat([last.x, last.y, last.z, last.w]).apply([1.0, 0.0, 0.0])
    assert len(feedback) >= 3 and max(error_angles) > 0.05
    assert _angle(axis, DIRECTION) < 5.0


def test_a_pose_effector_turns_its_frame_to_the_waypoint(rclpy_context, tmp_path):
    """``cbha_approach`` with a ``pose`` tip: a pose of the forward model is reached, frame too."""
    (tmp_path / 'scenes').mkdir()
    (tmp_path / 'segments').symlink_to(REPO_ROOT / 'config' / 'segments')
    text = (REPO_ROOT / 'config' / 'scenes' / 'cbha_approach.yaml').read_text()
    text = text.replace('kind: axis', 'kind: pose').replace(' axis: [1.0, 0.0, 0.0],', '')
    scene_path = tmp_path / 'scenes' / 'cbha_pose.yaml'
    scene_path.write_text(text)
    scene = load_scene(scene_path)
    assert scene.effectors.kinds == ('pose',)
    reached = scene.forward(np.array([6e4, 1e4, 2e4, 3e4, 5e4, 1e4]), strict=True)
    rotation = reached.state.rotations[scene.effectors.frames[0]]
    position = reached.effector_positions[0]
    solver = _solver(rclpy_context, scene=str(scene_path))
    client = Node('goal_client', context=rclpy_context, namespace='/cbha')
    action = ActionClient(client, FollowJointTrajectory, ACTION)
    tolerance = np.radians(0.5)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, action.server_is_ready, 10.0)
        status, result = wait_result(executor, send_goal(executor, action, _oriented(
            [position], [0.0], [Rotation.from_matrix(rotation).as_quat()], tolerance)))
        frame = solver.solver.effectors.rotations(solver.solver.state.rotations)[0]
    assert status == SUCCEEDED, result.error_string
    turned = np.degrees(Rotation.from_matrix(frame.T @ rotation).magnitude())
    assert turned <= np.degrees(tolerance), turned
    # the pose is not the rest one: the frame really turned
    assert np.degrees(Rotation.from_matrix(rotation).magnitude()) > 10.0


def test_a_nan_or_zero_quaternion_is_an_invalid_goal_naming_its_waypoint(rclpy_context):
    solver = _solver(rclpy_context)
    client = Node('goal_client', context=rclpy_context, namespace='/cbha')
    action = ActionClient(client, FollowJointTrajectory, ACTION)
    points = [CENTER, CENTER + [0.0, 0.005, 0.0]]
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, action.server_is_ready, 10.0)
        outcomes = [wait_result(executor, send_goal(executor, action, _oriented(
            points, [1.0, 2.0], quaternions))) for quaternions in (
                [[0.0, 0.0, 0.0, 1.0], [np.nan, 0.0, 0.0, 1.0]],
                [[0.0, 0.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])]
        assert solver.commanding.run is None
    (nan_status, nan), (zero_status, zero) = outcomes
    assert nan_status == ABORTED and nan.error_code == goals.INVALID_GOAL
    assert nan.error_string.startswith('waypoint 1: rotation of tip must be finite')
    assert zero_status == ABORTED and zero.error_code == goals.INVALID_GOAL
    assert zero.error_string.startswith('waypoint 0: rotation of tip must be a unit quaternion')


def _goto(executor, *arguments):
    """Run ``cbha_goto`` as a user does while ``executor`` spins; return (status, out, err)."""
    process = subprocess.Popen([sys.executable, '-m', 'cbha_inverse.ros.console.goto',
                                *arguments], cwd=REPO_ROOT, env=child_env(),
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        assert spin_until(executor, lambda: process.poll() is not None, 60.0)
    finally:
        if process.poll() is None:
            process.kill()
    out, err = process.communicate()
    return process.returncode, out, err


def test_cbha_goto_axis_reaches_and_is_refused_for_a_point_effector(rclpy_context):
    solver = _solver(rclpy_context)
    direction = 3.0 * DIRECTION                    # normalised by cbha_goto
    with spinning(rclpy_context, solver) as executor:
        status, out, err = _goto(executor, *map(str, CENTER), '--axis', *map(str, direction),
                                 '--tolerance', '0.0005')
        turned = solver.solver.effector_directions()[0].copy()
    assert status == 0, out + err
    assert 'deg to go' in out and 'deg off the path' in out, out
    assert 'SUCCESSFUL: reached: tip ' in out, out
    assert _angle(turned, DIRECTION) <= 1.0
    point = _solver(rclpy_context, scene='cbha')
    with spinning(rclpy_context, point) as executor:
        status, out, err = _goto(executor, *map(str, CENTER), '--axis', '1', '0', '0')
        assert point.commanding.run is None
    assert status == 2, out + err
    assert err.strip() == ("cbha_goto: --axis: tip is a point effector of scene 'cbha', not an "
                           'axis effector'), err
