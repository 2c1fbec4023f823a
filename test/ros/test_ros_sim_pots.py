"""
``cbha_sim`` publishes ``string_pots`` from the plant's true shape, over real DDS.

With ``tip_output: none`` no ``tip/measured`` is published, ``tip/true`` is; the readings of a
plant with its own pot offset and gain (noise off) equal ``offset + gain * length`` of the routed
lengths at the published true state, in the driver's names and order, with the plant state's
stamp; a ``payload_mass`` lowers the tip.
"""

from cbha_inverse.ros.common.conversions import command_array, command_message, point_array
from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import spin_until, spinning
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from std_srvs.srv import Trigger

OFFSET = [1.0, 2.0, 3.0, 4.0, 5.0, 6.0]
GAIN = 900.0


def _stamp(message):
    return (message.header.stamp.sec, message.header.stamp.nanosec)


def test_sim_publishes_string_pots_and_no_tip_measurement(rclpy_context):
    common = {'scene': 'cbha', 'tip_output': 'none', 'string_pot_noise_std': 0.0,
              'string_pot_offset': OFFSET, 'string_pot_gain': [GAIN], 'rate_hz': 50.0,
              'string_pot_rate_hz': 50.0}
    sims = {name: CbhaSimNode(context=rclpy_context, namespace=f'/pots_{name}',
                              parameter_overrides=[Parameter(k, value=v) for k, v in {
                                  **common, 'payload_mass': mass}.items()])
            for name, mass in (('bare', 0.0), ('loaded', 0.1))}
    probe = Node('probe', context=rclpy_context)
    pots, truth, measured = {n: [] for n in sims}, {n: [] for n in sims}, []
    for name in sims:
        probe.create_subscription(JointState, f'/pots_{name}/string_pots',
                                  lambda m, n=name: pots[n].append(m), MEASURED_QOS)
        probe.create_subscription(PointStamped, f'/pots_{name}/tip/true',
                                  lambda m, n=name: truth[n].append(m), MEASURED_QOS)
        probe.create_subscription(PointStamped, f'/pots_{name}/tip/measured', measured.append,
                                  MEASURED_QOS)
    with spinning(rclpy_context, *sims.values(), probe) as executor:
        # the two topics of one tick arrive in either order: wait for the tips up to the
        # third reading's tick
        assert spin_until(executor, lambda: all(
            len(pots[n]) >= 3 and truth[n] and _stamp(truth[n][-1]) >= _stamp(pots[n][2])
            for n in sims), 20.0)
    sim = sims['bare']
    assert not measured
    message = pots['bare'][2]
    assert list(message.name) == [f'string_pot_{v}' for v in sim.valve_names]
    assert message.header.frame_id == 'cbha_base'
    result = sim.last_result
    lengths = sim.scene.sensors.lengths(result.positions, result.rotations)
    # the plant is at rest: every published state is the same
    np.testing.assert_allclose(message.position, np.array(OFFSET) + GAIN * lengths, rtol=1e-9)
    assert _stamp(message) in {_stamp(m) for m in truth['bare']}
    drop = point_array(truth['bare'][-1])[2] - point_array(truth['loaded'][-1])[2]
    assert drop > 0.02, drop


