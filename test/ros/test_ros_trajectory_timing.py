"""
``trajectory`` over real DDS: the publication period and the speed along the path.

Both within 2 % of the parameters, measured on the stamps and points of the published targets.
"""

from cbha_inverse.ros.common.qos import TARGET_QOS
from cbha_inverse.ros.nodes.trajectory import TrajectoryNode
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.node import Node
from ros_helpers import make_node, spin_until, spinning, stamp_seconds


def test_trajectory_period_and_speed_on_stamps(rclpy_context):
    """
    Period and speed within 2 % of the parameters, from the stamps and points of 60 targets.

    Period: the median stamp difference, and the mean rate may not exceed the set one. Speed:
    the least-squares slope of the arc length (from each point's angle on the circle) over the
    stamps (the node stamps each point with the time it sampled it at).
    """
    rate, speed, radius = 20.0, 0.04, 0.06
    tolerance = 0.02
    center = np.array([0.2, 0.0, -0.01])
    node = make_node(TrajectoryNode, rclpy_context, center=center.tolist(), rate_hz=rate,
                     speed=speed, radius=radius)
    listener = Node('listener', context=rclpy_context)
    received = []
    listener.create_subscription(PointStamped, '/cbha/target', received.append, TARGET_QOS)
    with spinning(rclpy_context, node, listener) as executor:
        assert spin_until(executor, lambda: len(received) >= 60, timeout=30.0)
    stamps = np.array([stamp_seconds(m) for m in received])
    points = np.array([[m.point.x, m.point.y, m.point.z] for m in received])
    # the timer fires on the grid t0 + k T: a late callback gives one long and one short
    # difference, a missed tick one double difference, so the median difference is T; and no
    # load makes a timer fire more often than 1 / T on average (delays only drop ticks)
    period = np.median(np.diff(stamps))
    mean_rate = (stamps.size - 1) / (stamps[-1] - stamps[0])
    angle = np.unwrap(np.arctan2(points[:, 2] - center[2], points[:, 1] - center[1]))
    measured_speed = np.polyfit(stamps - stamps[0], radius * angle, 1)[0]
    print(f'period {period * 1e3:.3f} ms (set {1e3 / rate:g}), speed {measured_speed:.5f} m/s '
          f'(set {speed:g})')
    assert period == pytest.approx(1.0 / rate, rel=tolerance)
    assert mean_rate < (1.0 + tolerance) * rate
    assert measured_speed == pytest.approx(speed, rel=tolerance)
