"""
``cbha_excite`` over real DDS: it publishes its program, ends with exit 0, refuses to fight.

1. In process, on a test-driven ``/clock`` (``use_sim_time``, one 20 ms step per command at
   50 Hz, each step waited for): every received command equals the program's actuation at the
   clock value it was published at, in ``valve_names`` order (here the reverse of the scene
   order); the last one is the end actuation and the node's ``done`` completes with 0.
2. As processes (``python -m cbha_inverse.ros.nodes.cbha_excite``, wall clock): a short program
   runs to its end and exits 0; with another publisher on ``pressure_command`` it refuses (exit 1,
   no command sent) unless ``force:=true``; SIGINT before the end exits 1; an unknown program or a
   broken program file exits 2 with one line naming the parameter or the file and key.
"""

import signal

from cbha_inverse.identify.excitation import make_program
from cbha_inverse.ros.common.qos import COMMAND_QOS, reliable
from cbha_inverse.ros.nodes.cbha_excite import ExciteNode
from cbha_inverse.scene import load_scene
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import spin_for, spin_until, spinning, start_node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

START_NS = 500 * 10 ** 9
STEP_NS = 20_000_000
HOLD, RAMP = 0.2, 0.1
MODULE = 'cbha_inverse.ros.nodes.cbha_excite'


def _clock(ns):
    message = Clock()
    message.clock.sec, message.clock.nanosec = divmod(ns, 10 ** 9)
    return message


def test_commands_follow_the_program_on_the_sim_clock(rclpy_context):
    scene = load_scene('cbha')
    valve_names = list(scene.actuator_names)[::-1]
    order = [scene.actuator_names.index(n) for n in valve_names]
    start = np.linspace(10e3, 60e3, 6)                      # valve_names order
    node = ExciteNode(context=rclpy_context, namespace='/ex_sim', parameter_overrides=[
        Parameter(k, value=v) for k, v in {
            'use_sim_time': True, 'program': 'outer_bends', 'hold_time': HOLD,
            'ramp_time': RAMP, 'rate_hz': 50.0, 'valve_names': valve_names,
            'start_pressure': start.tolist(), 'discovery_time': 0.2,
            'wait_for_subscribers': 1}.items()])
    program = make_program(scene, 'outer_bends', hold_time=HOLD, ramp_time=RAMP,
                           start=start[np.argsort(order)])
    probe = Node('probe', context=rclpy_context)
    clock = probe.create_publisher(Clock, '/clock', 10)
    step = {'now': START_NS}
    received = []
    with spinning(rclpy_context, node, probe) as executor:
        def has_clock():
            clock.publish(_clock(START_NS))
            executor.spin_once(timeout_sec=0.05)
            return node.get_clock().now().nanoseconds == START_NS
        # the node gets its first /clock (the jump fires its sim-time timer) while it still waits
        # for a subscriber, so it cannot be ready, and start, at that jump
        assert spin_until(executor, has_clock, 20.0), node.phase
        assert node.phase in ('discovery', 'waiting'), node.phase
        probe.create_subscription(Float64MultiArray, '/ex_sim/pressure_command',
                                  lambda m: received.append((step['now'], np.array(m.data))),
                                  COMMAND_QOS)

        def ready():
            clock.publish(_clock(START_NS))
            executor.spin_once(timeout_sec=0.05)
            return node.phase == 'ready' and node.get_clock().now().nanoseconds == START_NS
        assert spin_until(executor, ready, 20.0), node.phase
        assert received == []                     # nothing before the clock moves
        steps = 0
        while not node.done.done() and steps < 200:
            steps += 1
            step['now'] = START_NS + steps * STEP_NS
            count = len(received)
            clock.publish(_clock(step['now']))
            assert spin_until(executor, lambda: len(received) > count, 10.0), (
                f'no command after clock step {steps}')
        spin_for(executor, 0.1)
    assert node.done.done() and node.done.result() == 0 and node.phase == 'done'
    stamps = np.array([ns for ns, _ in received])
    data = np.array([d for _, d in received])
    t = (stamps - stamps[0]) * 1e-9
    assert stamps[0] == START_NS + STEP_NS            # the first tick after the wait
    np.testing.assert_allclose(data, program.pressures_at(t)[:, order], rtol=0, atol=1e-6)
    # independent facts: starts at start_pressure, ends at mid range after the whole program,
    # holds outer_over (valve index 2 in the reversed order) at its maximum in hold 1
    np.testing.assert_allclose(data[0], start, atol=0)
    np.testing.assert_allclose(data[-1], 75e3, atol=0)
    assert t[-1] == pytest.approx(program.duration, abs=1e-9)
    assert program.duration == pytest.approx(3 * HOLD + 4 * RAMP, abs=1e-12)
    assert len(received) == round(program.duration / (STEP_NS * 1e-9)) + 1
    in_hold = (t >= RAMP) & (t <= RAMP + HOLD)
    np.testing.assert_allclose(data[in_hold], [[0, 0, 150e3, 75e3, 75e3, 75e3]] * in_hold.sum(),
                               atol=1e-6)
    assert np.all(data >= 0.0) and np.all(data <= 150e3)


