"""
Targets in a frame of ``/tf_static`` over real DDS: transformed into ``cbha_base``, or refused.

``cbha_static_transform`` (a process, as a user starts it) latches a ``table`` frame on
``/tf_static``; ``inverse_solver`` started afterwards receives it, takes a target given in
``table`` as the same point in ``cbha_base`` (the frame's transform applied here with scipy),
and refuses a target in a frame nobody published, counting it under ``target.unknown_frame``.
"""

import signal
import subprocess
import sys

from cbha_inverse.ros.common.qos import TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import child_env, REPO_ROOT, spin_until, spinning
from scipy.spatial.transform import Rotation

TABLE = {'x': 0.05, 'y': -0.02, 'z': 0.01, 'roll': 0.3, 'pitch': -0.2, 'yaw': 1.1}
BASE_TARGET = np.array([0.117, 0.004, -0.008])
"""A reachable target of the tendon trunk in ``cbha_base`` [m]."""


def _point(xyz, frame):
    message = PointStamped()
    message.header.frame_id = frame
    message.point.x, message.point.y, message.point.z = (float(v) for v in xyz)
    return message


def test_a_target_in_a_static_frame_is_transformed_and_an_unknown_frame_refused(
        rclpy_context):
    rotation = Rotation.from_euler('xyz', [TABLE['roll'], TABLE['pitch'], TABLE['yaw']])
    translation = np.array([TABLE['x'], TABLE['y'], TABLE['z']])
    in_table = rotation.inv().apply(BASE_TARGET - translation)
    arguments = [f'--{name}={value}' for name, value in TABLE.items()]
    publisher = subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.console.static_transform', *arguments,
         '--frame-id', 'cbha_base', '--child-frame-id', 'table'], cwd=REPO_ROOT,
        env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        assert 'table in cbha_base' in publisher.stdout.readline()
        solver = InverseSolverNode(context=rclpy_context, namespace='/cbha', parameter_overrides=[
            Parameter('scene', value='tendon_6f_8c'), Parameter('max_pressure', value=10.0)])
        client = Node('frames_client', context=rclpy_context, namespace='/cbha')
        targets = client.create_publisher(PointStamped, 'target', TARGET_QOS)
        with spinning(rclpy_context, solver, client) as executor:
            assert spin_until(executor, lambda: targets.get_subscription_count() > 0
                              and solver.static_tf.received > 0, 10.0)
            targets.publish(_point(in_table, 'table'))
            assert spin_until(executor, lambda: solver.target is not None, 5.0)
            np.testing.assert_allclose(solver.target, BASE_TARGET, atol=1e-12)
            targets.publish(_point(BASE_TARGET, 'shelf'))
            assert spin_until(executor, lambda: solver.rejected.get('target.unknown_frame'),
                              5.0)
    finally:
        publisher.send_signal(signal.SIGINT)
        output = publisher.communicate(timeout=30)[0]
    assert publisher.returncode == 0, output
    assert 'Traceback' not in output
