"""
``inverse_solver`` commanded as a manipulator over real DDS (``docs/commanding.md``), open loop.

The trajectory action ``~/follow_trajectory`` (success inside the goal tolerance, a waypoint
beyond the reach refused with its name and distance, streaming targets refused while a goal
runs, cancel holds, a new goal preempts), the effector topics ``targets/<effector>`` and the
teleop topic ``~/delta_twist_cmds`` (the target integrates the velocity, a gap in the commands
holds it). Open loop: the actual effector is the model's, so the checks need no plant.
"""

import signal
import subprocess
import sys
import time

from cbha_inverse.robot import goals
from cbha_inverse.ros.common.qos import MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from control_msgs.action import FollowJointTrajectory
from geometry_msgs.msg import PointStamped, TwistStamped
import numpy as np
import pytest
from rclpy.action import ActionClient
from rclpy.node import Node
from ros_goal_helpers import send_goal, trajectory_goal, wait_result
from ros_helpers import (child_env, make_node, REPO_ROOT, set_parameters, spin_for, spin_until,
                         spinning, target_point)

TENDON = 'tendon_6f_8c'
CENTER = np.array([0.117, 0.0, -0.005])
"""A tip position well in the tendon trunk's reach [m]."""
ACTION = 'inverse_solver/follow_trajectory'
SUCCEEDED, CANCELED, ABORTED = 4, 5, 6
"""action_msgs/GoalStatus values."""


def _solver(context, **params):
    return make_node(InverseSolverNode, context, scene=TENDON, max_pressure=10.0,
                     reach_samples=300, **params)


def _tip(solver):
    return solver.solver.effector_positions()[0].copy()


def test_a_goal_succeeds_within_its_tolerance_and_one_beyond_reach_is_invalid(rclpy_context):
    solver = _solver(rclpy_context)
    client = Node('goal_client', context=rclpy_context, namespace='/cbha')
    action = ActionClient(client, FollowJointTrajectory, ACTION)
    targets = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    tip_targets = client.create_publisher(PointStamped, 'targets/tip', TARGET_QOS)
    feedback = []
    points = CENTER + [[0.0, 0.01, 0.0], [0.0, 0.01, 0.01], [0.0, 0.0, 0.01]]
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: action.server_is_ready()
                          and tip_targets.get_subscription_count() > 0, 10.0)
        tip_targets.publish(target_point(CENTER))
        assert spin_until(executor, lambda: solver.target is not None, 5.0)
        np.testing.assert_array_equal(solver.target, CENTER)
        handle = send_goal(executor, action, trajectory_goal(
            'tip', points, [0.5, 1.0, 1.5], goal_tolerance=0.0005), feedback.append)
        spin_for(executor, 0.3)
        targets.publish(target_point(CENTER))         # refused: a goal runs
        status, result = wait_result(executor, handle)
        final = _tip(solver)
        assert spin_until(executor, lambda: solver.rejected.get('target.goal_active'), 5.0)
        far = CENTER + [0.0, 0.0, 0.012]
        handle = send_goal(executor, action, trajectory_goal(
            'tip', [far, CENTER + [0.0, 0.12, 0.0]], [1.0, 2.0]))
        invalid_status, invalid = wait_result(executor, handle)
        handle = send_goal(executor, action, trajectory_goal('elbow', [CENTER], [1.0]))
        joints_status, joints = wait_result(executor, handle)
    assert status == SUCCEEDED and result.error_code == goals.SUCCESSFUL, result.error_string
    assert np.linalg.norm(final - points[-1]) <= 0.0005
    assert result.error_string.startswith('reached: tip ')
    assert feedback and feedback[-1].feedback.multi_dof_joint_names == ['tip']
    error = feedback[0].feedback.multi_dof_error.transforms[0].translation
    assert np.isfinite([error.x, error.y, error.z]).all()
    assert invalid_status == ABORTED and invalid.error_code == goals.INVALID_GOAL
    assert invalid.error_string.startswith('waypoint 1: tip at [0.117, 0.12, -0.005] m is ')
    assert 'mm beyond its reachable set' in invalid.error_string
    assert joints_status == ABORTED and joints.error_code == goals.INVALID_JOINTS
    assert "unknown effectors ['elbow']" in joints.error_string


