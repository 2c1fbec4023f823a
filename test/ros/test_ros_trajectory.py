"""The ``trajectory`` node over real DDS: rate, points on the circle, bad parameters."""

import subprocess
import sys

from cbha_inverse.ros.common.params import ParameterError
from cbha_inverse.ros.common.qos import TARGET_QOS
from cbha_inverse.ros.nodes.trajectory import TrajectoryNode
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import child_env, REPO_ROOT, spin_until

CENTER = (0.2, 0.0, -0.01)


# its bounds are the timer's period: beside a worker building the interface packages (a fresh
# clone) the median period came out doubled (0.040 s at 50 Hz)
@pytest.mark.timing
def test_subscriber_receives_circle_targets_at_rate(rclpy_context):
    rate = 50.0
    node = TrajectoryNode(context=rclpy_context, namespace='/cbha', parameter_overrides=[
        Parameter('center', value=list(CENTER)), Parameter('rate_hz', value=rate),
        Parameter('speed', value=0.05)])
    listener = Node('listener', context=rclpy_context)
    received = []
    listener.create_subscription(PointStamped, '/cbha/target', received.append, TARGET_QOS)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(node)
    executor.add_node(listener)
    try:
        assert spin_until(executor, lambda: len(received) >= 40, timeout=20.0)
    finally:
        executor.shutdown()
        node.destroy_node()
        listener.destroy_node()
    assert all(msg.header.frame_id == 'cbha_base' for msg in received)
    points = np.array([[m.point.x, m.point.y, m.point.z] for m in received])
    np.testing.assert_allclose(np.linalg.norm(points - CENTER, axis=1), 0.06, atol=1e-12)
    np.testing.assert_allclose(points[:, 0], CENTER[0], atol=1e-15)
    stamps = np.array([m.header.stamp.sec + 1e-9 * m.header.stamp.nanosec for m in received])
    # the stamps are taken by the publishing timer: their median period is the configured one
    assert np.median(np.diff(stamps)) == pytest.approx(1.0 / rate, rel=0.2)
    # the path advances at the configured speed: chord between consecutive targets ~ speed * dt
    chords = np.linalg.norm(np.diff(points, axis=0), axis=1)
    assert np.median(chords / np.diff(stamps)) == pytest.approx(0.05, rel=0.2)


@pytest.mark.parametrize('override, match', [
    (Parameter('radius', value=-0.06), 'radius'),
    (Parameter('speed', value=0.0), 'speed'),
    (Parameter('shape', value='triangle'), 'shape'),
    (Parameter('center', value=[0.0, 0.0]), 'center'),
])
def test_bad_parameters_fail_at_construction(rclpy_context, override, match):
    with pytest.raises(ParameterError, match=match):
        TrajectoryNode(context=rclpy_context, parameter_overrides=[override])


def test_bad_params_file_exits_nonzero_with_message(tmp_path):
    params = tmp_path / 'trajectory.yaml'
    params.write_text('/**:\n  ros__parameters:\n    radius: 60\n')
    result = subprocess.run(
        [sys.executable, '-m', 'cbha_inverse.ros.nodes.trajectory', '--ros-args',
         '--params-file', str(params)],
        cwd=REPO_ROOT, env=child_env(), capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert 'radius' in result.stderr and 'must be of type double' in result.stderr
