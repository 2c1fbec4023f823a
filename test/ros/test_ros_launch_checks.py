"""
``cbha_launch`` checks what the user gives the nodes before starting any, and runs one scene.

Refused before a node starts (exit 2, one line naming the nearest valid name): a params-file
section that matches no node of the composition (``/cbha/solver:``), a parameter the node does
not declare (in a file or a ``-p <node>.<parameter>:=<value>``), a value it would refuse. One
scene for the cell: a scene set on one node (its ``<node>_params`` file, ``-p``) is every node's
that loads one, unless the user sets them different ones (a one-line warning). The real launch:
``inverse_solver_params`` sets the tendon scene, and the simulator runs it too (it accepts every
command). A Ctrl-C at several moments of a launch that checks files is a clean stop.
"""

import re
import signal
import subprocess
import sys
import time

from cbha_inverse.ros.launch.checks import parameter_value, section_matches
from cbha_inverse.ros.launch.compositions import ArgumentError, COMPOSITIONS, resolve
import pytest
from ros_helpers import child_env, REPO_ROOT, spin_until, spinning

SIM = COMPOSITIONS['sim']


def _params(folder, name, text):
    path = folder / name
    path.write_text(text)
    return str(path)


def _scene_file(folder, scene, name='solver.yaml', section='/**'):
    return _params(folder, name, f'{section}:\n  ros__parameters:\n    scene: {scene}\n')


def _launch(*args, dry_run=False):
    return subprocess.run(
        [sys.executable, '-m', 'cbha_inverse.ros.launch.launcher', 'sim',
         *(['--dry-run'] if dry_run else []), *args],
        env=child_env(), capture_output=True, text=True, timeout=120)


@pytest.mark.parametrize('key, node, matches', [
    ('/**', '/cbha/inverse_solver', True), ('/cbha/inverse_solver', '/cbha/inverse_solver', True),
    ('/cbha/*', '/cbha/inverse_solver', True),
    ('/**/inverse_solver', '/cbha/inverse_solver', True),
    ('/*/inverse_solver', '/cbha/inverse_solver', True), ('/cbha/**', '/cbha/cbha_sim', True),
    ('cbha/inverse_solver', '/cbha/inverse_solver', True),
    # measured on rclpy 7.1: without its leading / a name is from the root namespace
    ('inverse_solver', '/cbha/inverse_solver', False), ('*', '/cbha/inverse_solver', False),
    ('inverse_solver', '/inverse_solver', True), ('/**/inverse_solver', '/inverse_solver', True),
    ('/cbha/solver', '/cbha/inverse_solver', False), ('/cbha/*', '/left/inverse_solver', False),
])
def test_sections_match_nodes_as_ros_matches_them(key, node, matches):
    assert section_matches(key, node) == matches


def test_p_values_are_typed_as_ros2_types_them():
    assert parameter_value('0.3') == 0.3 and parameter_value('3') == 3
    assert parameter_value('true') is True and parameter_value('open') == 'open'
    assert parameter_value('[1.0, 2.0]') == [1.0, 2.0]
    assert parameter_value('[a, b]') == ['a', 'b']
    assert parameter_value('[1, a]') == '[1, a]' and parameter_value('{a: 1}') == '{a: 1}'


@pytest.mark.parametrize('args, message', [
    (['inverse_solver_params:={bad_key}'],
     '{bad_key}: /cbha/solver: applies to no node of sim (/cbha/trajectory, '
     '/cbha/inverse_solver, /cbha/cbha_sim, /cbha/stereo_tracker, /cbha/shape_estimator); did '
     "you mean '/cbha/inverse_solver'?"),
    (['inverse_solver_params:={bad_name}'],
     '{bad_name}: /cbha/inverse_solver.ros__parameters.loop_gian: unknown parameter of '
     "inverse_solver, did you mean 'loop_gain'?"),
    (['-p', 'inverse_solver.loop_gian:=0.2'],
     '-p inverse_solver.loop_gian:=0.2: unknown parameter of inverse_solver, did you mean '
     "'loop_gain'?"),
    (['-p', 'cbha_sim.noise_std:=1'],
     '-p cbha_sim.noise_std:=1: noise_std must be of type double (write floats with a decimal '
     'point: 1.0, not 1), got 1'),
    (['-p', 'solver.loop_gain:=0.2'],
     "-p solver.<parameter>: sim starts no node solver, did you mean 'inverse_solver'?"),
    (['-p', 'loop_gain:=0.2'],
     '-p loop_gain:=0.2: write -p <node>.<parameter>:=<value> (-p inverse_solver.loop_gain:=0.2)'),
])
def test_what_no_node_would_read_is_refused_before_any_starts(args, message, tmp_path):
    files = {'bad_key': _scene_file(tmp_path, 'tendon_6f_8c', 'key.yaml', '/cbha/solver'),
             'bad_name': _params(tmp_path, 'name.yaml', '/cbha/inverse_solver:\n'
                                 '  ros__parameters:\n    loop_gian: 0.2\n')}
    args = [arg.format(**files) for arg in args]
    start = time.monotonic()
    result = _launch(*args)     # not a dry run: it would start the nodes
    assert result.returncode == 2, result
    assert result.stderr == f'cbha_launch: error: {message.format(**files)}\n', result.stderr
    assert result.stdout == '', result.stdout       # no node started, nothing announced
    assert time.monotonic() - start < 60.0


