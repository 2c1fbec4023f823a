"""
Node behaviours over real DDS that a planted bug would break unseen, each against a reference.

- valve order: ``inverse_solver`` and ``cbha_sim`` with a permuted ``valve_names`` (a cyclic
  shift, not its own inverse): the command is the independent core solver's actuation in that
  order, and the plant's tip is the scene's static equilibrium of the named tube's pressure;
- the simulator's transport latency and first-order valve response, measured from a step command
  on the tip stamps (tip -> pressure through the scene's own forward model);
- hold vs vent on stale feedback told apart by value: the held command is the last solved one;
- the trajectory's period and speed to 2 %, measured on the message stamps.
"""

import math
import time

from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.ros.nodes.trajectory import TrajectoryNode
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import spin_for, spin_until, spinning
from std_msgs.msg import Float64MultiArray

CBHA = 'cbha'
TENDON = 'tendon_6f_8c'


def _stamp(message):
    return message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec


def _shifted(names):
    """Return the names cyclically shifted by one (a permutation that is not an involution)."""
    names = list(names)
    return names[1:] + names[:1]


def _node(node_class, context, **params):
    return node_class(context=context, namespace='/cbha', parameter_overrides=[
        Parameter(k, value=v) for k, v in params.items()])


def _point(point, frame='cbha_base'):
    message = PointStamped()
    message.header.frame_id = frame
    message.point.x, message.point.y, message.point.z = (float(v) for v in point)
    return message


def test_solver_commands_follow_a_permuted_valve_order(rclpy_context):
    """
    The first command after a target = the core solver's first tick, entry i = valve_names[i].

    ``rate_hz`` 1 keeps the timer from ticking the solver during the test, so exactly one tick
    (the one the target triggers) is compared with an independent solver of the same scene.
    """
    scene = load_scene(CBHA)
    names = list(scene.actuator_names)
    valve_names = _shifted(names)
    target = scene.workspace_center[-1] + np.array([0.0, 0.02, 0.01])
    reference = scene.make_inverse_solver()
    reference.warm_up()
    actuation = reference.step(target[None]).actuation
    expected = np.clip(actuation, 0.0, 150000.0)[[names.index(n) for n in valve_names]]
    # the permutation matters for this target: scene order differs from valve order by > 1 kPa
    assert np.abs(expected - np.clip(actuation, 0.0, 150000.0)).max() > 1e3

    solver = _node(InverseSolverNode, rclpy_context, scene=CBHA, valve_names=valve_names,
                   rate_hz=1.0)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    commands = []
    client.create_subscription(Float64MultiArray, 'pressure_command', commands.append,
                               COMMAND_QOS)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and client.count_publishers('/cbha/pressure_command') > 0, 10.0)
        spin_for(executor, 0.1)
        before = len(commands)
        target_pub.publish(_point(target))
        assert spin_until(executor, lambda: solver.ticks >= 1 and len(commands) > before, 10.0)
        spin_until(executor, lambda: any(np.any(np.asarray(c.data) > 0.0)
                                         for c in commands[before:]), 2.0)
    assert solver.ticks == 1
    solved = [c for c in commands[before:] if np.any(np.asarray(c.data) > 0.0)]
    assert solved, 'no solved command received'
    assert solved[0].layout.dim[0].label == ','.join(valve_names)
    np.testing.assert_allclose(solved[0].data, expected, rtol=1e-9, atol=1e-6)


def test_simulator_applies_each_pressure_to_the_named_tube(rclpy_context):
    """cbha_sim with permuted valve_names: the tip is the equilibrium of the named tubes' load."""
    plant_scene = load_scene(CBHA, stiffness_scale=0.9, gravity=(0.0, 0.0, -9.81))
    names = list(plant_scene.actuator_names)
    valve_names = _shifted(names)
    command = np.zeros(len(names))
    command[valve_names.index('outer_left')] = 1.2e5
    command[valve_names.index('inner_over')] = 0.4e5
    in_scene_order = np.zeros(len(names))
    in_scene_order[names.index('outer_left')] = 1.2e5
    in_scene_order[names.index('inner_over')] = 0.4e5
    expected = plant_scene.forward(in_scene_order).effector_positions[-1]
    unpermuted = plant_scene.forward(command).effector_positions[-1]
    assert np.linalg.norm(expected - unpermuted) > 5e-3  # the order decides the tip by > 5 mm

    sim = _node(CbhaSimNode, rclpy_context, scene=CBHA, valve_names=valve_names,
                noise_std=0.0, tolerance=1e-9)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    tips = []
    client.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(
        (time.monotonic(), [m.point.x, m.point.y, m.point.z])), MEASURED_QOS)
    with spinning(rclpy_context, sim, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and len(tips) > 0, 10.0)
        command_pub.publish(Float64MultiArray(data=[float(v) for v in command]))
        sent = time.monotonic()
        # 10 ms valves: after 0.4 s the pressures are within exp(-37) of the set-points
        assert spin_until(executor, lambda: tips[-1][0] > sent + 0.4, 10.0)
    assert sim.accepted == 1
    np.testing.assert_allclose(tips[-1][1], expected, atol=1e-6)


