"""
Helpers for the tests of ``~/follow_trajectory``: goals of effector positions, their results.

rclpy and the message packages are imported inside the functions (see ``ros_helpers``).
"""

from ros_helpers import spin_until


def trajectory_goal(effector, points, times, goal_tolerance=0.0, path_tolerance=0.0,
                    goal_time_tolerance=0.0):
    """
    Return a FollowJointTrajectory goal of one effector through ``points`` at ``times``.

    Parameters
    ----------
    effector : str
        The effector's name.
    points : (n, 3) array_like  [m]
        The waypoints.
    times : (n,) array_like  [s]
        Their ``time_from_start``.
    goal_tolerance, path_tolerance : float  [m]
        The effector's tolerances (0: the node's default).
    goal_time_tolerance : float  [s]
        0: the node's default.

    """
    from control_msgs.action import FollowJointTrajectory
    from control_msgs.msg import JointTolerance
    from geometry_msgs.msg import Transform, Vector3
    from rclpy.duration import Duration
    from trajectory_msgs.msg import MultiDOFJointTrajectoryPoint
    goal = FollowJointTrajectory.Goal()
    goal.multi_dof_trajectory.joint_names = [effector]
    for point, time in zip(points, times):
        waypoint = MultiDOFJointTrajectoryPoint()
        x, y, z = (float(v) for v in point)
        waypoint.transforms = [Transform(translation=Vector3(x=x, y=y, z=z))]
        waypoint.time_from_start = Duration(seconds=float(time)).to_msg()
        goal.multi_dof_trajectory.points.append(waypoint)
    goal.goal_tolerance = [JointTolerance(name=effector, position=float(goal_tolerance))]
    goal.path_tolerance = [JointTolerance(name=effector, position=float(path_tolerance))]
    goal.goal_time_tolerance = Duration(seconds=float(goal_time_tolerance)).to_msg()
    return goal


def send_goal(executor, client, goal, feedback=None, timeout=10.0):
    """Send a goal, spin until it is accepted; return its handle."""
    future = client.send_goal_async(goal, feedback_callback=feedback)
    assert spin_until(executor, future.done, timeout), 'no answer to the goal'
    handle = future.result()
    assert handle.accepted
    return handle


def wait_result(executor, handle, timeout=20.0):
    """Spin until a goal ends; return (status, result)."""
    future = handle.get_result_async()
    assert spin_until(executor, future.done, timeout), 'the goal did not end'
    return future.result().status, future.result().result
