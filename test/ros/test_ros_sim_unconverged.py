"""
``cbha_sim`` never publishes a tip or pot reading of a state its static solve did not reach.

The plant's update is made to report a state that did not converge (its result with
``converged`` False, as a solve that ran out of its iteration budget returns it), over real DDS:
while it does, no ``tip/measured``, ``tip/true`` or ``string_pots`` message leaves the node and
its diagnostics read WARN; when the solves converge again, the readings resume.
"""

from dataclasses import replace
import time

from cbha_inverse.ros.common.qos import MEASURED_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import spin_for, spin_until, spinning
from sensor_msgs.msg import JointState


def test_no_reading_leaves_the_sim_while_its_plant_has_not_converged(rclpy_context):
    sim = CbhaSimNode(context=rclpy_context, namespace='/unconverged', parameter_overrides=[
        Parameter('scene', value='cbha'), Parameter('rate_hz', value=100.0),
        Parameter('diagnostics_period', value=0.1)])
    probe = Node('probe', context=rclpy_context)
    counts = {'measured': 0, 'true': 0, 'pots': 0}
    levels = []
    for kind in ('measured', 'true'):
        probe.create_subscription(PointStamped, f'/unconverged/tip/{kind}',
                                  lambda _, kind=kind: counts.__setitem__(kind, counts[kind] + 1),
                                  MEASURED_QOS)
    probe.create_subscription(JointState, '/unconverged/string_pots',
                              lambda _: counts.__setitem__('pots', counts['pots'] + 1),
                              MEASURED_QOS)
    probe.create_subscription(DiagnosticArray, '/diagnostics', lambda m: levels.extend(
        (s.level, s.message) for s in m.status if 'cbha_sim' in s.name), 10)
    update = sim.arm.update_plant

    def unconverged():
        result, tip = update()
        return replace(result, converged=False, message='injected: iteration budget'), tip

    with spinning(rclpy_context, sim, probe) as executor:
        assert spin_until(executor, lambda: counts['measured'] >= 5 and counts['true'] >= 5,
                          10.0)
        sim.arm.update_plant = unconverged
        spin_for(executor, 0.05)
        before = dict(counts)
        levels.clear()
        spin_for(executor, 0.5)
        assert counts == before, (counts, before)
        assert any(level == b'\x01' and 'not converged' in text for level, text in levels), levels
        sim.arm.update_plant = update
        started = time.monotonic()
        assert spin_until(executor, lambda: counts['measured'] >= before['measured'] + 5, 10.0)
        assert time.monotonic() - started < 5.0
    assert sim.not_converged >= 40
