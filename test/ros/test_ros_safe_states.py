"""
Stopping the arm over real DDS: ``~/vent``, ``~/hold``, ``on_disable`` and controller loss.

The simulated composition (``inverse_solver`` + ``cbha_sim`` on the CBHA scene) is measured on the
simulator's published valve pressures (``pressure_measured``, the valve model's state) as the
test receives them (steady clock). The valve time constant is raised to 0.1 s so that the
delivery and the ticks (10 ms each) are small beside it.
"""

import math
import signal
import time

from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
import numpy as np
import pytest
from rclpy.node import Node
from ros_helpers import make_node, reaped, spin_for, spin_until, spinning, start_node, \
    target_point
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import SetBool, Trigger

# bounds on the timing of node callbacks (timeouts + 100 ms, republication rates): ``make
# test`` runs them in its timing phase, alone on the cores (test/conftest.py)
pytestmark = pytest.mark.timing

SCENE = 'cbha'
TARGET = (0.2308, 0.03, -0.0292)
"""A tip position in the CBHA's reach (the paper circle's centre + 30 mm in y) [m]."""
TAU = 0.1
"""The simulator's valve time constant in these tests [s]."""
LATENCY = 0.003
"""The simulator's transport latency (its default) [s]."""
RATE = 100.0
"""Tick rate of solver and simulator [Hz]."""
DELIVERY = 0.05
"""Slack for the delivery of the service call, the command and the pressures [s] (loaded host)."""


class Probe:
    """The test's node: the sim's pressures and the solver's commands, stamped on arrival."""

    def __init__(self, context):
        self.node = Node('probe', context=context, namespace='/cbha')
        self.pressures, self.commands = [], []
        self.node.create_subscription(Float64MultiArray, 'pressure_measured', lambda m: (
            self.pressures.append((time.monotonic(), np.array(m.data)))), MEASURED_QOS)
        self.node.create_subscription(Float64MultiArray, 'pressure_command', lambda m: (
            self.commands.append((time.monotonic(), np.array(m.data)))), COMMAND_QOS)
        self.target = self.node.create_publisher(
            type(target_point(TARGET)), 'target', TARGET_QOS)

    def call(self, executor, srv_type, name, request):
        """Call a service; return its response and the steady time it arrived."""
        client = self.node.create_client(srv_type, name)
        assert spin_until(executor, client.service_is_ready, 10.0), f'no service {name}'
        future = client.call_async(request)
        assert spin_until(executor, future.done, 5.0), f'no response from {name}'
        return future.result(), time.monotonic()

    def peak_after(self, start):
        """Return the largest valve pressure received after ``start``, per message."""
        return [(t, float(p.max())) for t, p in self.pressures if t > start]


def _sim(context, **overrides):
    return make_node(CbhaSimNode, context, scene=SCENE, valve_time_constant=TAU,
                     latency=LATENCY, rate_hz=RATE, noise_std=0.0, **overrides)


def _solver(context, **overrides):
    return make_node(InverseSolverNode, context, scene=SCENE, rate_hz=RATE, **overrides)


def _settled(probe, executor):
    """Publish the target; spin until the pressures are up and steady; return them."""
    assert spin_until(executor, lambda: probe.target.get_subscription_count() > 0, 10.0)
    probe.target.publish(target_point(TARGET))
    assert spin_until(executor, lambda: len(probe.commands) > 50 and np.allclose(
        probe.pressures[-1][1], probe.commands[-1][1], atol=1.0), 20.0), 'no steady pressures'
    return probe.pressures[-1][1]


def _crossing(series, level, start):
    """Return the first steady time after ``start`` at which the peak is below ``level``."""
    return next((t for t, peak in series if t > start and peak < level), math.inf)


