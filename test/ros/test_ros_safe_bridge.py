"""
``robotino_bridge``'s ``~/vent``, ``~/hold`` and ``~/enable`` and its controller-loss parameters.

As test/ros/test_ros_robotino_bridge.py: the shipped ``robotino_msgs`` built once per session, a
driver stand-in taking ``/set_bha_pressures``. Expected set-points written out by hand (bar,
channels 0-5 arm, 6-7 wrist).
"""

import signal
import subprocess
import sys
import time

from cbha_inverse.ros.common.params import ParameterError
from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.nodes.robotino_bridge import RobotinoBridgeNode
import numpy as np
import pytest
from rclpy.node import Node
from robotino_helpers import DriverStandIn, robotino_child_env
from ros_helpers import make_node, reaped, REPO_ROOT, spin_for, spin_until, spinning
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger

# bounds on the timing of node callbacks (timeouts + 100 ms, republication rates): ``make
# test`` runs them in its timing phase, alone on the cores (test/conftest.py)
pytestmark = pytest.mark.timing

FIRST = [1e4, 2e4, 3e4, 4e4, 5e4, 6e4]
FIRST_BAR = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.0, 0.0]
SECOND = [6e4, 5e4, 4e4, 3e4, 2e4, 1e4]
SECOND_BAR = [0.6, 0.5, 0.4, 0.3, 0.2, 0.1, 0.0, 0.0]
VENT_BAR = [0.0] * 8


def _call(executor, client, request):
    assert spin_until(executor, client.service_is_ready, 10.0), client.srv_name
    future = client.call_async(request)
    assert spin_until(executor, future.done, 5.0), client.srv_name
    return future.result(), time.monotonic()


def _stream(executor, publisher, values, duration):
    end = time.monotonic() + duration
    while time.monotonic() < end:
        publisher.publish(Float64MultiArray(data=[float(v) for v in values]))
        spin_for(executor, 0.02)


def _after(driver, start):
    return [values for t, values in driver.received if t > start]


def test_bridge_vent_and_hold_override_a_streaming_controller(rclpy_context, robotino_msgs):
    """While a controller streams: ~/vent sends zeros, ~/hold the last set-points, till enabled."""
    bridge = make_node(RobotinoBridgeNode, rclpy_context, rate_hz=100.0,
                       controller_loss_timeout=30.0)
    driver = DriverStandIn(rclpy_context)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    vent = client.create_client(Trigger, 'robotino_bridge/vent')
    hold = client.create_client(Trigger, 'robotino_bridge/hold')
    enable = client.create_client(SetBool, 'robotino_bridge/enable')
    with spinning(rclpy_context, bridge, driver, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and bridge.driver_publisher.get_subscription_count() > 0, 10.0)
        _stream(executor, command_pub, FIRST, 0.2)
        response, vented = _call(executor, vent, Trigger.Request())
        assert response.success and 'venting' in response.message
        _stream(executor, command_pub, SECOND, 0.3)        # not forwarded while vented
        vent_sent = _after(driver, vented)
        response, enabled = _call(executor, enable, SetBool.Request(data=True))
        assert response.success
        _stream(executor, command_pub, SECOND, 0.2)
        resumed = _after(driver, enabled + 0.05)
        response, held = _call(executor, hold, Trigger.Request())
        assert response.success and 'holding' in response.message
        _stream(executor, command_pub, FIRST, 0.3)         # not forwarded while held
        hold_sent = _after(driver, held)
    assert len(vent_sent) >= 20, 'vent set-points not republished at rate_hz'
    for values in vent_sent:
        np.testing.assert_allclose(values, VENT_BAR, atol=1e-12)
    assert resumed and all(np.allclose(v, SECOND_BAR, rtol=1e-6) for v in resumed)
    assert len(hold_sent) >= 20
    for values in hold_sent:
        np.testing.assert_allclose(values, SECOND_BAR, rtol=1e-6)
    assert bridge.ignored_while_stopped >= 20 and bridge.stopped == 'hold'


@pytest.mark.parametrize('names', [('controller_loss_timeout', 'on_controller_loss'),
                                   ('command_timeout', 'stale_action')])
def test_controller_loss_parameters_and_their_old_names(rclpy_context, robotino_msgs, names):
    """Either name sets the loss: hold keeps the last set-points past the timeout."""
    timeout_name, action_name = names
    bridge = make_node(RobotinoBridgeNode, rclpy_context, rate_hz=100.0,
                       **{timeout_name: 0.2, action_name: 'hold'})
    assert bridge.command_watch.timeout == 0.2 and bridge.params.loss_action == 'hold'
    driver = DriverStandIn(rclpy_context)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    with spinning(rclpy_context, bridge, driver, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and bridge.driver_publisher.get_subscription_count() > 0, 10.0)
        _stream(executor, command_pub, FIRST, 0.2)
        last = time.monotonic()
        spin_for(executor, 0.5)
    assert bridge.decision == 'hold'
    late = _after(driver, last + 0.3)
    assert len(late) >= 10 and all(np.allclose(v, FIRST_BAR, rtol=1e-6) for v in late)


def test_both_names_with_different_values_are_refused_in_one_line(rclpy_context,
                                                                  robotino_msgs):
    with pytest.raises(ParameterError, match='^controller_loss_timeout 0.2 and its old name '
                       'command_timeout 0.3 disagree: set only controller_loss_timeout$'):
        make_node(RobotinoBridgeNode, rclpy_context, controller_loss_timeout=0.2,
                  command_timeout=0.3)


def test_ctrl_c_of_the_bridge_process_vents_the_driver(rclpy_context, robotino_msgs):
    """SIGINT after set-points were sent: the driver gets the vent set-points before the exit."""
    process = subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.nodes.robotino_bridge', '--ros-args',
         '--params-file', str(REPO_ROOT / 'config' / 'robotino_bridge.yaml'),
         '-r', '__ns:=/cbha'], cwd=REPO_ROOT, env=robotino_child_env(robotino_msgs),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    driver = DriverStandIn(rclpy_context)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    with reaped(process), spinning(rclpy_context, driver, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0, 30.0)
        _stream(executor, command_pub, FIRST, 0.2)
        assert spin_until(executor, lambda: driver.received, 5.0)
        process.send_signal(signal.SIGINT)
        stopped = time.monotonic()
        assert spin_until(executor, lambda: process.poll() is not None, 20.0)
        spin_for(executor, 0.1)
        output = process.communicate(timeout=10.0)[0]
    assert process.returncode == 0, output
    np.testing.assert_allclose(driver.received[-1][1], VENT_BAR, atol=1e-12)
    assert driver.received[-1][0] > stopped and 'stopping: vented' in output, output