def test_cancel_holds_where_the_arm_is_and_a_new_goal_preempts(rclpy_context):
    solver = _solver(rclpy_context)
    client = Node('goal_client', context=rclpy_context, namespace='/cbha')
    action = ActionClient(client, FollowJointTrajectory, ACTION)
    path = CENTER + [[0.0, -0.01, 0.0], [0.0, 0.01, 0.0]]
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, action.server_is_ready, 10.0)
        handle = send_goal(executor, action, trajectory_goal('tip', path, [0.5, 3.0]))
        spin_for(executor, 1.5)
        cancel = handle.cancel_goal_async()
        assert spin_until(executor, cancel.done, 5.0)
        status, result = wait_result(executor, handle)
        at_cancel = _tip(solver)
        spin_for(executor, 0.5)
        held = _tip(solver)
        moved = np.linalg.norm(at_cancel - (CENTER + [0.0, -0.01, 0.0]))
        first = send_goal(executor, action, trajectory_goal('tip', path, [0.5, 3.0]))
        spin_for(executor, 1.0)
        second = send_goal(executor, action, trajectory_goal('tip', [CENTER], [0.5]))
        first_status, first_result = wait_result(executor, first)
        second_status, second_result = wait_result(executor, second)
        final = _tip(solver)
    assert status == CANCELED and result.error_string.startswith('canceled'), result
    assert moved > 0.003, 'the goal had not moved before the cancel'
    assert np.linalg.norm(held - at_cancel) <= 0.001
    assert first_status == ABORTED and first_result.error_string == 'preempted by a new goal'
    assert second_status == SUCCEEDED, second_result.error_string
    assert np.linalg.norm(final - CENTER) <= 0.001


def _twist(vy):
    message = TwistStamped()
    message.header.frame_id = 'cbha_base'
    message.twist.linear.y = float(vy)
    return message


def test_teleop_integrates_the_twist_and_a_gap_in_the_commands_holds(rclpy_context):
    speed = 0.02
    solver = _solver(rclpy_context, teleop_timeout=0.2)
    client = Node('teleop_client', context=rclpy_context, namespace='/cbha')
    targets = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    twists = client.create_publisher(TwistStamped, 'inverse_solver/delta_twist_cmds',
                                     TARGET_QOS)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: twists.get_subscription_count() > 0
                          and targets.get_subscription_count() > 0, 10.0)
        targets.publish(target_point(CENTER))
        spin_for(executor, 0.5)
        started = time.monotonic()
        while time.monotonic() < started + 1.0:
            twists.publish(_twist(speed))
            spin_for(executor, 0.02)
        twists.publish(_twist(0.0))
        ended = time.monotonic()
        spin_for(executor, 0.5)
        integrated = CENTER + [0.0, speed * (ended - started), 0.0]
        after_stream = np.array(solver.target, dtype=float)
        tip = _tip(solver)
        # a stream that stops without a zero twist: the target moves until the timeout only
        gap_start = time.monotonic()
        while time.monotonic() < gap_start + 0.3:
            twists.publish(_twist(-speed))
            spin_for(executor, 0.02)
        last = time.monotonic()
        spin_for(executor, 0.3)
        at_timeout = np.array(solver.target, dtype=float)
        spin_for(executor, 0.2)
        held = np.array(solver.target, dtype=float)
    assert np.linalg.norm(after_stream - integrated) <= 0.001
    assert np.linalg.norm(tip - integrated) <= 0.001
    np.testing.assert_array_equal(held, at_timeout)
    travelled = after_stream[1] - at_timeout[1]
    assert speed * (last - gap_start) - 0.001 <= travelled <= speed * (last - gap_start + 0.25)


