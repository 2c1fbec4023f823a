"""
``cbha_goto X Y Z [--axis AX AY AZ]``: move one effector of ``inverse_solver`` there (its action).

Sends one ``~/follow_trajectory`` goal (``docs/commanding.md``): the effector ``--effector``
(default ``tip``) to (X, Y, Z) [m] in ``cbha_base``, with ``--tolerance`` as its goal tolerance,
and prints its progress on one line (the effector's distance to the point, to its path, the
angle of its axis to the direction with ``--axis``, and the actuators at a bound) until the goal
ends. Without ``--speed`` the node's ``approach_speed`` bounds the motion; with it, the first
feedback gives where the effector is and the goal is sent again with its time set for that
speed (never faster than ``approach_speed``).

``--axis AX AY AZ`` turns the approach axis of an ``axis`` effector (``docs/effectors.md``) to
that direction of ``cbha_base`` (normalised), within ``--angle-tolerance``: the node's ``scene``
parameter gives the effector's kind and axis (its scene file must be readable here). Without
``--axis`` the goal frees the orientation (its goal angle tolerance is < 0): an ``axis`` or
``pose`` effector keeps its orientation target.

Exit status: 0 reached within the tolerance; 1 not reached (the goal refused, e.g. beyond the
reach, or a tolerance violated: the reason on stderr), no action server within ``--timeout`` or
no feedback for that long while the goal runs, the node's scene not readable for ``--axis``; 2
bad arguments (``--axis`` of an effector that is not an ``axis`` effector); 128 + the signal
number after SIGINT/SIGTERM, which cancels the goal first (the arm holds where it is). ROS
arguments after ``--ros-args`` (``-r __ns:=/left``). ``--help`` starts no ROS.
"""

import argparse
import math
import os
import signal
import sys
import time

from cbha_inverse.robot.goals import CODE_NAMES, SUCCESSFUL
from cbha_inverse.ros.common.loading import loaded, split_ros_arguments

PROGRAM = 'cbha_goto'
POLL_S = 0.05
"""Longest spin slice [s]: how soon a stop signal or an answer is noticed."""
SUCCEEDED = 4
"""action_msgs/GoalStatus of a goal that succeeded."""


def _parser():
    parser = argparse.ArgumentParser(
        prog=PROGRAM, description=__doc__.strip().splitlines()[0],
        epilog='Exit status: 0 reached, 1 not reached, 2 bad arguments, 130 Ctrl-C. ROS '
        'arguments after --ros-args (e.g. -r __ns:=/left).')
    for axis in 'XYZ':
        parser.add_argument(axis.lower(), metavar=axis, type=float, help=f'{axis} [m] in '
                            'cbha_base')
    parser.add_argument('--effector', default='tip', help='the effector (default tip)')
    parser.add_argument('--speed', type=float, default=None,
                        help="top speed [m/s] (default: the node's approach_speed)")
    parser.add_argument('--tolerance', type=float, default=0.001,
                        help='goal tolerance [m] (default 0.001)')
    parser.add_argument('--axis', type=float, nargs=3, default=None,
                        metavar=('AX', 'AY', 'AZ'),
                        help='approach direction of an axis effector in cbha_base (normalised; '
                        'default: its orientation target is kept)')
    parser.add_argument('--angle-tolerance', type=float, default=0.0175,
                        help='goal angle tolerance [rad] of --axis (default 0.0175, 1 degree)')
    parser.add_argument('--timeout', type=float, default=10.0,
                        help='seconds to wait for the node, and for the result beyond the '
                        'motion (default 10)')
    parser.add_argument('--node', default='inverse_solver',
                        help='the controller node (default inverse_solver, in /cbha)')
    parser.add_argument('-n', '--namespace', default='/cbha', help='its namespace')
    return parser


def make_goal(effector, point, tolerance, time_from_start=0.0, quaternion=None,
              angle_tolerance=0.0):
    """
    Return the FollowJointTrajectory goal of one effector to one point.

    Parameters
    ----------
    effector : str
        The effector's name.
    point : (3,) sequence of float  [m]
        Where, in ``cbha_base``.
    tolerance : float  [m]
        Its goal tolerance.
    time_from_start : float  [s]
        When it is due (0: at the node's approach speed).
    quaternion : (4,) sequence of float, optional
        The orientation ``(x, y, z, w)`` of the effector's frame in ``cbha_base`` (its
        ``angle_tolerance`` [rad] as the goal angle tolerance); None: the orientation is free
        (a goal angle tolerance of -1).
    angle_tolerance : float  [rad]
        With ``quaternion``.

    """
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointComponentTolerance, JointTolerance
    from geometry_msgs.msg import Quaternion, Transform, Vector3
    from rclpy.duration import Duration
    from trajectory_msgs.msg import MultiDOFJointTrajectoryPoint
    goal = FollowJointTrajectory.Goal()
    goal.multi_dof_trajectory.joint_names = [effector]
    waypoint = MultiDOFJointTrajectoryPoint()
    x, y, z = (float(v) for v in point)
    qx, qy, qz, qw = (0.0, 0.0, 0.0, 1.0) if quaternion is None else (float(v)
                                                                      for v in quaternion)
    waypoint.transforms = [Transform(translation=Vector3(x=x, y=y, z=z),
                                     rotation=Quaternion(x=qx, y=qy, z=qz, w=qw))]
    waypoint.time_from_start = Duration(seconds=float(time_from_start)).to_msg()
    goal.multi_dof_trajectory.points = [waypoint]
    goal.goal_tolerance = [JointTolerance(name=effector, position=float(tolerance))]
    goal.component_goal_tolerance = [JointComponentTolerance(
        joint_name=effector, component=JointComponentTolerance.ROTATION,
        position=-1.0 if quaternion is None else float(angle_tolerance))]
    return goal


