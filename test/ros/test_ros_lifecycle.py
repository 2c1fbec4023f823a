"""
The managed ``inverse_solver`` and ``robotino_bridge`` driven through the lifecycle services.

A manager's requests (``~/change_state``) over real DDS: unconfigured and inactive nodes have no
command topic; active ones command as the plain nodes do; ``deactivate`` and ``shutdown`` from
active leave the vent command as the last one received, and nothing after it.
"""

from cbha_inverse.ros.common.qos import COMMAND_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.inverse_solver_managed import ManagedInverseSolverNode
from cbha_inverse.ros.nodes.robotino_bridge_managed import ManagedRobotinoBridgeNode
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped
from lifecycle_msgs.msg import Transition
from lifecycle_msgs.srv import ChangeState, GetState
import numpy as np
from rclpy.lifecycle import TransitionCallbackReturn
from rclpy.node import Node
from robotino_helpers import DriverStandIn
from ros_helpers import (
    assert_refused, make_node, set_parameters, spin_for, spin_until, spinning, target_point)
from std_msgs.msg import Float64MultiArray

TENDON = 'tendon_6f_8c'
TENDON_CENTER = (0.117, 0.0, -0.005)
"""A tip position well in the tendon trunk's reach (near its workspace centre) [m]."""


class Manager:
    """A lifecycle manager's client of one node: ``change(transition)``, ``state()``."""

    def __init__(self, client, node_name):
        self.change_client = client.create_client(ChangeState, f'{node_name}/change_state')
        self.state_client = client.create_client(GetState, f'{node_name}/get_state')

    def _call(self, executor, client, request):
        assert spin_until(executor, client.service_is_ready, 10.0)
        future = client.call_async(request)
        assert spin_until(executor, future.done, 30.0)
        return future.result()

    def change(self, executor, transition_id):
        request = ChangeState.Request()
        request.transition.id = transition_id
        return self._call(executor, self.change_client, request).success

    def state(self, executor):
        return self._call(executor, self.state_client, GetState.Request()).current_state.label


def test_managed_solver_commands_only_when_active_and_vents_on_leaving(rclpy_context):
    vent = 1.0
    names = list(load_scene(TENDON).actuator_names)
    solver = make_node(ManagedInverseSolverNode, rclpy_context, scene=TENDON, valve_names=names,
                       max_pressure=10.0, vent_pressure=vent)
    client = Node('manager', context=rclpy_context, namespace='/cbha')
    manager = Manager(client, 'inverse_solver')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    commands = []
    client.create_subscription(Float64MultiArray, 'pressure_command',
                               lambda m: commands.append(np.array(m.data)), COMMAND_QOS)
    topic = '/cbha/pressure_command'

    def run_until_commanded(executor):
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0, 10.0)
        start = len(commands)
        target_pub.publish(target_point(TENDON_CENTER))
        assert spin_until(executor, lambda: len(commands) > start + 5, 10.0)

    with spinning(rclpy_context, solver, client) as executor:
        assert manager.state(executor) == 'unconfigured'
        assert client.count_publishers(topic) == 0
        assert manager.change(executor, Transition.TRANSITION_CONFIGURE)
        assert manager.state(executor) == 'inactive'
        spin_for(executor, 0.2)
        assert client.count_publishers(topic) == 0 and not commands
        assert manager.change(executor, Transition.TRANSITION_ACTIVATE)
        run_until_commanded(executor)
        assert not np.allclose(commands[-1], vent)
        assert manager.change(executor, Transition.TRANSITION_DEACTIVATE)
        assert spin_until(executor, lambda: np.allclose(commands[-1], vent), 2.0)
        received = len(commands)
        spin_for(executor, 0.3)
        assert len(commands) == received and client.count_publishers(topic) == 0
        # again, then shut down from active
        assert manager.change(executor, Transition.TRANSITION_ACTIVATE)
        run_until_commanded(executor)
        assert not np.allclose(commands[-1], vent)
        assert manager.change(executor, Transition.TRANSITION_ACTIVE_SHUTDOWN)
        assert spin_until(executor, lambda: np.allclose(commands[-1], vent), 2.0)
        assert manager.state(executor) == 'finalized'
        received = len(commands)
        spin_for(executor, 0.3)
        assert len(commands) == received


def test_managed_bridge_forwards_only_when_active_and_vents_on_leaving(
        rclpy_context, robotino_msgs):
    bridge = make_node(ManagedRobotinoBridgeNode, rclpy_context, vent_pressure=1.0e4,
                       command_timeout=30.0)
    driver = DriverStandIn(rclpy_context)
    client = Node('manager', context=rclpy_context, namespace='/cbha')
    manager = Manager(client, 'robotino_bridge')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    vent_bar = [0.1] * 6 + [0.0, 0.0]
    with spinning(rclpy_context, bridge, driver, client) as executor:
        assert manager.change(executor, Transition.TRANSITION_CONFIGURE)
        spin_for(executor, 0.2)
        assert command_pub.get_subscription_count() == 0
        assert manager.change(executor, Transition.TRANSITION_ACTIVATE)
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0, 10.0)
        command_pub.publish(Float64MultiArray(data=[5.0e4] * 6))
        assert spin_until(executor, lambda: len(driver.received) == 1, 5.0)
        np.testing.assert_allclose(driver.received[0][1][:6], 0.5)
        assert manager.change(executor, Transition.TRANSITION_DEACTIVATE)
        assert spin_until(executor, lambda: len(driver.received) == 2, 2.0)
        np.testing.assert_allclose(driver.received[1][1], vent_bar)
        spin_for(executor, 0.2)
        assert command_pub.get_subscription_count() == 0
        # shutdown from inactive: nothing more is sent (it vented on leaving active)
        assert manager.change(executor, Transition.TRANSITION_INACTIVE_SHUTDOWN)
        assert manager.state(executor) == 'finalized'
        spin_for(executor, 0.2)
    assert len(driver.received) == 2