def test_vent_service_vents_the_simulated_arm_within_a_valve_time_constant(rclpy_context):
    """
    ``~/vent`` on the solver: the sim's pressures fall as a first-order valve, from the call.

    Measured: the time from the service's response to the peak pressure falling below 1/e of
    its start (one valve time constant of the sim's valve model) and below 1 %.
    """
    sim, solver, probe = _sim(rclpy_context), _solver(rclpy_context), Probe(rclpy_context)
    with spinning(rclpy_context, sim, solver, probe.node) as executor:
        start = _settled(probe, executor)
        response, called = probe.call(executor, Trigger, 'inverse_solver/vent',
                                      Trigger.Request())
        assert response.success and 'venting' in response.message
        assert spin_until(executor, lambda: (probe.pressures[-1][0] > called + 6.0 * TAU
                                             and len(probe.commands) > 0), 10.0)
        spin_for(executor, 0.2)
    peak0 = float(start.max())
    series = probe.peak_after(called - 0.1)
    one_tau = _crossing(series, peak0 / math.e, called - 0.1) - called
    one_percent = _crossing(series, 0.01 * peak0, called - 0.1) - called
    print(f'vent from {peak0:.0f} Pa: 1/e after {1e3 * one_tau:.0f} ms, 1 % after '
          f'{1e3 * one_percent:.0f} ms (tau {1e3 * TAU:g} ms, latency {1e3 * LATENCY:g} ms)')
    # the vent reaches the valves within the latency, a tick and the delivery; the valve model
    # then takes one time constant to 1/e and ln(100) = 4.6 of them to 1 %
    assert one_tau <= TAU + LATENCY + 1.0 / RATE + DELIVERY
    assert one_percent <= 4.61 * TAU + LATENCY + 1.0 / RATE + DELIVERY
    after = [c for t, c in probe.commands if t > called + 0.05]
    assert len(after) >= 30, 'the vent command is not republished at rate_hz'
    assert all(np.all(c == 0.0) for c in after)
    assert solver.decision == 'disabled' and solver.stopped == 'vent'
    assert np.all(sim.pressures < 0.01 * peak0)


@pytest.mark.parametrize('action', ['vent', 'hold'])
def test_a_controller_that_stops_publishing_vents_or_holds_the_sim(rclpy_context, action):
    """
    A controller's stream stops: ``on_controller_loss`` acts within the timeout + 100 ms.

    The stream is the test's own, commands at 100 Hz, then none; the loss is timed from the
    sim's own record of the last command's arrival (steady clock, this process).
    """
    timeout = 0.3
    sim = _sim(rclpy_context, on_controller_loss=action, controller_loss_timeout=timeout)
    probe = Probe(rclpy_context)
    publisher = probe.node.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    command = np.array([8e4, 2e4, 0.0, 5e4, 0.0, 3e4])
    with spinning(rclpy_context, sim, probe.node) as executor:
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
        for _ in range(60):
            publisher.publish(Float64MultiArray(data=command.tolist()))
            spin_for(executor, 1.0 / RATE)
        assert spin_until(executor, lambda: sim.accepted == 60, 5.0)
        assert sim.controller == 'streaming'
        assert spin_until(executor, lambda: sim.controller == 'lost', timeout + 1.0)
        lost = time.monotonic()
        stopped = sim.command_watch.last    # the sim's steady time of the last command
        spin_for(executor, 0.2 + 5.0 * TAU)
    print(f'{action} {1e3 * (lost - stopped):.0f} ms after the last command '
          f'(timeout {1e3 * timeout:g} ms)')
    assert timeout <= lost - stopped <= timeout + 0.1
    final = probe.pressures[-1][1]
    if action == 'vent':
        peaks = probe.peak_after(stopped)
        began = next(t for t, peak in peaks if peak < 0.99 * command.max())
        print(f'pressures falling {1e3 * (began - stopped):.0f} ms after the last command')
        assert began - stopped <= timeout + 0.1 + LATENCY + 1.0 / RATE + DELIVERY
        np.testing.assert_allclose(final, 0.0, atol=0.01 * command.max())
    else:
        np.testing.assert_allclose(final, command, atol=1.0)


