"""
``cbha_status`` over real DDS: the block it prints from a running controller's ``/diagnostics``.

The controller runs in this process (closed loop, no feedback: it waits); ``cbha_status --once``
runs as a process and must show its decision, mode and the status line, and say that no driver
is there. Without any diagnostics it exits 1.
"""

import subprocess
import sys

from cbha_inverse.ros.console.status import status_lines
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
from ros_helpers import child_env, spin_until, spinning

SCENE = 'tendon_6f_8c'


def _status(*args):
    return subprocess.Popen([sys.executable, '-m', 'cbha_inverse.ros.console.status', *args],
                            env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)


def test_status_shows_the_controller_and_the_missing_driver(rclpy_context):
    from rclpy.parameter import Parameter
    names = list(load_scene(SCENE).actuator_names)
    # renamed (as a launch file may): its statuses carry the name it runs under
    solver = InverseSolverNode(
        context=rclpy_context, namespace='/cbha', cli_args=['--ros-args', '-r',
                                                            '__node:=left_solver'],
        parameter_overrides=[Parameter(name, value=value) for name, value in (
            ('scene', SCENE), ('valve_names', names), ('mode', 'closed'),
            ('diagnostics_period', 0.2))])
    with spinning(rclpy_context, solver) as executor:
        process = _status('--once', '--wait', '6')
        spin_until(executor, lambda: process.poll() is not None, 60.0)
        out, err = process.communicate(timeout=30)
    assert process.returncode == 0, err
    assert 'controller  waiting (closed loop): waiting for a target' in out, out
    assert 'driver      none on /diagnostics' in out, out
    assert 'OK    left_solver: control: waiting for a target (' in out, out


def test_status_without_diagnostics_exits_1():
    process = _status('--once', '--wait', '1')
    out, err = process.communicate(timeout=60)
    assert process.returncode == 1, err
    assert 'controller  no inverse_solver on /diagnostics' in out


def test_status_block_of_a_running_loop():
    control = (0, 'running (solved)', {
        'decision': 'run', 'mode': 'closed', 'measured_error_mm': '1.234', 'at_lower_bound':
        'tendon_1', 'at_upper_bound': 'tendon_0', 'feedback_age_s': '0.01', 'target_age_s': '0.02',
        'tick_median_ms': '0.4', 'tick_p99_ms': '1.2', 'latency_median_ms': 'nan'}, 9.0)
    driver = (1, 'no recent bha_readings from the driver', {'reading_age_s': 'inf'}, 9.5)
    lines = status_lines({'inverse_solver: control': control,
                          'robotino_bridge: driver': driver}, 10.0)
    assert lines[0] == 'controller  run (closed loop): running (solved)'
    assert lines[1].startswith(
        '            error 1.23 mm, predicted - mm, at upper bound tendon_0')
    assert 'tick median 0.400 ms, p99 1.200 ms; latency median - ms' in lines[3]
    assert lines[4] == ('driver      robotino_bridge: driver: WARN no recent bha_readings from '
                        'the driver, readings inf s old')
    assert 'WARN  robotino_bridge: driver: no recent bha_readings from the driver (0.5 s ago)' \
        in lines


def test_status_finds_renamed_nodes_by_their_task():
    """A status is named '<node name>: <task>': a renamed controller and plant are still found."""
    control = (0, 'waiting for a target', {'decision': 'waiting', 'mode': 'open'}, 9.0)
    plant = (0, 'ok', {'accepted_commands': '3'}, 9.0)
    others = {'trajectory: path': (0, 'running', {}, 9.0),
              'other: control': (0, 'not a controller', {}, 9.0)}
    lines = status_lines({**others, 'left_arm_solver: control': control,
                          'left_arm_sim: plant': plant}, 10.0)
    assert lines[0] == 'controller  waiting (open loop): waiting for a target'
    drivers = [line for line in lines if line.startswith('driver')]
    assert drivers == ['driver      left_arm_sim: plant: OK ok'], lines
