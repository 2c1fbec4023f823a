"""
``cbha_sim``'s valve line over real DDS: transport latency, then a first-order valve response.

Measured from a step command on the stamps of the published tips: the scene's own forward model
turns each tip back into the valve pressure.
"""

import math

from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.node import Node
from ros_helpers import make_node, sim_plant_scene, spin_until, spinning, stamp_seconds
from std_msgs.msg import Float64MultiArray

CBHA = 'cbha'


# the plant's tick rate is what is measured (samples on the rise, the start within 30 ms):
# beside the other worker's multi-process tests it fell to ~20 Hz once
@pytest.mark.timing
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
    plant_tick = 1.0 / rate
    # the fitted start: no earlier than a plant tick and a half of fit scatter before step +
    # latency, no later than the delivery and the plant's compute time after it
    early, late = 1.5 * plant_tick, 0.03
    plant_scene = sim_plant_scene(CBHA)
    names = list(plant_scene.actuator_names)
    valve = names.index('outer_right')
    fractions = np.linspace(0.0, 1.0, 81)
    unit = np.zeros(len(names))
    unit[valve] = step
    curve = np.array([plant_scene.forward(f * unit).effector_positions[-1] for f in fractions])
    direction = (curve[-1] - curve[0]) / np.linalg.norm(curve[-1] - curve[0]) ** 2
    progress = (curve - curve[0]) @ direction
    assert np.all(np.diff(progress) > 0.0), 'the calibration curve must be monotonic'

    sim = make_node(CbhaSimNode, rclpy_context, scene=CBHA, valve_names=names, noise_std=0.0,
                    latency=latency, valve_time_constant=tau, rate_hz=rate, tolerance=1e-9)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    tips = []
    client.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(
        (stamp_seconds(m), [m.point.x, m.point.y, m.point.z])), MEASURED_QOS)
    with spinning(rclpy_context, sim, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and len(tips) > 5, 10.0)
        sent = client.get_clock().now().nanoseconds * 1e-9
        command_pub.publish(Float64MultiArray(data=[float(v) for v in unit]))
        assert spin_until(executor, lambda: tips[-1][0] > sent + latency + 4.0 * tau, 20.0)
    times = np.array([t for t, _ in tips])
    pressure = np.interp((np.array([p for _, p in tips]) - curve[0]) @ direction, progress,
                         fractions)
    before = times < sent + latency - plant_tick
    assert before.sum() >= 5 and np.all(np.abs(pressure[before]) < 1e-6), 'moved too early'
    rising = (pressure > 0.05) & (pressure < 0.95)
    assert rising.sum() >= 20, f'{rising.sum()} samples on the rise: no first-order response'
    slope, intercept = np.polyfit(times[rising], -np.log1p(-pressure[rising]), 1)
    start = -intercept / slope
    print(f'fitted tau {1e3 / slope:.1f} ms (set {tau * 1e3:g}), start {1e3 * (start - sent):.1f}'
          f' ms after the step (latency {latency * 1e3:g} ms)')
    assert 1.0 / slope == pytest.approx(tau, rel=0.1)
    assert latency - early < start - sent < latency + late
    assert pressure[-1] == pytest.approx(1.0 - math.exp(-(times[-1] - start) / tau), abs=0.01)