def test_a_single_command_is_kept_past_the_timeout(rclpy_context):
    """One command (a test rig, a one-shot publisher) is no stream: nothing vents it."""
    sim = _sim(rclpy_context, controller_loss_timeout=0.1)
    probe = Probe(rclpy_context)
    publisher = probe.node.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    command = [5e4, 0.0, 0.0, 0.0, 0.0, 0.0]
    with spinning(rclpy_context, sim, probe.node) as executor:
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
        publisher.publish(Float64MultiArray(data=command))
        assert spin_until(executor, lambda: sim.accepted == 1, 5.0)
        spin_for(executor, 0.6)
    assert sim.controller == 'none' and sim.losses == 0
    np.testing.assert_allclose(probe.pressures[-1][1], command, atol=0.01 * max(command))


def test_killed_controller_process_vents_the_sim(rclpy_context):
    """
    SIGKILL of a running ``inverse_solver`` process: the sim vents after its timeout.

    The sim runs here (its default ``on_controller_loss: vent`` after 0.5 s); the loss is timed
    from the sim's record of the last command's arrival.
    """
    sim, probe = _sim(rclpy_context), Probe(rclpy_context)
    process = start_node('cbha_inverse.ros.nodes.inverse_solver', '-p', f'scene:={SCENE}',
                         '-p', f'rate_hz:={RATE}', '-r', '__ns:=/cbha')
    with reaped(process), spinning(rclpy_context, sim, probe.node) as executor:
        start = _settled(probe, executor)
        assert sim.controller == 'streaming'
        process.send_signal(signal.SIGKILL)
        process.wait(10.0)
        assert spin_until(executor, lambda: sim.controller == 'lost', 5.0)
        lost = time.monotonic()
        spin_for(executor, 0.2 + 5.0 * TAU)
    last_command = sim.command_watch.last
    print(f'vent {1e3 * (lost - last_command):.0f} ms after the last command of the killed '
          'controller (timeout 500 ms)')
    assert lost - last_command <= 0.5 + 0.1
    np.testing.assert_allclose(probe.pressures[-1][1], 0.0, atol=0.01 * start.max())


@pytest.mark.parametrize('on_disable', ['hold', 'vent'])
def test_disable_holds_or_vents_and_keeps_publishing(rclpy_context, on_disable):
    """``~/enable false`` does ``on_disable``; ``~/hold`` holds; ``~/enable true`` resumes."""
    sim = _sim(rclpy_context)
    solver = _solver(rclpy_context, on_disable=on_disable)
    probe = Probe(rclpy_context)
    with spinning(rclpy_context, sim, solver, probe.node) as executor:
        start = _settled(probe, executor)
        response, called = probe.call(executor, SetBool, 'inverse_solver/enable',
                                      SetBool.Request(data=False))
        assert response.success
        last = solver.command.copy()    # the last command, as the service stopped the ticks
        ticks = solver.ticks
        spin_for(executor, 1.0)         # past the sim's controller-loss timeout (0.5 s)
        assert solver.ticks == ticks, 'the solver ticked while disabled'
        after = [c for t, c in probe.commands if t > called + 0.05]
        expected = last if on_disable == 'hold' else np.zeros_like(last)
        assert len(after) >= 50 and all(np.array_equal(c, expected) for c in after)
        assert sim.controller == 'streaming', 'the sim took a disabled controller for lost'
        np.testing.assert_allclose(probe.pressures[-1][1], expected, atol=0.01 * start.max())
        response, _ = probe.call(executor, SetBool, 'inverse_solver/enable',
                                 SetBool.Request(data=True))
        assert spin_until(executor, lambda: solver.ticks > ticks + 10, 5.0)
        response, called = probe.call(executor, Trigger, 'inverse_solver/hold',
                                      Trigger.Request())
        assert response.success and 'holding' in response.message
        held = solver.command.copy()
        spin_for(executor, 0.3)
    assert all(np.array_equal(c, held) for t, c in probe.commands if t > called + 0.05)