def test_a_20_s_scripted_twist_stream_ends_at_its_integral(rclpy_context):
    """A twist turning on a 8 mm circle for 2.5 turns (20 s): target and tip at its integral."""
    radius, period, duration = 0.008, 8.0, 20.0
    solver = _solver(rclpy_context, teleop_timeout=0.2)
    client = Node('teleop_client', context=rclpy_context, namespace='/cbha')
    targets = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    twists = client.create_publisher(TwistStamped, 'inverse_solver/delta_twist_cmds',
                                     TARGET_QOS)
    omega = 2.0 * np.pi / period
    integral = np.zeros(3)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: twists.get_subscription_count() > 0
                          and targets.get_subscription_count() > 0, 10.0)
        targets.publish(target_point(CENTER))
        spin_for(executor, 0.5)
        started = sent = time.monotonic()
        velocity = np.zeros(3)
        while sent < started + duration:
            now = time.monotonic()
            integral += velocity * (now - sent)     # the last twist held since it was sent
            sent = now
            phase = omega * (now - started)
            velocity = radius * omega * np.array([0.0, -np.sin(phase), np.cos(phase)])
            message = _twist(velocity[1])
            message.twist.linear.z = float(velocity[2])
            twists.publish(message)
            spin_for(executor, 0.02)
        integral += velocity * (time.monotonic() - sent)
        twists.publish(_twist(0.0))
        spin_for(executor, 0.5)
        target = np.array(solver.target, dtype=float)
        tip = _tip(solver)
    assert np.linalg.norm(integral) > 0.015     # half a turn short of closing: 2 r away
    assert np.linalg.norm(target - (CENTER + integral)) <= 0.001, target - CENTER - integral
    assert np.linalg.norm(tip - target) <= 0.001, tip - target


@pytest.mark.timing
def test_closed_loop_goal_reaches_and_a_plant_fault_violates_the_path_tolerance(rclpy_context):
    """
    Closed loop on ``cbha_sim``: a goal reached at the true tip, a stuck valve aborts the next.

    A goal ends inside its goal tolerance at the plant's true tip; a valve stuck shut mid-path
    (the plant's ``valve_stuck``) aborts the next goal with PATH_TOLERANCE_VIOLATED.
    """
    from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
    names = list(load_scene(TENDON).actuator_names)
    solver = _solver(rclpy_context, mode='closed', valve_names=names)
    plant = make_node(CbhaSimNode, rclpy_context, scene=TENDON, valve_names=names,
                      noise_std=0.0001)
    client = Node('goal_client', context=rclpy_context, namespace='/cbha')
    action = ActionClient(client, FollowJointTrajectory, ACTION)
    truth = []
    client.create_subscription(PointStamped, 'tip/true', lambda m: truth.append(
        [m.point.x, m.point.y, m.point.z]), MEASURED_QOS)
    path = CENTER + [[0.0, 0.005, 0.0], [0.0, 0.005, 0.008]]
    with spinning(rclpy_context, solver, plant, client) as executor:
        assert spin_until(executor, lambda: action.server_is_ready() and truth, 10.0)
        handle = send_goal(executor, action, trajectory_goal(
            'tip', path, [0.5, 1.0], goal_tolerance=0.001, goal_time_tolerance=2.0))
        status, result = wait_result(executor, handle)
        reached = np.array(truth[-1])
        handle = send_goal(executor, action, trajectory_goal(
            'tip', [CENTER, CENTER + [0.0, 0.02, 0.0]], [0.5, 1.5], path_tolerance=0.002))
        spin_for(executor, 0.8)
        assert set_parameters(plant, valve_stuck=1).successful     # tip_90, pulls toward +y
        fault_status, fault = wait_result(executor, handle)
    assert status == SUCCEEDED, result.error_string
    assert np.linalg.norm(reached - path[-1]) <= 0.001
    assert fault_status == ABORTED and fault.error_code == goals.PATH_TOLERANCE_VIOLATED
    # after the fault (0.8 s into the goal), not before: the healthy loop stayed in tolerance
    at = float(fault.error_string.split('from its path at ')[1].split(' s')[0])
    assert at >= 0.7, fault.error_string
    assert solver.decision == 'run'


