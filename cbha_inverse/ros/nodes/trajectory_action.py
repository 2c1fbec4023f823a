"""
A path sent as one ``FollowJointTrajectory`` goal (``trajectory --action``, docs/commanding.md).

Thin rclpy shell: the timed waypoints come from :meth:`cbha_inverse.robot.trajectory.
Trajectory.waypoints`, the goal's semantics are those of :mod:`cbha_inverse.robot.goals`.
"""

import time

from cbha_inverse.robot.goals import CODE_NAMES, SUCCESSFUL
from control_msgs.action import FollowJointTrajectory
from geometry_msgs.msg import Transform, Vector3
from rclpy.action import ActionClient
from rclpy.duration import Duration
from trajectory_msgs.msg import MultiDOFJointTrajectoryPoint

SUCCEEDED = 4
"""action_msgs/GoalStatus of a goal that succeeded."""
FEEDBACK_LOG_S = 1.0
"""Least time [s] between two logged feedback messages."""


def path_goal(effector, times, points, frame_id='cbha_base'):
    """
    Return the FollowJointTrajectory goal of one effector along timed waypoints.

    Parameters
    ----------
    effector : str
        The effector's name.
    times : (n,) array_like  [s]
        The waypoints' ``time_from_start``.
    points : (n, 3) array_like  [m]
        The waypoints.
    frame_id : str
        The frame of the points (the header of ``multi_dof_trajectory``).

    """
    goal = FollowJointTrajectory.Goal()
    goal.multi_dof_trajectory.header.frame_id = frame_id
    goal.multi_dof_trajectory.joint_names = [effector]
    for time_from_start, (x, y, z) in zip(times, points):
        waypoint = MultiDOFJointTrajectoryPoint()
        waypoint.transforms = [Transform(translation=Vector3(x=float(x), y=float(y),
                                                             z=float(z)))]
        waypoint.time_from_start = Duration(seconds=float(time_from_start)).to_msg()
        goal.multi_dof_trajectory.points.append(waypoint)
    return goal


class PathGoal:
    """
    Send one path goal once its server is there; complete ``done`` with the exit code.

    Parameters
    ----------
    node : rclpy.node.Node
        The node that sends it.
    server : str
        The action's name (relative names resolve in the node's namespace).
    effector, times, points, frame_id
        As in :func:`path_goal`.
    done : rclpy.task.Future
        Gets 0 when the goal succeeded, 1 otherwise.

    """

    def __init__(self, node, server, effector, times, points, frame_id, done):
        self.node = node
        self.done = done
        self.goal = path_goal(effector, times, points, frame_id)
        self.client = ActionClient(node, FollowJointTrajectory, server)
        self.sent = None
        self.logged = -FEEDBACK_LOG_S
        self.timer = node.create_timer(0.1, self._send_when_ready)
        node.get_logger().info(f'{len(times)} waypoints of {effector} over {times[-1]:.2f} s, '
                               f'one goal of {server} once it is there')

    def _send_when_ready(self):
        if self.sent is not None or not self.client.server_is_ready():
            return
        self.timer.cancel()
        self.sent = self.client.send_goal_async(self.goal, feedback_callback=self._on_feedback)
        self.sent.add_done_callback(self._on_answer)

    def _on_feedback(self, message):
        now = time.monotonic()
        if now - self.logged < FEEDBACK_LOG_S:
            return
        self.logged = now
        feedback = message.feedback
        error = feedback.multi_dof_error.transforms[0].translation
        norm = (error.x ** 2 + error.y ** 2 + error.z ** 2) ** 0.5
        self.node.get_logger().info(f'{feedback.multi_dof_joint_names[0]} {1e3 * norm:.2f} mm '
                                    'from its path')

    def _on_answer(self, future):
        handle = future.result()
        if not handle.accepted:
            self.node.get_logger().error('the goal was not accepted')
            self.done.set_result(1)
            return
        handle.get_result_async().add_done_callback(self._on_result)

    def _on_result(self, future):
        answer = future.result()
        result = answer.result
        text = f'{CODE_NAMES.get(result.error_code, result.error_code)}: {result.error_string}'
        if answer.status == SUCCEEDED and result.error_code == SUCCESSFUL:
            self.node.get_logger().info(f'path done, {text}')
            self.done.set_result(0)
        else:
            self.node.get_logger().error(f'path not done (status {answer.status}), {text}')
            self.done.set_result(1)