def test_simulator_latency_and_first_order_valves_from_a_step(rclpy_context):
    """
    A step command: the tip does not move for ``latency``, then follows ``1 - exp(-t / tau)``.

    The tip stamps give the time; the scene's own forward model turns each tip back into the
    valve pressure (the tip is the static equilibrium of the current pressure: monotonic along
    this one-tube step). A fit of ``-ln(1 - f) = (t - t_start) / tau`` over 5-95 % gives tau
    and the start; the start lies within one plant tick (10 ms) of the step + latency, plus
    the delivery and the plant's compute time (bounded here by 30 ms on a loaded machine).
    """
    latency, tau, rate, step = 0.15, 0.2, 100.0, 1.0e5
    plant_scene = load_scene(CBHA, stiffness_scale=0.9, gravity=(0.0, 0.0, -9.81))
    names = list(plant_scene.actuator_names)
    valve = names.index('outer_right')
    fractions = np.linspace(0.0, 1.0, 81)
    unit = np.zeros(len(names))
    unit[valve] = step
    curve = np.array([plant_scene.forward(f * unit).effector_positions[-1] for f in fractions])
    direction = (curve[-1] - curve[0]) / np.linalg.norm(curve[-1] - curve[0]) ** 2
    progress = (curve - curve[0]) @ direction
    assert np.all(np.diff(progress) > 0.0), 'the calibration curve must be monotonic'

    sim = _node(CbhaSimNode, rclpy_context, scene=CBHA, valve_names=names, noise_std=0.0,
                latency=latency, valve_time_constant=tau, rate_hz=rate, tolerance=1e-9)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    tips = []
    client.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(
        (_stamp(m), [m.point.x, m.point.y, m.point.z])), MEASURED_QOS)
    with spinning(rclpy_context, sim, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and len(tips) > 5, 10.0)
        sent = client.get_clock().now().nanoseconds * 1e-9
        command_pub.publish(Float64MultiArray(data=[float(v) for v in unit]))
        assert spin_until(executor, lambda: tips[-1][0] > sent + latency + 4.0 * tau, 20.0)
    times = np.array([t for t, _ in tips])
    pressure = np.interp((np.array([p for _, p in tips]) - curve[0]) @ direction, progress,
                         fractions)
    before = times < sent + latency - 0.01
    assert before.sum() >= 5 and np.all(np.abs(pressure[before]) < 1e-6), 'moved too early'
    rising = (pressure > 0.05) & (pressure < 0.95)
    assert rising.sum() >= 20, f'{rising.sum()} samples on the rise: no first-order response'
    slope, intercept = np.polyfit(times[rising], -np.log1p(-pressure[rising]), 1)
    start = -intercept / slope
    print(f'fitted tau {1e3 / slope:.1f} ms (set {tau * 1e3:g}), start {1e3 * (start - sent):.1f}'
          f' ms after the step (latency {latency * 1e3:g} ms)')
    assert 1.0 / slope == pytest.approx(tau, rel=0.1)
    assert latency - 0.015 < start - sent < latency + 0.03
    assert pressure[-1] == pytest.approx(1.0 - math.exp(-(times[-1] - start) / tau), abs=0.01)