def test_each_pot_reading_is_of_the_last_pressures_published_before_it(rclpy_context):
    """
    A pot reading is of the equilibrium of the last pressures received before it.

    During a valve step (50 ms, ticks of 20 ms: tens of kPa per tick), one reading per tick with
    the tick's ``tip/true`` stamp, published after the tick's ``pressure_measured`` (as the
    driver's one message carries both).
    """
    sim = CbhaSimNode(context=rclpy_context, namespace='/pair', parameter_overrides=[
        Parameter(k, value=v) for k, v in {
            'scene': 'cbha', 'tip_output': 'none', 'string_pot_noise_std': 0.0,
            'stiffness_scale': 1.0, 'rate_hz': 50.0, 'string_pot_rate_hz': 50.0,
            'valve_time_constant': 0.05, 'tolerance': 1e-9}.items()])
    probe = Node('probe', context=rclpy_context)
    received, truth = [], set()
    probe.create_subscription(Float64MultiArray, '/pair/pressure_measured',
                              lambda m: received.append(('pressures', command_array(m))),
                              MEASURED_QOS)
    probe.create_subscription(JointState, '/pair/string_pots',
                              lambda m: received.append(('pots', m)), MEASURED_QOS)
    probe.create_subscription(PointStamped, '/pair/tip/true',
                              lambda m: truth.add(_stamp(m)), MEASURED_QOS)
    command = probe.create_publisher(Float64MultiArray, '/pair/pressure_command', COMMAND_QOS)
    step = np.array([1.2e5, 0.3e5, 0.0, 0.2e5, 0.9e5, 0.0])
    with spinning(rclpy_context, sim, probe) as executor:
        assert spin_until(executor, lambda: command.get_subscription_count() >= 1
                          and any(kind == 'pots' for kind, _ in received), 20.0)
        start = len(received)
        command.publish(command_message(step, sim.valve_names))
        assert spin_until(executor, lambda: sum(
            kind == 'pots' for kind, _ in received[start:]) >= 12, 20.0)
        spin_until(executor, lambda: False, 0.1)
        # the messages checked below; a tick's tip/true may arrive after its string_pots (under
        # load it came later than the 0.1 s above)
        count = len(received)
        spin_until(executor, lambda: {_stamp(message) for kind, message in received[:count]
                                      if kind == 'pots'} <= truth, 5.0)
    pairs, last = [], None
    for kind, value in received[:count]:
        if kind == 'pressures':
            last = value
        elif last is not None:
            pairs.append((last, value))
    stamps = [_stamp(message) for _, message in pairs]
    assert len(set(stamps)) == len(stamps) and set(stamps) <= truth
    scene, sensors = sim.scene, sim.pots.sensors
    moving, state = 0, None
    for pressures, message in pairs:
        in_scene_order = np.empty(pressures.size)
        in_scene_order[sim.order] = pressures
        moving += np.abs(in_scene_order - step[sim.order]).max() > 1e3
        result = scene.forward(in_scene_order, initial_state=state, strict=True)
        state = result.state
        expected = sensors.readings(sensors.lengths(state.positions, state.rotations))
        # a tick apart the readings differ by millimetres (gain 1 reading/m: 1e-3)
        np.testing.assert_allclose(message.position, expected, atol=2e-5 * np.abs(
            sensors.reading_gain).max())
    assert moving >= 2, moving


def test_a_stuck_pot_freezes_after_the_first_command_and_reset_frees_it(rclpy_context):
    """``string_pot_stuck``: one pot keeps its last reading from 0.1 s after the first command."""
    sim = CbhaSimNode(context=rclpy_context, namespace='/stuck', parameter_overrides=[
        Parameter(k, value=v) for k, v in {
            'scene': 'cbha', 'tip_output': 'none', 'string_pot_noise_std': 0.0,
            'rate_hz': 50.0, 'string_pot_rate_hz': 50.0, 'valve_time_constant': 0.05,
            'string_pot_stuck': 3, 'string_pot_stuck_after': 0.1}.items()])
    probe = Node('probe', context=rclpy_context)
    readings = []
    probe.create_subscription(JointState, '/stuck/string_pots',
                              lambda m: readings.append(np.array(m.position)), MEASURED_QOS)
    command = probe.create_publisher(Float64MultiArray, '/stuck/pressure_command', COMMAND_QOS)
    with spinning(rclpy_context, sim, probe) as executor:
        assert spin_until(executor, lambda: command.get_subscription_count() >= 1
                          and len(readings) >= 2, 20.0)
        start = len(readings)
        command.publish(command_message([0.0, 0.0, 0.0, 1.2e5, 0.0, 0.0], sim.valve_names))
        assert spin_until(executor, lambda: len(readings) >= start + 20, 20.0)
        moved = np.array(readings[start:])
        sim._on_reset(Trigger.Request(), Trigger.Response())
        freed = len(readings)
        assert spin_until(executor, lambda: len(readings) >= freed + 20, 20.0)
    lengths = sim.scene.sensors.lengths(sim.last_result.positions, sim.last_result.rotations)
    # pot 3 (outer_over, the inflated tube's) moves first, then holds for the last 10 readings
    # (0.2 s) while the others still follow the 50 ms valve lag
    assert np.ptp(moved[:4, 3]) > 1e-4 and np.ptp(moved[-10:, 3]) == 0.0
    assert np.ptp(moved[-10:, 4]) > 1e-6
    # after the reset the plant is at rest and pot 3 reads its true length again
    np.testing.assert_allclose(readings[-1], sim.scene.sensors.readings(lengths), rtol=1e-9)