def test_a_scene_set_on_one_node_is_the_cells(tmp_path):
    solver = _scene_file(tmp_path, 'tendon_6f_8c')
    warnings = []
    nodes = {p.executable: p for p in resolve(SIM, {'inverse_solver_params': solver,
                                                    'feedback': 'proprio'}, warnings=warnings)}
    assert 'scene' not in nodes['inverse_solver'].parameters
    assert nodes['cbha_sim'].parameters['scene'] == 'tendon_6f_8c'
    assert nodes['shape_estimator'].parameters['scene'] == 'tendon_6f_8c'
    assert warnings == []
    # through -p as well; a -p override wins over the node's file
    nodes = {p.executable: p for p in resolve(SIM, {}, {'cbha_sim': {'scene': 'tendon_6f_8c'}})}
    assert nodes['inverse_solver'].parameters['scene'] == 'tendon_6f_8c'
    assert nodes['cbha_sim'].parameters['scene'] == 'tendon_6f_8c'
    # the same scene written two ways is one scene
    plant = _scene_file(tmp_path, 'tendon_6f_8c.yaml', 'plant.yaml')
    resolve(SIM, {'inverse_solver_params': solver, 'cbha_sim_params': plant}, warnings=warnings)
    assert warnings == []
    # and the scene:= argument still wins over nothing but agrees or conflicts with the nodes'
    with pytest.raises(ArgumentError, match=re.escape(
            'scene:=cbha.yaml conflicts with scene: tendon_6f_8c in -p cbha_sim.scene')):
        resolve(SIM, {'scene': 'cbha.yaml'}, {'cbha_sim': {'scene': 'tendon_6f_8c'}})


def test_different_scenes_given_on_purpose_run_with_one_warning(tmp_path):
    solver = _scene_file(tmp_path, 'tendon_6f_8c')
    plant = _scene_file(tmp_path, 'cbha.yaml', 'plant.yaml')
    result = _launch(f'inverse_solver_params:={solver}', f'cbha_sim_params:={plant}',
                     dry_run=True)
    assert result.returncode == 0, result
    assert result.stderr == (
        f'cbha_launch: warning: the nodes load different scenes: inverse_solver tendon_6f_8c '
        f'({solver}), cbha_sim cbha.yaml ({plant})\n'), result.stderr
    lines = dict(line.split(': ', 1) for line in result.stdout.splitlines())
    assert f'--params-file {plant}' in lines['cbha_sim']
    import shutil
    for overrides in set(re.findall(r'(\S+/cbha_launch_\w+)/', result.stdout)):
        shutil.rmtree(overrides, ignore_errors=True)


@pytest.fixture
def tendon_trajectory(tmp_path):
    """Write a trajectory params file for the tendon trunk (a 10 mm circle in reach)."""
    text = (REPO_ROOT / 'config' / 'trajectory.yaml').read_text()
    return _params(tmp_path, 'trajectory.yaml', text.replace(
        'center: [0.2308, 0.0, -0.0292]', 'center: [0.117, 0.0, -0.005]').replace(
        'radius: 0.06', 'radius: 0.01'))


@pytest.mark.timing
def test_the_simulator_runs_the_scene_of_the_controllers_file(rclpy_context, tmp_path,
                                                              tendon_trajectory):
    """``cbha_launch sim inverse_solver_params:=FILE`` (FILE: the tendon scene) tracks."""
    from diagnostic_msgs.msg import DiagnosticArray
    from rclpy.node import Node
    solver = _scene_file(tmp_path, 'tendon_6f_8c')
    plant = {}
    listener = Node('plant_listener', context=rclpy_context)

    def on_diagnostics(message):
        for status in message.status:
            if status.name == 'cbha_sim: plant':
                plant.update({kv.key: kv.value for kv in status.values})

    listener.create_subscription(DiagnosticArray, '/diagnostics', on_diagnostics, 10)
    process = subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.launch.launcher', 'sim',
         f'inverse_solver_params:={solver}', f'trajectory_params:={tendon_trajectory}'],
        env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        with spinning(rclpy_context, listener) as executor:
            running = spin_until(executor, lambda: int(plant.get('accepted_commands', 0)) >= 50
                                 or process.poll() is not None, 120.0)
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert running and int(plant.get('accepted_commands', 0)) >= 50, (plant, output)
    assert plant['rejected_total'] == '0', plant
    assert re.search(r'^\[cbha_sim\] .*plant tendon_6f_8c ', output, re.MULTILINE), output
    assert re.search(r'^\[inverse_solver\] .*scene tendon_6f_8c: 8 valves', output,
                     re.MULTILINE), output
    assert process.returncode == 0 and 'Traceback' not in output, output


def _handles_sigterm(pid):
    from pathlib import Path
    try:
        status = Path(f'/proc/{pid}/status').read_text().splitlines()
    except OSError:
        return False
    caught = next(line.split()[1] for line in status if line.startswith('SigCgt:'))
    return bool(int(caught, 16) >> (signal.SIGTERM - 1) & 1)


@pytest.mark.timing
@pytest.mark.parametrize('delay', [0.05, 0.2, 0.5, 1.5, 4.0])
def test_ctrl_c_while_the_launch_checks_and_starts_is_a_clean_stop(delay, tmp_path):
    """From the launcher's quiet stop: its checks (node modules' imports), the nodes' start."""
    solver = _scene_file(tmp_path, 'tendon_6f_8c')
    process = subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.launch.launcher', 'sim',
         f'inverse_solver_params:={solver}', '-p', 'cbha_sim.noise_std:=0.0'],
        env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        deadline = time.monotonic() + 60.0
        while not _handles_sigterm(process.pid) and process.poll() is None:
            assert time.monotonic() < deadline, 'cbha_launch set no stop handler within 60 s'
            time.sleep(0.002)
        time.sleep(delay)
        process.send_signal(signal.SIGINT)
        output, _ = process.communicate(timeout=60)
    finally:
        if process.poll() is None:
            process.kill()
            process.communicate()
    assert process.returncode in (0, 130), output
    assert 'Traceback' not in output and 'Fatal Python error' not in output, output
