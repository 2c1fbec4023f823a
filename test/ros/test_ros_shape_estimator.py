"""
``shape_estimator`` on ``cbha_sim``'s string pots, over real DDS.

A camera-less plant (``tip_output: none``) with cavity-gain errors holds a bent pose; the
estimator's ``tip/estimated`` carries the stamps of the pot readings and lies within 2 mm RMS of
``tip/true`` of the same stamp while the nominal model is several mm off. A probe's malformed,
misnamed and stale readings are rejected by reason and publish nothing.
"""

from builtin_interfaces.msg import Time
from cbha_inverse.ros.common.conversions import (command_message, joint_state, point_array,
                                                 stamp_ns)
from cbha_inverse.ros.common.qos import COMMAND_QOS, DIAGNOSTICS_QOS, MARKER_QOS, MEASURED_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.shape_estimator import ShapeEstimatorNode
from cbha_inverse.scene import load_scene
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import spin_until, spinning
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

PRESSURES = np.array([1.0e5, 0.2e5, 0.0, 0.3e5, 0.8e5, 0.0])
GAINS = [1.1, 0.9, 1.05, 0.92, 1.08, 0.95]


def test_estimated_tip_follows_the_true_tip(rclpy_context):
    sim = CbhaSimNode(context=rclpy_context, namespace='/se', parameter_overrides=[
        Parameter('scene', value='cbha'), Parameter('tip_output', value='none'),
        Parameter('stiffness_scale', value=1.0), Parameter('cavity_gain_scale', value=GAINS),
        Parameter('rate_hz', value=50.0), Parameter('string_pot_rate_hz', value=50.0)])
    estimator = ShapeEstimatorNode(context=rclpy_context, namespace='/se')
    # renamed, so that its diagnostics do not overwrite those of the estimator under test
    probe_target = ShapeEstimatorNode(context=rclpy_context, namespace='/se_probe',
                                      cli_args=['--ros-args', '-r',
                                                '__node:=shape_estimator_probe'],
                                      parameter_overrides=[Parameter('use_pressures',
                                                                     value=False)])
    probe = Node('probe', context=rclpy_context)
    command = probe.create_publisher(Float64MultiArray, '/se/pressure_command', COMMAND_QOS)
    bad = probe.create_publisher(JointState, '/se_probe/string_pots', MEASURED_QOS)
    truth, estimated, measured, probe_tips = {}, {}, [], []
    probe.create_subscription(PointStamped, '/se/tip/true', lambda m: truth.__setitem__(
        stamp_ns(m.header.stamp), point_array(m)), MEASURED_QOS)
    probe.create_subscription(PointStamped, '/se/tip/estimated', lambda m: estimated.__setitem__(
        stamp_ns(m.header.stamp), point_array(m)), MEASURED_QOS)
    probe.create_subscription(PointStamped, '/se/tip/measured', measured.append, MEASURED_QOS)
    probe.create_subscription(PointStamped, '/se_probe/tip/estimated', probe_tips.append,
                              MEASURED_QOS)
    markers, statuses = [], {}
    probe.create_subscription(MarkerArray, '/se/backbone_estimated', markers.append, MARKER_QOS)
    probe.create_subscription(DiagnosticArray, '/diagnostics', lambda m: statuses.update(
        {s.name: {v.key: v.value for v in s.values} for s in m.status}), DIAGNOSTICS_QOS)
    with spinning(rclpy_context, sim, estimator, probe_target, probe) as executor:
        assert spin_until(executor, lambda: command.get_subscription_count() >= 1
                          and bad.get_subscription_count() >= 1, 20.0)
        command.publish(command_message(PRESSURES, sim.valve_names))
        assert spin_until(executor, lambda: estimator.published >= 120 and markers
                          and 'residual_mm.string_pot_outer_left' in statuses.get(
                              'shape_estimator: estimate', {}), 30.0)
        now = probe.get_clock().now().to_msg()
        names = list(estimator.pot_names)
        good = np.full(6, 150.0)
        bad.publish(joint_state(names, [np.nan] + [150.0] * 5, now, 'cbha_base'))
        bad.publish(joint_state(names[::-1][:5], good[:5], now, 'cbha_base'))
        bad.publish(joint_state(names, good, Time(sec=1), 'cbha_base'))
        assert spin_until(executor, lambda: sum(probe_target.rejected.values()) >= 3, 10.0)
    assert not measured and not probe_tips
    assert probe_target.rejected == {'non_finite': 1, 'wrong_names': 1, 'stale': 1}
    common = sorted(set(truth) & set(estimated))
    assert len(common) >= 50 and set(estimated) <= set(truth)
    late = common[-50:]
    errors = np.array([np.linalg.norm(estimated[ns] - truth[ns]) for ns in late])
    nominal = load_scene('cbha').forward(PRESSURES, strict=True).effector_positions[-1]
    open_loop = np.linalg.norm(nominal - truth[late[-1]])
    # the 0.1 mm pot noise moves the estimated tip by ~1 mm (docs/proprioception.md)
    rms = np.sqrt(np.mean(errors ** 2))
    assert open_loop > 4e-3 and rms < min(2e-3, open_loop / 3.0), (rms, open_loop)
    assert estimator.last.status == 'ok' and estimator.last.rank == 6
    assert not estimator.rejected
    # the markers draw the estimated backbone: 17 frames from the base
    assert len(markers[-1].markers[0].points) == 17
    assert markers[-1].markers[0].header.frame_id == 'cbha_base'
    report = statuses['shape_estimator: estimate']
    assert report['rank'] == '6' and float(report['estimate_median_ms']) > 0.0
