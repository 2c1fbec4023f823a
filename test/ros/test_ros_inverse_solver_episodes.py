"""
``inverse_solver`` over DDS reports a target beyond reach as one WARN episode with its distance.

A target inside the safety box but far outside what the CBHA reaches: the ticks read
``unreachable``, the controller's diagnostics go to WARN naming the distance of the closest
reachable point (the model's predicted gap) while the commands stay within the bounds; a
reachable target afterwards ends the episode and the diagnostics read OK again.
"""

from cbha_inverse.ros.common.diagnostics import OK, WARN
from cbha_inverse.ros.common.qos import TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from ros_helpers import make_node, spin_until, spinning, target_point

CBHA_TARGET = np.array([0.2308, 0.0, -0.0292])
"""The demo's circle centre, in the CBHA's reach [m]."""
FAR = CBHA_TARGET + [0.0, 0.25, 0.25]
"""Inside the safety box, some 0.3 m outside the reach [m]."""


def _control(node):
    """Return the controller's diagnostics status (level, message, values)."""
    status = node._statuses()[0]
    return status.level, status.message, {v.key: v.value for v in status.values}


def test_a_target_beyond_reach_is_one_warn_episode_that_ends(rclpy_context):
    solver = make_node(InverseSolverNode, rclpy_context, mode='open', trigger='timer')
    client = Node('client', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0, 10.0)
        target_pub.publish(target_point(FAR))
        assert spin_until(executor, lambda: solver.ticks >= 40, 10.0)
        level, message, values = _control(solver)
        episode = solver.episodes.current
        # at the edge of the reach the state leaves equilibrium now and then: one episode
        assert episode is not None and episode.condition == 'unreachable'
        assert level == WARN and message.startswith('target beyond reach'), message
        # the distance it names is the model's predicted gap, some 0.2 m
        assert f'{1e3 * episode.figure:.2f} mm' in message
        assert 0.1 < episode.figure < 0.5
        assert float(values['predicted_error_mm']) > 100.0
        assert np.all(solver.command >= 0.0) and np.all(solver.command <= 150e3 + 1e-6)
        target_pub.publish(target_point(CBHA_TARGET))
        assert spin_until(executor, lambda: solver.episodes.current is None, 10.0)
        level, message, _ = _control(solver)
    assert level == OK, message
    assert solver.statuses['unreachable'] >= 30