def _args(namespace, *extra):
    return ['-r', f'__ns:={namespace}', '-p', 'program:=outer_bends', '-p',
            f'hold_time:={HOLD}', '-p', f'ramp_time:={RAMP}', '-p', 'discovery_time:=0.5',
            *extra]


def test_runs_to_the_end_and_refuses_to_fight_a_controller(rclpy_context, tmp_path):
    broken = tmp_path / 'holds.yaml'
    broken.write_text('holds:\n  - [0.0, 0.0, 0.0, 0.0, 0.0, 1.0e+6]\n')
    probe = Node('probe_controller', context=rclpy_context)
    received = {name: [] for name in ('run', 'refuse', 'force', 'interrupt')}
    for name, store in received.items():
        probe.create_subscription(Float64MultiArray, f'/ex_{name}/pressure_command',
                                  lambda m, store=store: store.append(np.array(m.data)),
                                  reliable(1000))
    # the "controller" already commands the valves of /ex_refuse and /ex_force
    probe.create_publisher(Float64MultiArray, '/ex_refuse/pressure_command', COMMAND_QOS)
    probe.create_publisher(Float64MultiArray, '/ex_force/pressure_command', COMMAND_QOS)
    with spinning(rclpy_context, probe) as executor:
        processes = {
            'run': start_node(MODULE, *_args('/ex_run')),
            'refuse': start_node(MODULE, *_args('/ex_refuse')),
            'force': start_node(MODULE, *_args('/ex_force', '-p', 'force:=true')),
            'interrupt': start_node(MODULE, *_args('/ex_interrupt', '-p', 'hold_time:=30.0')),
            'unknown': start_node(MODULE, '-p', 'program:=outer_bend'),
            'broken': start_node(MODULE, '-p', f'program:={broken}'),
        }
        outputs = {}
        try:
            # SIGINT once the long program runs
            assert spin_until(executor, lambda: received['interrupt'], 60.0)
            processes['interrupt'].send_signal(signal.SIGINT)
            assert spin_until(executor, lambda: all(
                p.poll() is not None for p in processes.values()), 90.0)
            spin_for(executor, 0.2)
        finally:
            for name, process in processes.items():
                if process.poll() is None:
                    process.kill()
                outputs[name] = process.communicate()[0]
    codes = {name: process.returncode for name, process in processes.items()}
    assert codes == {'run': 0, 'refuse': 1, 'force': 0, 'interrupt': 1, 'unknown': 2,
                     'broken': 2}, outputs
    assert 'Traceback' not in ''.join(outputs.values()), outputs
    for name in ('run', 'force'):
        assert 'hold 3 of 3' in outputs[name] and 'program done' in outputs[name], outputs[name]
        data = np.array(received[name])
        np.testing.assert_allclose(data[0], 75e3, atol=0)          # start: mid range
        np.testing.assert_allclose(data[-1], 75e3, atol=0)         # end: mid range
        assert data.max(axis=0).tolist() == [75e3] * 3 + [150e3] * 3
        assert np.all(data >= 0.0)
    assert 'also publish(es) /ex_force/pressure_command' in outputs['force'], outputs['force']
    assert received['refuse'] == []
    assert 'hold 1 of 3' not in outputs['interrupt'] and len(received['interrupt']) >= 1
    assert 'refusing to start: /probe_controller also publish(es) /ex_refuse/pressure_command' \
        in outputs['refuse'], outputs['refuse']
    assert "unknown excitation program 'outer_bend'" in outputs['unknown']
    assert len(outputs['unknown'].strip().splitlines()) == 1, outputs['unknown']
    assert f'{broken}: holds[0][5]: 1e+06 is outside the bounds [0, 150000] of outer_left' \
        in outputs['broken'], outputs['broken']


@pytest.mark.untimed
@pytest.mark.parametrize('overrides, match', [
    ({'start_pressure': [75e3] * 5}, 'start_pressure needs 6 values'),
    ({'end_pressure': [75e3] * 5 + [2e5]}, 'end_pressure: 200000 Pa for outer_left is outside '
     r'\[0, 150000\] Pa'),
    ({'start_pressure': [75e3] * 6, 'max_pressure': 50e3}, 'start_pressure: 75000 Pa for '
     r'inner_over is outside \[0, 50000\]'),
    ({'valve_names': ['a', 'b']}, 'must be a permutation'),
    ({'scene': 'tendon_6f_8c'}, "unknown excitation program 'bends'"),
    ({'scene': 'no_such_scene'}, 'no scene no_such_scene'),
])
def test_invalid_parameters_stop_the_node(rclpy_context, overrides, match):
    from cbha_inverse.ros.common.params import ParameterError
    with pytest.raises(ParameterError, match=match):
        ExciteNode(context=rclpy_context, parameter_overrides=[
            Parameter(k, value=v) for k, v in overrides.items()])