def test_managed_bridge_takes_live_parameters_in_every_state(rclpy_context, robotino_msgs):
    bridge = make_node(ManagedRobotinoBridgeNode, rclpy_context, command_timeout=30.0)
    driver = DriverStandIn(rclpy_context)
    client = Node('manager', context=rclpy_context, namespace='/cbha')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    with spinning(rclpy_context, bridge, driver, client) as executor:
        # unconfigured: the parameter checks, then configure builds with the new values
        assert set_parameters(bridge, vent_pressure=2.0e4, rate_hz=20.0).successful
        assert_refused(bridge, 'above max_pressure', max_pressure=1.0e4)
        assert_refused(bridge, 'read-only', valve_names=['inner_over'])
        assert bridge.trigger_configure() == TransitionCallbackReturn.SUCCESS
        np.testing.assert_allclose(bridge.vent_bar, [0.2] * 6 + [0.0, 0.0])
        # inactive: the vent set-points follow; the timer is not there yet
        assert set_parameters(bridge, vent_pressure=3.0e4, rate_hz=25.0).successful
        np.testing.assert_allclose(bridge.vent_bar, [0.3] * 6 + [0.0, 0.0])
        assert_refused(bridge, 'above max_pressure', max_pressure=1.0e4)
        assert bridge.trigger_activate() == TransitionCallbackReturn.SUCCESS
        assert bridge.timer.timer_period_ns == 40_000_000
        # active: timers and watchdogs too
        assert set_parameters(bridge, rate_hz=100.0, command_timeout=20.0).successful
        assert bridge.timer.timer_period_ns == 10_000_000
        assert bridge.command_watch.timeout == 20.0
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0, 10.0)
        command_pub.publish(Float64MultiArray(data=[5.0e4] * 6))
        assert spin_until(executor, lambda: len(driver.received) == 1, 5.0)
        assert set_parameters(bridge, vent_pressure=4.0e4).successful
        assert bridge.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
        assert spin_until(executor, lambda: len(driver.received) == 2, 2.0)
        np.testing.assert_allclose(driver.received[1][1], [0.4] * 6 + [0.0, 0.0])
        # inactive again: its timer is gone, a change of rate_hz is kept for the next activate
        assert set_parameters(bridge, rate_hz=50.0).successful
        assert bridge.trigger_activate() == TransitionCallbackReturn.SUCCESS
        assert bridge.timer.timer_period_ns == 20_000_000


def test_managed_solver_takes_live_parameters_in_every_state(rclpy_context):
    names = list(load_scene(TENDON).actuator_names)
    solver = make_node(ManagedInverseSolverNode, rclpy_context, scene=TENDON, valve_names=names,
                       max_pressure=10.0)
    client = Node('manager', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    commands = []
    client.create_subscription(Float64MultiArray, 'pressure_command',
                               lambda m: commands.append(np.array(m.data)), COMMAND_QOS)
    with spinning(rclpy_context, solver, client) as executor:
        assert set_parameters(solver, vent_pressure=1.0, loop_gain=0.2).successful
        assert_refused(solver, 'out of range', loop_gain=2.0)
        assert_refused(solver, 'read-only', scene='cbha')
        assert solver.trigger_configure() == TransitionCallbackReturn.SUCCESS
        np.testing.assert_allclose(solver.vent_command, 1.0)
        assert set_parameters(solver, vent_pressure=2.0, rate_hz=40.0).successful
        np.testing.assert_allclose(solver.vent_command, 2.0)
        # the scene's own checks refuse, and nothing changes
        assert_refused(solver, 'must be below', workspace_min=[0.7, 0.0, 0.0])
        assert solver.trigger_activate() == TransitionCallbackReturn.SUCCESS
        assert solver.timer.timer_period_ns == 25_000_000
        assert set_parameters(solver, rate_hz=50.0, feedback_timeout=2.0).successful
        assert solver.timer.timer_period_ns == 20_000_000
        assert solver.feedback_watch.timeout == 2.0
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0, 10.0)
        target_pub.publish(target_point(TENDON_CENTER))
        assert spin_until(executor, lambda: len(commands) > 5, 10.0)
        assert set_parameters(solver, vent_pressure=3.0).successful
        assert solver.trigger_deactivate() == TransitionCallbackReturn.SUCCESS
        assert spin_until(executor, lambda: np.allclose(commands[-1], 3.0), 2.0)
        # inactive again: the destroyed timers are not touched; the next activate reads it
        assert set_parameters(solver, rate_hz=20.0).successful
        assert solver.trigger_activate() == TransitionCallbackReturn.SUCCESS
        assert solver.timer.timer_period_ns == 50_000_000
