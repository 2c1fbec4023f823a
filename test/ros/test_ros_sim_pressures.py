"""
``cbha_sim`` publishes its valve pressures on ``pressure_measured``, over real DDS.

The test drives ``/clock`` itself (``use_sim_time``), 10 ms per step (one plant tick at 100 Hz),
and waits for each tick's message before the next step, so every message belongs to a known
clock value. A command held from ``t0`` must read, in ``valve_names`` order (here the reverse
of the scene order), as the closed form of the delayed first-order step
``p(t) = c (1 - exp(-(t - t0 - latency) / tau))`` (0 before ``t0 + latency``). A second plant
with ``pressure_noise_std`` adds Gaussian noise of that size, and its tip noise is still the
sequence its ``seed`` gave without pressure noise.
"""

from cbha_inverse.ros.common.conversions import command_message
from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import spin_until, spinning
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

START_NS = 1000 * 10 ** 9
STEP_NS = 10_000_000
STEPS = 12
LATENCY = 0.003
TAU = 0.01
PRESSURE_NOISE = 500.0
TIP_NOISE = 2e-4
SEED = 7


def _clock(ns):
    message = Clock()
    message.clock.sec, message.clock.nanosec = divmod(ns, 10 ** 9)
    return message


def _stamp_ns(message):
    return message.header.stamp.sec * 10 ** 9 + message.header.stamp.nanosec


def test_sim_publishes_valve_pressures_after_latency_and_lag(rclpy_context):
    scene_order = list(load_scene('cbha').actuator_names)
    valve_names = scene_order[::-1]
    common = {'use_sim_time': True, 'scene': 'cbha', 'valve_names': valve_names,
              'rate_hz': 100.0, 'latency': LATENCY, 'valve_time_constant': TAU,
              'noise_std': TIP_NOISE, 'seed': SEED}
    sims = {
        'exact': CbhaSimNode(context=rclpy_context, namespace='/pm_exact', parameter_overrides=[
            Parameter(k, value=v) for k, v in common.items()]),
        'noisy': CbhaSimNode(context=rclpy_context, namespace='/pm_noisy', parameter_overrides=[
            Parameter(k, value=v) for k, v in {**common,
                                               'pressure_noise_std': PRESSURE_NOISE}.items()])}
    probe = Node('probe', context=rclpy_context)
    clock = probe.create_publisher(Clock, '/clock', 10)
    step = {'now': None}
    received = {name: [] for name in sims}
    commands, tips = {}, {'measured': {}, 'true': {}}
    for name in sims:
        commands[name] = probe.create_publisher(Float64MultiArray, f'/pm_{name}/pressure_command',
                                                COMMAND_QOS)
        probe.create_subscription(
            Float64MultiArray, f'/pm_{name}/pressure_measured',
            lambda m, name=name: received[name].append((step['now'], np.array(m.data))),
            MEASURED_QOS)
    for kind in tips:
        probe.create_subscription(
            PointStamped, f'/pm_noisy/tip/{kind}', lambda m, kind=kind: tips[kind].__setitem__(
                _stamp_ns(m), np.array([m.point.x, m.point.y, m.point.z])), MEASURED_QOS)
    with spinning(rclpy_context, *sims.values(), probe) as executor:
        def started():
            clock.publish(_clock(START_NS))
            executor.spin_once(timeout_sec=0.05)
            return all(s.get_clock().now().nanoseconds == START_NS
                       and s.pressure_publisher.get_subscription_count() >= 1
                       and commands[n].get_subscription_count() >= 1 for n, s in sims.items())
        assert spin_until(executor, started, 20.0)
        step['now'] = START_NS
        assert spin_until(executor, lambda: all(received.values()), 10.0)
        c = np.array([20e3, 40e3, 60e3, 80e3, 100e3, 120e3])     # valve_names order
        for name in sims:
            commands[name].publish(command_message(c, valve_names))
        assert spin_until(executor, lambda: all(s.accepted == 1 for s in sims.values()), 10.0)
        for k in range(1, STEPS + 1):
            step['now'] = START_NS + k * STEP_NS
            counts = {name: len(r) for name, r in received.items()}
            clock.publish(_clock(step['now']))
            assert spin_until(executor, lambda: all(len(received[n]) > counts[n] for n in sims),
                              10.0), f'no pressure_measured after clock step {k}'
        spin_until(executor, lambda: len(tips['true']) >= STEPS + 1
                   and len(tips['measured']) >= STEPS + 1, 2.0)

    t0 = START_NS
    for name, series in received.items():
        # before step['now'] was set the clock's value was not known yet: those are not used
        stamps = np.array([ns for ns, _ in series if ns is not None])
        data = np.array([d for ns, d in series if ns is not None])
        assert data.shape == (len(stamps), 6) and len(stamps) >= STEPS
        elapsed = (stamps - t0) * 1e-9
        expected = np.where(elapsed[:, None] >= LATENCY,
                            c * -np.expm1(-(elapsed[:, None] - LATENCY) / TAU), 0.0)
        if name == 'exact':
            np.testing.assert_allclose(data, expected, rtol=1e-9, atol=1e-6)
            assert data[-1, -1] > 0.99 * c[-1]            # order: valve_names, the last one
            assert stamps[-1] == t0 + STEPS * STEP_NS
        else:
            noise = (data - expected).ravel()
            assert 0.6 * PRESSURE_NOISE < noise.std() < 1.5 * PRESSURE_NOISE
            assert abs(noise.mean()) < 4.0 * PRESSURE_NOISE / np.sqrt(noise.size)
    # the tip noise of the seed, tick by tick, is what it was without pressure noise
    common_stamps = sorted(set(tips['true']) & set(tips['measured']))
    assert len(common_stamps) >= STEPS
    index = [(ns - START_NS) // STEP_NS for ns in common_stamps]
    draws = np.random.default_rng(SEED).normal(0.0, TIP_NOISE, (max(index) + 1, 3))
    observed = np.array([tips['measured'][ns] - tips['true'][ns] for ns in common_stamps])
    np.testing.assert_allclose(observed, draws[index], rtol=0.0, atol=1e-12)
