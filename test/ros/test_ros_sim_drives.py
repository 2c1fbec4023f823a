"""
``cbha_sim`` with ``command_kind: displacement`` over real DDS: drives commanded by position.

The plant (tendon_6f_8c with its stiffness error) takes ``tendon_displacement_command``: the
displacements that hold a set of tensions in the plant's own forward model put ``tip/true`` where
that model puts the tip under those tensions; a command outside the drives' reach, a NaN and a
command on ``pressure_command`` change nothing (the first two rejected and counted).
``inverse_solver`` with the same ``command_kind`` drives it to a target as it drives tensions.
"""

import math

from cbha_inverse.ros.common.conversions import point_stamped
from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.node import Node
from ros_helpers import make_node, sim_plant_scene, spin_for, spin_until, spinning
from std_msgs.msg import Float64MultiArray

TENSIONS = np.array([3.0, 0.0, 0.0, 1.5, 0.0, 2.0, 0.0, 0.5])


def _command(values):
    message = Float64MultiArray()
    message.data = [float(v) for v in values]
    return message


def test_the_sim_driven_by_displacement_reaches_the_pose_of_the_tensions(rclpy_context):
    sim = make_node(CbhaSimNode, rclpy_context, scene='tendon_6f_8c', noise_std=0.0,
                    command_kind='displacement')
    client = Node('client', context=rclpy_context, namespace='/cbha')
    drives = client.create_publisher(Float64MultiArray, 'tendon_displacement_command',
                                     COMMAND_QOS)
    pressures = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    tips = []
    client.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(
        np.array([m.point.x, m.point.y, m.point.z])), MEASURED_QOS)
    plant = sim_plant_scene('tendon_6f_8c')
    by_tension = plant.forward(TENSIONS, strict=True)
    displacements = plant.tendon_drives.displacements(by_tension.state, TENSIONS)
    with spinning(rclpy_context, sim, client) as executor:
        assert spin_until(executor, lambda: drives.get_subscription_count() == 1 and tips, 10.0)
        drives.publish(_command(displacements))
        assert spin_until(executor, lambda: sim.accepted == 1, 5.0)
        start = len(tips)
        assert spin_until(executor, lambda: len(tips) >= start + 30, 10.0)   # 0.3 s: settled
        reached = tips[-1]
        for bad in ([0.1] * 8, [math.nan] + [0.0] * 7):
            drives.publish(_command(bad))
        pressures.publish(_command(TENSIONS))
        assert spin_until(executor, lambda: sum(sim.rejected.values()) == 2, 5.0)
        start = len(tips)
        assert spin_until(executor, lambda: len(tips) >= start + 10, 5.0)
        after = tips[-1]
    np.testing.assert_allclose(reached, by_tension.effector_positions[-1], rtol=0, atol=1e-6)
    np.testing.assert_allclose(sim.arm.plant.tensions, TENSIONS, atol=1e-3)
    np.testing.assert_array_equal(after, reached)
    assert set(sim.rejected) == {'out_of_range', 'non_finite'}
    assert sim.accepted == 1


@pytest.mark.parametrize('command_kind', ['tension', 'displacement'])
def test_the_inverse_drives_tendons_by_tension_or_by_position(rclpy_context, command_kind):
    """Open loop on the nominal plant: either command reaches the target within 0.1 mm."""
    sim = make_node(CbhaSimNode, rclpy_context, scene='tendon_6f_8c', noise_std=0.0,
                    stiffness_scale=1.0, command_kind=command_kind)
    solver = make_node(InverseSolverNode, rclpy_context, scene='tendon_6f_8c', mode='open',
                       command_kind=command_kind)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    targets = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    tips = []
    client.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(
        np.array([m.point.x, m.point.y, m.point.z])), MEASURED_QOS)
    nominal = load_scene('tendon_6f_8c')
    target = nominal.forward(0.3 * nominal.upper_bounds, strict=True).effector_positions[-1]
    with spinning(rclpy_context, sim, solver, client) as executor:
        assert spin_until(executor, lambda: targets.get_subscription_count() == 1 and tips,
                          10.0)
        for _ in range(150):        # 1.5 s of targets at 100 Hz
            targets.publish(point_stamped(target, client.get_clock().now().to_msg(), 'cbha_base'))
            spin_for(executor, 0.01)
        reached = tips[-1]
    assert np.linalg.norm(reached - target) < 0.1e-3, 1e3 * (reached - target)
    assert sim.accepted > 50 and not sim.rejected