@pytest.mark.parametrize('action', ['hold', 'vent'])
def test_stale_feedback_holds_the_last_solved_command_or_vents(rclpy_context, action):
    """
    Closed loop, measurements stop: hold = exactly the last command solved, vent = the vent value.

    Targets keep moving all along; the measurements stop at ``last_measured``. Until the feedback
    is ``timeout`` old the solver follows the targets (the commands change every tick); after
    that, hold must repeat one of the commands of the last ticks before that moment (not the
    vent value, not an older command), and vent must publish the vent value, which no solved
    command equals.
    """
    timeout, vent, max_tension = 0.2, 1.0, 10.0
    names = list(load_scene(TENDON).actuator_names)
    solver = _node(InverseSolverNode, rclpy_context, scene=TENDON, valve_names=names,
                   rate_hz=100.0, max_pressure=max_tension, mode='closed',
                   feedback_timeout=timeout, stale_action=action, vent_pressure=vent)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    measured_pub = client.create_publisher(PointStamped, 'tip/measured', MEASURED_QOS)
    commands = []
    client.create_subscription(Float64MultiArray, 'pressure_command', lambda m: commands.append(
        (time.monotonic(), np.array(m.data))), COMMAND_QOS)
    center = np.array([0.117, 0.0, -0.005])
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and measured_pub.get_subscription_count() > 0, 10.0)
        # running first (so that no idle command falls into the running phase)
        measured_pub.publish(_point(center))
        target_pub.publish(_point(center + [0.0, 0.01, 0.0]))
        assert spin_until(executor, lambda: solver.ticks > 0, 10.0)
        first_target = time.monotonic()
        last_measured = None
        i = 0
        while time.monotonic() < first_target + 1.0:
            target_pub.publish(_point(center + [0.0, 0.01 * np.cos(0.1 * i),
                                                0.01 * np.sin(0.1 * i)]))
            if time.monotonic() < first_target + 0.5:
                measured_pub.publish(_point(center))
                last_measured = time.monotonic()
            i += 1
            spin_for(executor, 0.01)
    assert solver.decision == action
    stale_at = last_measured + timeout
    settled = [c for t, c in commands if t > stale_at + 0.05]
    assert len(settled) > 10
    for command in settled:
        np.testing.assert_array_equal(command, settled[0])
    running = [c for t, c in commands if first_target < t <= stale_at - 0.06]
    assert running and not any(np.allclose(c, vent) for c in running)
    if action == 'vent':
        np.testing.assert_array_equal(settled[0], np.full(len(names), vent))
        return
    held = settled[0]
    assert not np.allclose(held, vent)
    at_last_measured = [c for t, c in commands if t <= last_measured][-1]
    assert not np.array_equal(held, at_last_measured)
    last_ticks = [c for t, c in commands if stale_at - 0.06 < t <= stale_at + 0.03]
    assert any(np.array_equal(held, c) for c in last_ticks), 'held value was not solved last'
    # and the solver was still moving then: the running commands are not all equal
    assert len({c.tobytes() for c in running}) > 1


def test_trajectory_period_and_speed_on_stamps(rclpy_context):
    """
    Period and speed within 2 % of the parameters, from the stamps and points of 60 targets.

    Period: the median stamp difference, and the mean rate may not exceed the set one. Speed:
    the least-squares slope of the arc length (from each point's angle on the circle) over the
    stamps (the node stamps each point with the time it sampled it at).
    """
    rate, speed, radius = 20.0, 0.04, 0.06
    center = np.array([0.2, 0.0, -0.01])
    node = _node(TrajectoryNode, rclpy_context, center=center.tolist(), rate_hz=rate,
                 speed=speed, radius=radius)
    listener = Node('listener', context=rclpy_context)
    received = []
    listener.create_subscription(PointStamped, '/cbha/target', received.append, TARGET_QOS)
    with spinning(rclpy_context, node, listener) as executor:
        assert spin_until(executor, lambda: len(received) >= 60, timeout=30.0)
    stamps = np.array([_stamp(m) for m in received])
    points = np.array([[m.point.x, m.point.y, m.point.z] for m in received])
    # the timer fires on the grid t0 + k T: a late callback gives one long and one short
    # difference, a missed tick one double difference, so the median difference is T; and no
    # load makes a timer fire more often than 1 / T on average (delays only drop ticks)
    period = np.median(np.diff(stamps))
    mean_rate = (stamps.size - 1) / (stamps[-1] - stamps[0])
    angle = np.unwrap(np.arctan2(points[:, 2] - center[2], points[:, 1] - center[1]))
    measured_speed = np.polyfit(stamps - stamps[0], radius * angle, 1)[0]
    print(f'period {period * 1e3:.3f} ms (set {1e3 / rate:g}), speed {measured_speed:.5f} m/s '
          f'(set {speed:g})')
    assert period == pytest.approx(1.0 / rate, rel=0.02)
    assert mean_rate < 1.02 * rate
    assert measured_speed == pytest.approx(speed, rel=0.02)