def axis_quaternion(axis, direction):
    """
    Return the quaternion of the least rotation carrying an effector's axis to a direction.

    Parameters
    ----------
    axis : (3,) array_like
        The effector's unit axis in its frame.
    direction : (3,) array_like
        The unit direction in ``cbha_base``.

    Returns
    -------
    (4,) ndarray
        ``(x, y, z, w)``: the frame's orientation whose axis points along ``direction``.

    """
    from cbha_inverse.core.so3 import quat_from_matrix, shortest_rotation, so3_exp
    return quat_from_matrix(so3_exp(shortest_rotation(axis, direction)))


def progress_line(feedback, point, axis=None, direction=None):
    """
    Return the one-line progress of a feedback message toward ``point`` (3,) [m].

    With an effector's ``axis`` (3,) (in its frame) and a ``direction`` (3,) of ``cbha_base``,
    the line gives the angle of the actual axis to that direction and to its path too.
    """
    actual = feedback.multi_dof_actual.transforms[0].translation
    error = feedback.multi_dof_error.transforms[0].translation
    left = math.dist((actual.x, actual.y, actual.z), point)
    off = math.sqrt(error.x ** 2 + error.y ** 2 + error.z ** 2)
    saturated = ','.join(feedback.joint_names) or 'none'
    turn = ''
    if axis is not None:
        from cbha_inverse.core.so3 import matrix_from_quat, shortest_rotation, so3_log_angle
        q = feedback.multi_dof_actual.transforms[0].rotation
        left_angle = math.hypot(*shortest_rotation(
            matrix_from_quat([q.x, q.y, q.z, q.w]) @ axis, direction))
        q = feedback.multi_dof_error.transforms[0].rotation
        off_angle = so3_log_angle(matrix_from_quat([q.x, q.y, q.z, q.w]))[1]
        turn = (f', axis {math.degrees(left_angle):5.2f} deg to go, '
                f'{math.degrees(off_angle):4.2f} deg off the path')
    return (f'{feedback.multi_dof_joint_names[0]}: {1e3 * left:7.2f} mm to go, '
            f'{1e3 * off:6.2f} mm off the path{turn}, at a bound: {saturated}')


def effector_axis(scene_name, effector):
    """
    Return the axis (3,) of an ``axis`` effector of a scene, or raise with a one-line reason.

    Parameters
    ----------
    scene_name : str
        The node's ``scene`` parameter (a name in ``config/scenes`` or a file path).
    effector : str
        The effector.

    Raises
    ------
    LookupError
        The scene cannot be read here, or has no such effector.
    ValueError
        The effector is not an ``axis`` effector.

    """
    from cbha_inverse.errors import ConfigError
    from cbha_inverse.scene import load_scene
    try:
        effectors = load_scene(scene_name).effectors
    except (OSError, ConfigError) as exc:
        raise LookupError(f'the scene {scene_name!r} of the node cannot be read here ({exc})') \
            from None
    if effector not in effectors.names:
        raise LookupError(f'scene {scene_name!r} has no effector {effector!r} (it has '
                          f'{list(effectors.names)})')
    index = effectors.names.index(effector)
    if effectors.kinds[index] != 'axis':
        raise ValueError(f'{effector} is a {effectors.kinds[index]} effector of scene '
                         f'{scene_name!r}, not an axis effector')
    return effectors.axes[index]


class _Goal:
    """One goal's handle, last feedback and result future."""

    def __init__(self):
        self.sent = None
        self.handle = None
        self.result = None
        self.feedback = None


def _scene_of(node, name, spin_until, timeout):
    """Return the ``scene`` parameter of the node ``name``, or raise LookupError."""
    from rclpy.parameter_client import AsyncParameterClient
    client = AsyncParameterClient(node, name)
    if not spin_until(client.services_are_ready, timeout):
        raise LookupError(f'the parameter services of {name} are not ready within {timeout:g} s')
    future = client.get_parameters(['scene'])
    if not spin_until(future.done, timeout) or future.result() is None:
        raise LookupError(f'no answer to get_parameters of {name} within {timeout:g} s')
    return future.result().values[0].string_value


