"""
``inverse_solver``'s health over real DDS: the bound lists in its diagnostics and its WARN lines.

The WARN lines are read from ``/rosout`` (every node publishes its log there), so what is checked
is what an operator's console shows.
"""

import time

from cbha_inverse.ros.common.qos import COMMAND_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
from rcl_interfaces.msg import Log
from rclpy.node import Node
from rclpy.qos import QoSProfile, ReliabilityPolicy
from ros_helpers import make_node, spin_for, spin_until, spinning, target_point
from std_msgs.msg import Float64MultiArray

SCENE = 'tendon_6f_8c'
MAX_TENSION = 10.0
"""The tendon trunk's tension ceiling [N], as max_pressure."""
REACHABLE = (0.117, 0.004, -0.008)
"""A tip position well inside the tendon trunk's reach [m]."""
BEYOND = (0.09, 0.08, 0.0)
"""A tip position beyond its reach, far to one side [m]: some tendon pulls at its ceiling."""
QUIET_SPAN = 3.0
"""How long a one-shot target is watched for a stale-target WARN [s] (6x target_timeout)."""
STATUS = 'inverse_solver: control'


class Listener:
    """The solver's WARN lines from /rosout, its diagnostics and its commands."""

    def __init__(self, context):
        self.node = Node('listener', context=context, namespace='/cbha')
        self.warnings, self.controls, self.commands = [], [], []
        self.node.create_subscription(
            Log, '/rosout', self._on_log,
            QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE))
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics, 50)
        self.node.create_subscription(Float64MultiArray, 'pressure_command', lambda m: (
            self.commands.append(np.array(m.data))), COMMAND_QOS)
        self.targets = self.node.create_publisher(PointStamped, 'target', TARGET_QOS)

    def _on_log(self, message):
        if message.name.endswith('inverse_solver') and message.level >= Log.WARN:
            self.warnings.append(message.msg)

    def _on_diagnostics(self, message):
        self.controls += [{v.key: v.value for v in status.values} for status in message.status
                          if status.name == STATUS]


def _solver(context, **overrides):
    return make_node(InverseSolverNode, context, scene=SCENE, max_pressure=MAX_TENSION,
                     rate_hz=100.0, target_timeout=0.5, diagnostics_period=0.1, **overrides)


def _names(listed):
    return set(filter(None, listed.split(',')))


def test_a_one_shot_target_is_no_stale_target_warning_a_stopped_stream_is(rclpy_context):
    """
    One target, held ``QUIET_SPAN`` seconds: no WARN at all; a stream that stops: one WARN.

    The stream: 50 targets at 50 Hz (each within ``target_timeout`` of the one before).
    """
    solver = _solver(rclpy_context)
    listener = Listener(rclpy_context)
    with spinning(rclpy_context, solver, listener.node) as executor:
        assert spin_until(executor, lambda: listener.targets.get_subscription_count() > 0, 10.0)
        spin_for(executor, 0.5)         # the /rosout subscription matched
        listener.targets.publish(target_point(REACHABLE))
        spin_for(executor, QUIET_SPAN)
        assert solver.target_stale and solver.ticks > 100
        quiet = list(listener.warnings)
        for k in range(50):
            listener.targets.publish(target_point((REACHABLE[0], REACHABLE[1] + 1e-4 * k,
                                                   REACHABLE[2])))
            spin_for(executor, 0.02)
        assert spin_until(executor, lambda: listener.warnings, 2.0)
        spin_for(executor, 0.5)
    assert quiet == [], quiet
    assert len(listener.warnings) == 1, listener.warnings
    assert 'target stream stopped' in listener.warnings[0]


def test_diagnostics_separate_the_lower_and_the_upper_bound(rclpy_context):
    """In reach no tendon is at its ceiling; beyond it some pull their max, others are slack."""
    solver = _solver(rclpy_context)
    listener = Listener(rclpy_context)
    names = list(solver.valve_names)
    with spinning(rclpy_context, solver, listener.node) as executor:
        assert spin_until(executor, lambda: listener.targets.get_subscription_count() > 0, 10.0)
        for target in (REACHABLE, BEYOND):
            listener.targets.publish(target_point(target))
            spin_for(executor, 1.0)
            command = solver.command.copy()
            published = time.monotonic()
            listener.controls.clear()
            assert spin_until(executor, lambda: listener.controls, 2.0)
            values = listener.controls[-1]
            lower, upper = _names(values['at_lower_bound']), _names(values['at_upper_bound'])
            print(f'{target}: command {np.round(command, 3).tolist()} N, at lower {sorted(lower)}'
                  f', at upper {sorted(upper)} ({time.monotonic() - published:.2f} s)')
            assert lower == {n for n, c in zip(names, command) if c <= 1e-8}
            assert upper == {n for n, c in zip(names, command) if c >= MAX_TENSION - 1e-8}
            assert not lower & upper
            if target == REACHABLE:
                assert not upper
            else:
                # slack tendons (normal) and tendons at their ceiling, in separate lists
                assert upper and lower and values['last_status'] == 'unreachable'
    # the unreachable episode's own WARN stays
    assert any('beyond reach' in w for w in listener.warnings), listener.warnings
