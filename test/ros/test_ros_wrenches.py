"""
``wrench/tip`` and ``wrench/frame_<i>`` over real DDS: a WrenchStamped loads plant and model.

``cbha_sim`` (at rest, no command, noise-free tip) takes a dead tip force (``frame_id`` the base
frame) and then a follower force on frame 8 (``frame_id`` ``cbha_frame_8``, its own axes): each
moves ``tip/true`` by what the forward model of the plant's scene predicts under the same loads.
``inverse_solver`` on the same topic puts the same load into its model. A non-finite wrench or
one in another frame is rejected, counted and changes nothing.
"""

import math

from cbha_inverse.core.loads import Load
from cbha_inverse.ros.common.qos import MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from geometry_msgs.msg import PointStamped, WrenchStamped
import numpy as np
from rclpy.node import Node
from ros_helpers import make_node, sim_plant_scene, spin_until, spinning

TIP_FORCE = (0.0, 0.3, 0.1)
MID_FORCE = (0.0, 0.0, 0.4)


def _wrench(frame_id, force, torque=(0.0, 0.0, 0.0)):
    message = WrenchStamped()
    message.header.frame_id = frame_id
    f, t = message.wrench.force, message.wrench.torque
    f.x, f.y, f.z = (float(v) for v in force)
    t.x, t.y, t.z = (float(v) for v in torque)
    return message


def test_a_wrench_moves_the_plant_tip_as_the_forward_model_predicts(rclpy_context):
    sim = make_node(CbhaSimNode, rclpy_context, scene='cbha', noise_std=0.0,
                    wrench_frames=['tip', '8'])
    solver = make_node(InverseSolverNode, rclpy_context, mode='open', wrench_frames=['tip'])
    client = Node('client', context=rclpy_context, namespace='/cbha')
    tip_pub = client.create_publisher(WrenchStamped, 'wrench/tip', TARGET_QOS)
    mid_pub = client.create_publisher(WrenchStamped, 'wrench/frame_8', TARGET_QOS)
    tips = []
    client.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(
        np.array([m.point.x, m.point.y, m.point.z])), MEASURED_QOS)

    def settled(executor, count):
        """Wait for ``count`` more tips; return the last."""
        start = len(tips)
        assert spin_until(executor, lambda: len(tips) >= start + count, 10.0)
        return tips[-1]

    with spinning(rclpy_context, sim, solver, client) as executor:
        assert spin_until(executor, lambda: tip_pub.get_subscription_count() == 2
                          and mid_pub.get_subscription_count() == 1 and tips, 10.0)
        rest = settled(executor, 3)
        tip_pub.publish(_wrench('cbha_base', TIP_FORCE))
        assert spin_until(executor, lambda: sim.wrenches.received == 1
                          and solver.wrenches.received == 1, 5.0)
        pushed = settled(executor, 3)
        mid_pub.publish(_wrench('cbha_frame_8', MID_FORCE))
        assert spin_until(executor, lambda: sim.wrenches.received == 2, 5.0)
        both = settled(executor, 3)
        for bad in (_wrench('cbha_base', (math.nan, 0.0, 0.0)),
                    _wrench('cbha_base', (0.0, 0.0, 0.0), (0.0, math.inf, 0.0)),
                    _wrench('cbha_frame_3', TIP_FORCE)):
            tip_pub.publish(bad)
        assert spin_until(executor, lambda: sum(sim.rejected.values()) == 3
                          and sum(solver.rejected.values()) == 3, 5.0)
        after = settled(executor, 3)
    plant = sim_plant_scene('cbha')
    tip_load = Load.of_wrench('wrench/tip', 16, TIP_FORCE)
    mid_load = Load.of_wrench('wrench/frame_8', 8, MID_FORCE, axes='local')
    zero = np.zeros(6)

    def predicted(*loads):
        return plant.forward(zero, loads=plant.loads.updated(*loads),
                             strict=True).effector_positions[-1]
    np.testing.assert_allclose(rest, predicted(), rtol=0, atol=1e-6)
    moved = pushed - rest
    assert np.linalg.norm(moved) > 5e-3
    np.testing.assert_allclose(moved, predicted(tip_load) - predicted(), rtol=0, atol=1e-6)
    np.testing.assert_allclose(both, predicted(tip_load, mid_load), rtol=0, atol=1e-6)
    # the same force dead (base axes) would have put the tip elsewhere (frame 8 turned)
    dead = predicted(tip_load, Load.of_wrench('wrench/frame_8', 8, MID_FORCE))
    assert np.linalg.norm(both - dead) > 5e-6
    np.testing.assert_array_equal(after, both)
    assert set(sim.rejected) == {'wrench.non_finite', 'wrench.frame'}
    assert sim.rejected['wrench.non_finite'] == 2
    assert solver.solver.loads.items == (tip_load,)
    assert set(solver.rejected) == {'wrench.non_finite', 'wrench.frame'}