def run(args, ros_args, out=sys.stdout):
    """Send the goal and wait for it; return the exit status."""
    import rclpy
    from cbha_inverse.ros.common.runner import StopRequest
    from control_msgs.action import FollowJointTrajectory
    from rclpy.action import ActionClient
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.signals import SignalHandlerOptions
    point = (args.x, args.y, args.z)
    loaded()
    with StopRequest() as stop:
        context = rclpy.Context()
        rclpy.init(args=[PROGRAM, *ros_args], context=context,
                   signal_handler_options=SignalHandlerOptions.NO)
        node = Node(f'cbha_goto_{os.getpid()}', namespace=args.namespace,
                    context=context, start_parameter_services=False, enable_rosout=False)
        executor = SingleThreadedExecutor(context=context)
        executor.add_node(node)
        name = args.node if args.node.startswith('/') else (
            f"{node.get_namespace().rstrip('/')}/{args.node}")
        client = ActionClient(node, FollowJointTrajectory, f'{name}/follow_trajectory')

        def spin_until(done, timeout):
            deadline = time.monotonic() + timeout
            while not done() and not stop.requested and time.monotonic() < deadline:
                executor.spin_once(timeout_sec=POLL_S)
            return done()

        def send(time_from_start):
            goal = _Goal()
            goal.sent = client.send_goal_async(
                make_goal(args.effector, point, args.tolerance, time_from_start, quaternion,
                          args.angle_tolerance),
                feedback_callback=lambda message: setattr(goal, 'feedback', message.feedback))
            return goal

        try:
            if not spin_until(client.server_is_ready, args.timeout):
                if stop.requested:
                    return 128 + signal.Signals[stop.signal_name].value
                print(f'{PROGRAM}: no action server {name}/follow_trajectory within '
                      f'{args.timeout:g} s', file=sys.stderr)
                return 1
            quaternion = axis = None
            if args.axis is not None:
                try:
                    scene_name = _scene_of(node, name, spin_until, args.timeout)
                    axis = effector_axis(scene_name, args.effector)
                    quaternion = axis_quaternion(axis, args.axis)
                except LookupError as exc:
                    print(f'{PROGRAM}: --axis: {exc}', file=sys.stderr)
                    return 1
                except ValueError as exc:
                    print(f'{PROGRAM}: --axis: {exc}', file=sys.stderr)
                    return 2
            goal = send(0.0)
            resent = args.speed is None
            heard = time.monotonic()
            while not stop.requested:
                if time.monotonic() - heard > args.timeout:
                    print(f'\n{PROGRAM}: no feedback from {name} for {args.timeout:g} s',
                          file=sys.stderr)
                    return 1
                if goal.handle is None and goal.sent.done():
                    goal.handle = goal.sent.result()
                    goal.result = goal.handle.get_result_async()
                if goal.result is not None and goal.result.done():
                    break
                if goal.feedback is not None:
                    heard = time.monotonic()
                    print('\r' + progress_line(goal.feedback, point, axis, args.axis),
                          end='', file=out, flush=True)
                    if not resent:
                        resent = True
                        actual = goal.feedback.multi_dof_actual.transforms[0].translation
                        distance = math.dist((actual.x, actual.y, actual.z), point)
                        goal = send(distance / args.speed)
                        continue
                    goal.feedback = None
                executor.spin_once(timeout_sec=POLL_S)
            if stop.requested:
                if goal.handle is not None:
                    cancel = goal.handle.cancel_goal_async()
                    spin_until(cancel.done, 2.0)
                print(f'\n{PROGRAM}: stopped by {stop.signal_name}: goal canceled, the arm '
                      'holds', file=sys.stderr)
                return 128 + signal.Signals[stop.signal_name].value
            answer = goal.result.result().result
            print('', file=out)
            text = f'{CODE_NAMES.get(answer.error_code, answer.error_code)}: {answer.error_string}'
            if answer.error_code == SUCCESSFUL and goal.result.result().status == SUCCEEDED:
                print(text, file=out, flush=True)
                return 0
            print(f'{PROGRAM}: {text}', file=sys.stderr)
            return 1
        finally:
            client.destroy()
            executor.shutdown()
            node.destroy_node()
            rclpy.try_shutdown(context=context)


def main(argv=None):
    """
    Run ``cbha_goto``.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``); ROS arguments after ``--ros-args``.

    Returns
    -------
    int
        See the module docstring.

    """
    own, ros_args = split_ros_arguments(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(own)
    for name in ('speed', 'tolerance', 'timeout', 'angle_tolerance'):
        value = getattr(args, name)
        if value is not None and not (math.isfinite(value) and value > 0.0):
            print(f'{PROGRAM}: error: --{name.replace("_", "-")} must be a positive number',
                  file=sys.stderr)
            return 2
    if not all(math.isfinite(v) for v in (args.x, args.y, args.z)):
        print(f'{PROGRAM}: error: X Y Z must be finite', file=sys.stderr)
        return 2
    if args.axis is not None:
        size = math.hypot(*args.axis)
        if not (math.isfinite(size) and size > 0.0):
            print(f'{PROGRAM}: error: --axis must be a finite non-zero direction',
                  file=sys.stderr)
            return 2
        args.axis = [v / size for v in args.axis]
    try:
        return run(args, ros_args)
    except KeyboardInterrupt:        # a second signal
        print(f'{PROGRAM}: stopped', file=sys.stderr)
        return 130


if __name__ == '__main__':
    sys.exit(main())
