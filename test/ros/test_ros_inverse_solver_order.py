"""
``inverse_solver`` over DDS: a duplicated or reordered (older) ``tip/measured`` is not integrated.

Closed loop with a constant measured error ``e`` and gain ``g``: each integrated sample adds
``g * e`` to the correction (``TargetCorrector``). A first sample (before the target: not
integrated), then it and four newer samples each delivered twice, then three older ones: the
correction must be ``4 g e`` (12 ``g e`` if every delivery were integrated) and the eight drops
counted by reason in the diagnostics' rejection counts.
"""

import math

from cbha_inverse.ros.common.qos import MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from ros_helpers import make_node, spin_for, spin_until, spinning, target_point

TENDON = 'tendon_6f_8c'
TENDON_CENTER = (0.117, 0.0, -0.005)
"""A tip position well in the tendon trunk's reach (near its workspace centre) [m]."""


def stamped(point, seconds):
    message = target_point(point)
    message.header.stamp.sec = int(seconds)
    return message


def test_duplicated_and_older_measurements_are_dropped_and_counted(rclpy_context):
    gain, error = 0.1, np.array([0.0, 0.001, 0.0])
    names = list(load_scene(TENDON).actuator_names)
    solver = make_node(InverseSolverNode, rclpy_context, scene=TENDON, valve_names=names,
                       max_pressure=10.0, mode='closed', loop_gain=gain, feedback_timeout=5.0)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    measured_pub = client.create_publisher(PointStamped, 'tip/measured', MEASURED_QOS)
    target = np.array(TENDON_CENTER)
    deliveries = [1, 2, 2, 3, 3, 4, 4, 5, 5, 2, 3, 4]      # stamps [s] in arrival order
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and measured_pub.get_subscription_count() > 0, 10.0)
        measured_pub.publish(stamped(target - error, 1))      # closed loop: feedback first
        spin_for(executor, 0.05)
        target_pub.publish(target_point(target))
        # the first ticks from rest are off equilibrium (no integration then): settled first
        assert spin_until(executor, lambda: solver.ticks > 0
                          and solver.last_result.status == 'solved', 10.0)
        for seconds in deliveries:
            measured_pub.publish(stamped(target - error, seconds))
            spin_for(executor, 0.02)
        assert spin_until(executor, lambda: solver.rejected.get('tip/measured.older') == 3, 5.0)
        spin_for(executor, 0.05)
        # while the node exists (its statuses carry its name)
        inputs = solver._statuses()[1]
    assert solver.rejected == {'tip/measured.duplicate': 5, 'tip/measured.older': 3}
    np.testing.assert_allclose(solver.corrector.correction[0], 4 * gain * error, atol=1e-12)
    values = {v.key: v.value for v in inputs.values}
    assert values['rejected.tip/measured.duplicate'] == '5'
    assert values['rejected.tip/measured.older'] == '3'


def test_a_live_log_throttle_change_keeps_rejections_logged_and_counted(rclpy_context):
    from rclpy.parameter import Parameter
    names = list(load_scene(TENDON).actuator_names)
    solver = make_node(InverseSolverNode, rclpy_context, scene=TENDON, valve_names=names,
                       max_pressure=10.0, log_throttle=0.0)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    bad = target_point(np.array([math.nan, 0.0, 0.0]))
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0, 10.0)
        target_pub.publish(bad)
        assert spin_until(executor, lambda: sum(solver.rejected.values()) == 1, 5.0)
        assert solver.set_parameters([Parameter('log_throttle', value=2.0)])[0].successful
        target_pub.publish(bad)
        assert spin_until(executor, lambda: sum(solver.rejected.values()) == 2, 5.0)
    assert solver.rejected == {'target.non_finite': 2}
