"""
``inverse_solver``'s ``payload_topic`` over DDS: the estimated payload enters the model's loads.

Each accepted message moves the model's payload by at most ``max_payload_change`` and prepares
the new load's linearisation at once, so the next target's tick only solves (its assembly time
is zero); a payload beyond ``max_payload`` or not finite is rejected and counted.
"""

import math

from cbha_inverse.ros.common.qos import MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from ros_helpers import make_node, spin_until, spinning, target_point
from std_msgs.msg import Float64

CBHA_TARGET = (0.2308, 0.0, -0.0292)
"""The demo's circle centre, in the CBHA's reach [m]."""


def test_payload_messages_walk_the_model_load_and_bad_ones_are_counted(rclpy_context):
    solver = make_node(InverseSolverNode, rclpy_context, mode='open',
                       payload_topic='payload/estimated', max_payload_change=0.02)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    payload_pub = client.create_publisher(Float64, 'payload/estimated', MEASURED_QOS)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and payload_pub.get_subscription_count() > 0, 10.0)
        target_pub.publish(target_point(CBHA_TARGET))
        assert spin_until(executor, lambda: solver.ticks == 1, 10.0)
        walked = []
        for _ in range(3):
            payload_pub.publish(Float64(data=0.05))
            assert spin_until(executor, lambda: solver.solver.payload != (
                walked[-1] if walked else 0.0), 5.0)
            walked.append(solver.solver.payload)
        target_pub.publish(target_point(CBHA_TARGET))
        assert spin_until(executor, lambda: solver.ticks == 2, 5.0)
        for bad in (2.0, -1.5, math.nan, math.inf):
            payload_pub.publish(Float64(data=bad))
        assert spin_until(executor, lambda: sum(solver.rejected.values()) == 4, 5.0)
    assert walked == [0.02, 0.04, 0.05]
    # the load was linearised when it came, not in the target's tick
    assert solver.last_result.timings['assembly'] == 0.0
    # the new load moved the model's equilibrium some millimetres: the first tick after it
    # starts off equilibrium and says so
    assert solver.last_result.status in ('solved', 'saturated', 'not_converged')
    assert solver.last_result.equilibrium_gap > 1e-3 or solver.last_result.status != (
        'not_converged')
    assert solver.rejected == {'payload.out_of_range': 4}
    assert solver.solver.payload == 0.05