def _goto(executor, *arguments):
    """Run ``cbha_goto`` as a user does while ``executor`` spins; return (status, output)."""
    process = subprocess.Popen([sys.executable, '-m', 'cbha_inverse.ros.console.goto',
                                *arguments], cwd=REPO_ROOT, env=child_env(),
                               stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert spin_until(executor, lambda: process.poll() is not None, 60.0)
    finally:
        if process.poll() is None:
            process.kill()
    return process.returncode, process.communicate()[0]


def test_cbha_goto_exits_0_when_reached_and_1_with_the_reason(rclpy_context):
    solver = _solver(rclpy_context)
    with spinning(rclpy_context, solver) as executor:
        x, y, z = CENTER + [0.0, 0.008, 0.0]
        reached, output = _goto(executor, str(x), str(y), str(z), '--speed', '0.01',
                                '--tolerance', '0.0005')
        final = _tip(solver)
        refused, refusal = _goto(executor, str(x), '0.12', str(z))
    assert reached == 0, output
    assert 'mm to go' in output and 'SUCCESSFUL: reached: tip ' in output
    assert np.linalg.norm(final - [x, y, z]) <= 0.0005
    assert refused == 1 and 'INVALID_GOAL: waypoint 0: tip at' in refusal, refusal


def test_the_trajectory_node_sends_its_square_as_one_goal(rclpy_context):
    from cbha_inverse.ros.nodes.trajectory import TrajectoryNode
    solver = _solver(rclpy_context)
    path = make_node(TrajectoryNode, rclpy_context, action=True, shape='square', side=0.01,
                     speed=0.02, laps=1, center=list(CENTER))
    with spinning(rclpy_context, solver, path) as executor:
        assert spin_until(executor, path.done.done, 20.0)
        final = _tip(solver)
    assert path.done.result() == 0
    waypoints = path.goal.goal.multi_dof_trajectory.points
    assert len(waypoints) == 6      # the start, four corners, the start again
    corner = waypoints[1].transforms[0].translation
    np.testing.assert_allclose([corner.x, corner.y, corner.z], CENTER + [0.0, 0.005, 0.005])
    np.testing.assert_allclose(waypoints[-1].time_from_start.sec
                               + 1e-9 * waypoints[-1].time_from_start.nanosec, 0.04 / 0.02)
    assert np.linalg.norm(final - (CENTER + [0.0, 0.005, 0.0])) <= 0.001


def test_the_pick_and_place_example_runs_its_moves(rclpy_context):
    solver = _solver(rclpy_context)
    pick, place = CENTER + [0.0, 0.005, 0.0], CENTER + [0.0, -0.005, 0.0]
    script = REPO_ROOT / 'docs' / 'examples' / 'pick_and_place.py'
    process = subprocess.Popen(
        [sys.executable, str(script), '--pick', *map(str, pick), '--place', *map(str, place),
         '--lift', '0.005', '--speed', '0.02'], cwd=REPO_ROOT, env=child_env(),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    with spinning(rclpy_context, solver) as executor:
        try:
            assert spin_until(executor, lambda: process.poll() is not None, 60.0)
        finally:
            if process.poll() is None:
                process.kill()
        final = _tip(solver)
    output = process.communicate()[0]
    assert process.returncode == 0, output
    assert output.count('reached: tip') == 5 and 'open the gripper' in output, output
    assert np.linalg.norm(final - (place + [0.0, 0.0, 0.005])) <= 0.001


def test_teleop_pose_targets_and_the_speed_limit(rclpy_context):
    from geometry_msgs.msg import PoseStamped
    limit = 0.02
    solver = _solver(rclpy_context, teleop_max_speed=limit)
    client = Node('teleop_client', context=rclpy_context, namespace='/cbha')
    targets = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    twists = client.create_publisher(TwistStamped, 'inverse_solver/delta_twist_cmds',
                                     TARGET_QOS)
    poses = client.create_publisher(PoseStamped, 'inverse_solver/pose_target_cmds', TARGET_QOS)
    pose = PoseStamped()
    pose.header.frame_id = 'cbha_base'
    goal = CENTER + [0.0, 0.0, 0.006]
    pose.pose.position.x, pose.pose.position.y, pose.pose.position.z = (float(v) for v in goal)
    path = []
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: poses.get_subscription_count() > 0
                          and targets.get_subscription_count() > 0, 10.0)
        targets.publish(target_point(CENTER))
        spin_for(executor, 0.3)
        started = time.monotonic()
        while time.monotonic() < started + 0.6:
            poses.publish(pose)
            spin_for(executor, 0.02)
            path.append(np.array(solver.target, dtype=float))
        reached = np.array(solver.target, dtype=float)
        fast = time.monotonic()
        while time.monotonic() < fast + 0.3:
            twists.publish(_twist(1.0))         # 50 times the limit
            spin_for(executor, 0.02)
        twists.publish(_twist(0.0))
        pushed = time.monotonic() - fast
        spin_for(executor, 0.1)
        after_twist = np.array(solver.target, dtype=float)
        twists.publish(_twist(float('nan')))
        assert spin_until(executor, lambda: solver.rejected.get('delta_twist_cmds.non_finite'),
                          5.0)
        spin_for(executor, 0.1)
        np.testing.assert_array_equal(solver.target, after_twist)
    np.testing.assert_allclose(reached, goal, atol=1e-12)
    steps = np.linalg.norm(np.diff(path, axis=0), axis=1)
    assert steps.max() <= limit * 0.1 + 1e-12     # MAX_TELEOP_STEP_S bounds a late tick
    assert 0.0 < after_twist[1] - reached[1] <= limit * (pushed + 0.05)


def test_two_effectors_one_topic_each_and_one_goal_of_both(rclpy_context):
    """``tendon_10f_16c`` (vertebra_2 and tip): targets/<effector> sets its row, a goal both."""
    solver = make_node(InverseSolverNode, rclpy_context, scene='tendon_10f_16c',
                       max_pressure=10.0, reach_samples=0)
    client = Node('goal_client', context=rclpy_context, namespace='/cbha')
    mid_targets = client.create_publisher(PointStamped, 'targets/vertebra_2', TARGET_QOS)
    action = ActionClient(client, FollowJointTrajectory, ACTION)
    mid, tip = np.array([0.078, 0.002, -0.0067]), np.array([0.1946, 0.004, -0.0288])
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: action.server_is_ready()
                          and mid_targets.get_subscription_count() > 0, 10.0)
        rest = solver.solver.effector_positions().copy()
        mid_targets.publish(target_point(mid))
        assert spin_until(executor, lambda: solver.target is not None, 5.0)
        first = np.array(solver.target)
        goal = trajectory_goal('tip', [tip], [1.0], goal_tolerance=0.001)
        goal.multi_dof_trajectory.joint_names = ['vertebra_2', 'tip']
        point = goal.multi_dof_trajectory.points[0]
        point.transforms = [type(point.transforms[0])(), point.transforms[0]]
        point.transforms[0].translation.x, point.transforms[0].translation.y = mid[0], mid[1]
        point.transforms[0].translation.z = mid[2]
        goal.goal_tolerance.append(type(goal.goal_tolerance[0])(name='vertebra_2',
                                                                position=0.001))
        status, result = wait_result(executor, send_goal(executor, action, goal))
        final = solver.solver.effector_positions().copy()
    np.testing.assert_array_equal(first[0], mid)
    np.testing.assert_array_equal(first[1], rest[1])
    assert status == SUCCEEDED, result.error_string
    assert 'vertebra_2' in result.error_string and 'tip' in result.error_string
    assert np.linalg.norm(final - [mid, tip], axis=1).max() <= 0.001


