"""
Pick and place with ``inverse_solver``'s ``~/follow_trajectory`` action (``docs/commanding.md``).

A plain rclpy client, as a user writes one: each move is one
``control_msgs/action/FollowJointTrajectory`` goal of the ``tip`` effector (its
``multi_dof_trajectory``), sent when the previous one succeeded. Above the pick point, down,
(close the gripper), up, across to above the place point, down, (open the gripper), up. The
gripper is not modelled: a pause stands for it. Any goal that does not succeed stops the
sequence with its result code and reason (exit 1); Ctrl-C cancels the running goal (the arm
holds where it is).

    python3 docs/examples/pick_and_place.py --pick 0.2308 0.02 -0.03 --place 0.2308 -0.02 -0.03

Options: ``--lift`` [m] the height of the moves above the points (+z, against gravity: the CBHA
hangs horizontally along +x), ``--speed`` [m/s], ``--tolerance`` [m], ``--namespace``.
"""

import argparse
import math
import sys
import time

from control_msgs.action import FollowJointTrajectory
from control_msgs.msg import JointTolerance
from geometry_msgs.msg import Transform, Vector3
import rclpy
from rclpy.action import ActionClient
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from trajectory_msgs.msg import MultiDOFJointTrajectoryPoint

SUCCEEDED = 4   # action_msgs/GoalStatus


def tip_goal(points, speed, tolerance, start=None):
    """Return a goal of the tip through ``points`` at ``speed`` (times from the distances)."""
    goal = FollowJointTrajectory.Goal()
    goal.multi_dof_trajectory.header.frame_id = 'cbha_base'
    goal.multi_dof_trajectory.joint_names = ['tip']
    elapsed, previous = 0.0, start
    for point in points:
        # the first point's time: 0 lets the node's approach_speed pace the approach
        if previous is not None:
            elapsed += math.dist(previous, point) / speed
        previous = point
        waypoint = MultiDOFJointTrajectoryPoint()
        x, y, z = (float(v) for v in point)
        waypoint.transforms = [Transform(translation=Vector3(x=x, y=y, z=z))]
        waypoint.time_from_start = Duration(seconds=elapsed).to_msg()
        goal.multi_dof_trajectory.points.append(waypoint)
    goal.goal_tolerance = [JointTolerance(name='tip', position=tolerance)]
    return goal


def run(node, client, moves, speed, tolerance):
    """Send the moves one after the other; return the exit status."""
    if not client.wait_for_server(timeout_sec=10.0):
        print('no follow_trajectory action server', file=sys.stderr)
        return 1
    here = None
    for name, points in moves:
        if points is None:
            print(f'{name}', flush=True)
            time.sleep(0.3)     # the gripper would close or open here
            continue
        sent = client.send_goal_async(tip_goal(points, speed, tolerance, here))
        rclpy.spin_until_future_complete(node, sent)
        handle = sent.result()
        try:
            answer = handle.get_result_async()
            rclpy.spin_until_future_complete(node, answer)
        except KeyboardInterrupt:
            rclpy.spin_until_future_complete(node, handle.cancel_goal_async(), timeout_sec=2.0)
            raise
        result = answer.result()
        print(f'{name}: {result.result.error_string}', flush=True)
        if result.status != SUCCEEDED:
            print(f'{name} failed (code {result.result.error_code})', file=sys.stderr)
            return 1
        here = points[-1]
    return 0


def main(argv=None):
    """Run the pick-and-place sequence."""
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--pick', type=float, nargs=3, default=(0.2308, 0.02, -0.03))
    parser.add_argument('--place', type=float, nargs=3, default=(0.2308, -0.02, -0.03))
    parser.add_argument('--lift', type=float, default=0.01)
    parser.add_argument('--speed', type=float, default=0.02)
    parser.add_argument('--tolerance', type=float, default=0.001)
    parser.add_argument('--namespace', default='/cbha')
    args = parser.parse_args(argv)
    pick, place = tuple(args.pick), tuple(args.place)
    above_pick = (*pick[:2], pick[2] + args.lift)
    above_place = (*place[:2], place[2] + args.lift)
    moves = [('above the pick point', [above_pick]), ('down to pick', [pick]),
             ('close the gripper', None), ('up and across', [above_pick, above_place]),
             ('down to place', [place]), ('open the gripper', None),
             ('up', [above_place])]
    # Ctrl-C raises KeyboardInterrupt and leaves the context up: the goal can still be canceled
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    node = Node('pick_and_place', namespace=args.namespace)
    client = ActionClient(node, FollowJointTrajectory, 'inverse_solver/follow_trajectory')
    try:
        return run(node, client, moves, args.speed, args.tolerance)
    except KeyboardInterrupt:
        return 130
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == '__main__':
    sys.exit(main())
