"""
The sections' stiffness factors from ``shape_estimator`` into ``inverse_solver``'s model.

``shape_estimator`` with ``section_stiffness_std`` publishes one factor per scene section on
``sections/estimated`` (and with ``publish_gains`` one gain per valve on ``gains/estimated``);
``inverse_solver`` with ``section_stiffness_topic`` (``actuator_gain_topic``) takes a good message
into its model (rate-limited by ``max_section_change``) and rejects, by reason, one of the wrong
length, a non-finite one and one out of range, which change nothing.
"""

from cbha_inverse.ros.common.conversions import joint_state
from cbha_inverse.ros.common.qos import MEASURED_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.ros.nodes.shape_estimator import ShapeEstimatorNode
from cbha_inverse.scene import load_scene
import numpy as np
from rclpy.node import Node
from ros_helpers import make_node, set_parameters, spin_until, spinning
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray


def test_the_solver_takes_good_factors_and_rejects_bad_ones(rclpy_context):
    solver = make_node(InverseSolverNode, rclpy_context, section_stiffness_topic='sections/est',
                       max_section_change=0.0)
    assert solver.solver.section_names == ('inner', 'outer')
    probe = Node('probe', context=rclpy_context, namespace='/cbha')
    publisher = probe.create_publisher(Float64MultiArray, 'sections/est', MEASURED_QOS)
    with spinning(rclpy_context, solver, probe) as executor:
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
        publisher.publish(Float64MultiArray(data=[1.1, 0.9]))
        assert spin_until(executor, lambda: solver.solver.section_stiffness[0] != 1.0, 5.0)
        for data in ([1.0], [1.0, 1.0, 1.0], [float('nan'), 1.0], [3.0, 1.0], [1.0, 0.1]):
            publisher.publish(Float64MultiArray(data=data))
        assert spin_until(executor, lambda: solver.rejected.total >= 5, 5.0)
        np.testing.assert_array_equal(solver.solver.section_stiffness, [1.1, 0.9])
        # a limited change per message (live parameter)
        assert set_parameters(solver, max_section_change=0.05).successful
        publisher.publish(Float64MultiArray(data=[1.3, 0.7]))
        assert spin_until(executor, lambda: solver.solver.section_stiffness[0] != 1.1, 5.0)
        statuses = {s.name: {v.key: v.value for v in s.values} for s in solver._statuses()}
    np.testing.assert_allclose(solver.solver.section_stiffness, [1.15, 0.85])
    assert dict(solver.rejected) == {'sections.wrong_length': 2, 'sections.not_finite': 1,
                                     'sections.out_of_range': 2}
    control = statuses['inverse_solver: control']
    assert float(control['section_stiffness.inner']) == 1.15


def test_the_estimator_publishes_one_factor_per_section_and_the_gains(rclpy_context):
    scene = load_scene('cbha')
    rest = scene.forward(np.zeros(len(scene.actuator_names)), strict=True).state
    readings = scene.sensors.readings(scene.sensors.lengths(rest.positions, rest.rotations))
    estimator = make_node(ShapeEstimatorNode, rclpy_context, section_stiffness_std=0.2,
                          publish_gains=True)
    probe = Node('probe', context=rclpy_context, namespace='/cbha')
    pots = probe.create_publisher(JointState, 'string_pots', MEASURED_QOS)
    pressures = probe.create_publisher(Float64MultiArray, 'pressure_measured', MEASURED_QOS)
    factors, gains = [], []
    probe.create_subscription(Float64MultiArray, 'sections/estimated',
                              lambda m: factors.append(np.array(m.data)), MEASURED_QOS)
    probe.create_subscription(Float64MultiArray, 'gains/estimated',
                              lambda m: gains.append(np.array(m.data)), MEASURED_QOS)
    with spinning(rclpy_context, estimator, probe) as executor:
        assert spin_until(executor, lambda: pots.get_subscription_count() > 0
                          and pressures.get_subscription_count() > 0, 10.0)

        def publish_and_count():
            pressures.publish(Float64MultiArray(data=[0.0] * 6))
            pots.publish(joint_state(list(scene.sensors.names), readings,
                                     probe.get_clock().now().to_msg(), 'cbha_base'))
            return len(factors) >= 3 and len(gains) >= 3
        assert spin_until(executor, publish_and_count, 10.0), (len(factors), len(gains))
    assert all(f.shape == (2,) for f in factors) and all(g.shape == (6,) for g in gains)
    # the nominal scene's own readings: factors and gains near 1
    np.testing.assert_allclose(factors[-1], 1.0, atol=0.05)
    np.testing.assert_allclose(gains[-1], 1.0, atol=0.05)


def test_the_solver_takes_gains_in_valve_order_and_rejects_bad_ones(rclpy_context):
    names = list(load_scene('cbha').actuator_names)
    valves = names[::-1]
    solver = make_node(InverseSolverNode, rclpy_context, actuator_gain_topic='gains/est',
                       max_gain_change=0.0, valve_names=valves)
    probe = Node('probe', context=rclpy_context, namespace='/cbha')
    publisher = probe.create_publisher(Float64MultiArray, 'gains/est', MEASURED_QOS)
    gains = [0.9, 0.95, 1.0, 1.05, 1.1, 1.15]    # valve order
    with spinning(rclpy_context, solver, probe) as executor:
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
        publisher.publish(Float64MultiArray(data=gains))
        assert spin_until(executor, lambda: solver.solver.actuator_gain[0] != 1.0, 5.0)
        for data in ([1.0] * 5, [float('inf')] + [1.0] * 5, [0.2] + [1.0] * 5):
            publisher.publish(Float64MultiArray(data=data))
        assert spin_until(executor, lambda: solver.rejected.total >= 3, 5.0)
    np.testing.assert_array_equal(solver.solver.actuator_gain, gains[::-1])
    assert dict(solver.rejected) == {'gains.wrong_length': 1, 'gains.not_finite': 1,
                                     'gains.out_of_range': 1}