def test_a_goal_is_aborted_when_the_controller_stops(rclpy_context):
    from std_srvs.srv import Trigger
    solver = _solver(rclpy_context)
    client = Node('goal_client', context=rclpy_context, namespace='/cbha')
    action = ActionClient(client, FollowJointTrajectory, ACTION)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, action.server_is_ready, 10.0)
        handle = send_goal(executor, action, trajectory_goal(
            'tip', [CENTER, CENTER + [0.0, 0.01, 0.0]], [0.5, 2.0]))
        spin_for(executor, 0.5)
        solver._safe_state('hold', Trigger.Response())
        status, result = wait_result(executor, handle)
    assert status == ABORTED and result.error_string.startswith('controller stopped (hold')


def test_ctrl_c_of_cbha_goto_cancels_its_goal_quietly(rclpy_context):
    solver = _solver(rclpy_context)
    x, y, z = CENTER + [0.0, 0.01, 0.0]
    process = subprocess.Popen([sys.executable, '-m', 'cbha_inverse.ros.console.goto', str(x),
                                str(y), str(z), '--speed', '0.002'], cwd=REPO_ROOT,
                               env=child_env(), stdout=subprocess.PIPE,
                               stderr=subprocess.STDOUT, text=True)
    with spinning(rclpy_context, solver) as executor:
        try:
            assert spin_until(executor, lambda: solver.commanding.run is not None
                              and solver.commanding.run.ticks > 50, 30.0)
            process.send_signal(signal.SIGINT)
            assert spin_until(executor, lambda: process.poll() is not None, 20.0)
        finally:
            if process.poll() is None:
                process.kill()
        assert spin_until(executor, lambda: solver.commanding.run is None, 5.0)
    output = process.communicate()[0]
    assert process.returncode == 128 + signal.SIGINT, output
    assert 'goal canceled, the arm holds' in output and 'Traceback' not in output, output
