"""
The compositions of ``launch/*.launch.py`` and ``cbha_launch``.

They name only what exists, and ``cbha_launch sim`` runs the nodes over real DDS and stops them
all on SIGINT.

``launch`` and ``launch_ros`` are not installable here: the launch files are checked as Python
source (syntax, imports, the composition they read), and ``cbha_launch`` runs the same table.
"""

import ast
from dataclasses import fields, is_dataclass
import importlib
import io
from itertools import product
import os
from pathlib import Path
import re
import shutil
import signal
import subprocess
import sys
import time

from cbha_inverse.ros.common.qos import MEASURED_QOS
from cbha_inverse.ros.launch import processes as node_processes
from cbha_inverse.ros.launch.compositions import (
    ArgumentError, COMPOSITIONS, node_module, resolve)
import pytest
from ros_helpers import child_env, interrupt, loop_listener, reaped, REPO_ROOT, spin_until
import yaml

SCRIPTS = dict(re.findall(r"'(\w+) = ([\w.]+):main'", (REPO_ROOT / 'setup.py').read_text()))
# the names of the Jazzy launch API the launch files may use
LAUNCH_API = {'launch': {'LaunchDescription'},
              'launch.actions': {'DeclareLaunchArgument', 'OpaqueFunction'},
              'launch.substitutions': {'LaunchConfiguration'},
              'launch_ros.actions': {'Node'},
              'cbha_inverse.ros.launch.compositions': {'COMPOSITIONS', 'resolve'}}


def _variants(composition):
    """Yield every valid combination of the composition's arguments that have choices."""
    choices = [(a.name, a.choices) for a in composition.arguments if a.choices]
    for values in product(*(c for _, c in choices)):
        variant = dict(zip((name for name, _ in choices), values))
        # the one refused combination (test_solver_transport_is_the_solvers_alone)
        if variant['solver_transport'] != 'udp-loopback' or variant['role'] == 'all':
            yield variant


def _declared_parameters(executable):
    module = importlib.import_module(node_module(executable))
    params = [v for k, v in vars(module).items() if k.endswith('Params') and is_dataclass(v)
              and v.__module__ == module.__name__]
    assert len(params) == 1, f'{executable}: {len(params)} *Params dataclasses'
    return {spec.metadata.get('ros_name') or spec.name for spec in fields(params[0])}


@pytest.mark.untimed
@pytest.mark.parametrize('name', sorted(COMPOSITIONS))
def test_every_executable_params_file_and_parameter_of_a_composition_exists(name):
    composition = COMPOSITIONS[name]
    named = {node.executable for node in composition.nodes}
    started = set()
    for values in _variants(composition):
        for process in resolve(composition, values):
            started.add(process.executable)
            assert SCRIPTS.get(process.executable) == node_module(process.executable), (
                f'{process.executable}: no console script {node_module(process.executable)}:main')
            for params in process.params_files:
                with open(params, encoding='utf-8') as f:
                    assert '/**' in yaml.safe_load(f), params
            unknown = set(process.parameters) - _declared_parameters(process.executable)
            assert not unknown, f'{process.executable} has no parameters {unknown}'
    assert started == named, f'never started: {named - started}'


@pytest.mark.untimed
@pytest.mark.parametrize('name', sorted(COMPOSITIONS))
def test_launch_file_reads_its_composition_and_names_only_the_launch_api(name):
    path = REPO_ROOT / 'launch' / f'{name}.launch.py'
    tree = ast.parse(path.read_text(), str(path))
    imported = {}
    for statement in tree.body:
        if isinstance(statement, ast.ImportFrom):
            imported.setdefault(statement.module, set()).update(a.name for a in statement.names)
        assert not isinstance(statement, ast.Import), f'{path}: import statement'
    for module, names in imported.items():
        assert module in LAUNCH_API and names <= LAUNCH_API[module], (module, names)
    reads = [node for node in ast.walk(tree) if isinstance(node, ast.Subscript)
             and isinstance(node.value, ast.Name) and node.value.id == 'COMPOSITIONS']
    assert [ast.literal_eval(node.slice) for node in reads] == [name]
    assert any(isinstance(node, ast.FunctionDef) and node.name == 'generate_launch_description'
               for node in tree.body)


@pytest.mark.untimed
def test_bad_arguments_exit_2_with_one_line():
    for args, message in ((['sim', 'bogus:=1'], "unknown argument 'bogus'"),
                          (['sim', 'mode:=half'], 'mode:=half is not one of open|closed'),
                          (['sim', 'inverse_solver_params:=/nonexistent.yaml'],
                           '/nonexistent.yaml: file: no such file')):
        result = subprocess.run([sys.executable, '-m', 'cbha_inverse.ros.launch.launcher', *args],
                                env=child_env(), capture_output=True, text=True, timeout=60)
        assert result.returncode == 2, result
        assert result.stderr.strip() == f'cbha_launch: error: {message}' or (
            result.stderr.count('\n') == 1 and message in result.stderr), result.stderr


def _launch(*args):
    return subprocess.Popen([sys.executable, '-m', 'cbha_inverse.ros.launch.launcher', 'sim',
                             *args],
                            env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


@pytest.fixture
def tendon_trajectory(tmp_path):
    """Write a trajectory params file for the tendon trunk (a 10 mm circle in reach)."""
    params = tmp_path / 'trajectory.yaml'
    text = (REPO_ROOT / 'config' / 'trajectory.yaml').read_text()
    params.write_text(text.replace('center: [0.2308, 0.0, -0.0292]', 'center: [0.117, 0.0, '
                                   '-0.005]').replace('radius: 0.06', 'radius: 0.01'))
    return params


def _node_threads(launcher_pid):
    """Return ``{node module: thread names}`` of the node processes a launcher started."""
    threads = {}
    for pid in (int(p) for p in os.listdir('/proc') if p.isdigit()):
        try:
            status = Path(f'/proc/{pid}/status').read_text()
            command = Path(f'/proc/{pid}/cmdline').read_bytes().split(b'\0')
            parent = int(re.search(r'^PPid:\s+(\d+)', status, re.MULTILINE).group(1))
            names = {(Path(f'/proc/{pid}/task') / t / 'comm').read_text().strip()
                     for t in os.listdir(f'/proc/{pid}/task')}
        except (FileNotFoundError, ProcessLookupError):
            continue
        modules = [c.decode() for c in command if c.startswith(b'cbha_inverse.ros.nodes.')]
        if parent == launcher_pid and modules:
            threads[modules[0].rsplit('.', 1)[1]] = names
    return threads


def test_cbha_launch_sim_runs_the_nodes_and_stops_them_all_on_sigint(rclpy_context,
                                                                     tendon_trajectory):
    executor, listener, commands, tips = loop_listener(rclpy_context)
    # the controller over UDP on 127.0.0.1, the other nodes with the test environment's
    # shared memory: the loop closes across the two
    process = _launch('scene:=tendon_6f_8c', f'trajectory_params:={tendon_trajectory}',
                      'solver_transport:=udp-loopback')
    try:
        with reaped(process):
            running = spin_until(executor, lambda: len(commands) >= 20 and len(tips) >= 20
                                 or process.poll() is not None, 60.0)
            alive = process.poll() is None
            threads = _node_threads(process.pid)
            output, _ = interrupt(process)
    finally:
        executor.shutdown()
        listener.destroy_node()
    assert running and alive, f'{len(commands)} commands, {len(tips)} tips:\n{output}'
    for node in ('trajectory', 'inverse_solver', 'cbha_sim'):
        assert re.search(rf'^\[{node}\] \[INFO\]', output, re.MULTILINE), f'no {node}:\n{output}'
    assert 'exit statuses: trajectory 0, inverse_solver 0, cbha_sim 0' in output, output
    assert process.returncode == 0, output
    assert 'Traceback' not in output, output
    # the composition's overrides reached the nodes: closed loop on the tendon scene
    assert all(len(c.data) == 8 for c in commands)
    assert sorted(threads) == ['cbha_sim', 'inverse_solver', 'trajectory'], threads
    shared_memory = {node for node, names in threads.items()
                     if any(name.startswith('dds.shm') for name in names)}
    assert shared_memory == {'cbha_sim', 'trajectory'}, threads


def test_cbha_launch_stops_every_node_when_one_fails(tmp_path):
    params = tmp_path / 'inverse_solver.yaml'
    # a value the launcher's checks cannot see (the number of valves is the scene's): the node
    # refuses it at start
    params.write_text('/**:\n  ros__parameters:\n    valve_names: [a, b]\n')
    process = _launch('scene:=tendon_6f_8c', f'inverse_solver_params:={params}')
    start = time.monotonic()
    output, _ = process.communicate(timeout=60)
    assert process.returncode == 2, output
    assert 'inverse_solver exited with status 2: stopping the others' in output
    assert re.search(r'exit statuses: trajectory 0, inverse_solver 2, cbha_sim 0', output), output
    assert time.monotonic() - start < 45.0


_STOP_PROBE = """
import signal, sys, time
signal.signal(signal.SIGINT, {sigint})
signal.signal(signal.SIGTERM, {sigterm})
print('ready', flush=True)
while True:
    time.sleep(0.01)
"""


@pytest.mark.untimed
def test_a_node_that_ignores_sigint_gets_sigterm_then_sigkill(monkeypatch, tmp_path):
    monkeypatch.setattr(node_processes, 'STOP_TIMEOUT', 0.5)
    monkeypatch.setattr(node_processes, 'TERM_TIMEOUT', 0.5)
    behaviours = {'stops': ('lambda *_: sys.exit(0)', 'signal.SIG_DFL'),
                  'needs_sigterm': ('signal.SIG_IGN', 'lambda *_: sys.exit(3)'),
                  'hangs': ('signal.SIG_IGN', 'signal.SIG_IGN')}
    out = io.StringIO()
    group = node_processes.NodeProcesses('cbha_launch', out=out)
    children = []
    try:
        for name, (sigint, sigterm) in behaviours.items():
            log = tmp_path / f'{name}.log'
            children.append(group.start(
                name, [sys.executable, '-c', _STOP_PROBE.format(sigint=sigint, sigterm=sigterm)],
                log=log, node=False))
            deadline = time.monotonic() + 60.0
            while log.read_text() != 'ready\n':
                assert time.monotonic() < deadline and children[-1].poll() is None, name
                time.sleep(0.01)
        start = time.monotonic()
        statuses = group.stop()
        elapsed = time.monotonic() - start
    finally:
        for child in children:
            child.kill()
            child.wait()
    assert statuses == [('stops', 0), ('needs_sigterm', 3), ('hangs', -signal.SIGKILL)]
    assert 1.0 <= elapsed < 5.0, elapsed
    assert group.escalated == {'needs_sigterm': 'SIGTERM', 'hangs': 'SIGKILL'}
    assert out.getvalue().splitlines() == [
        '[cbha_launch] needs_sigterm still running 0.5 s after SIGINT: SIGTERM',
        '[cbha_launch] hangs still running 0.5 s after SIGINT: SIGTERM',
        '[cbha_launch] hangs still running 0.5 s after SIGTERM: SIGKILL']


@pytest.mark.untimed
def test_rviz_view_shows_what_the_nodes_publish_with_matching_qos():
    from cbha_inverse.ros.nodes.inverse_solver import InverseSolverParams
    from cbha_inverse.ros.common.qos import MARKER_QOS, TARGET_QOS
    from rclpy.qos import ReliabilityPolicy

    view = yaml.safe_load((REPO_ROOT / 'rviz' / 'cbha.rviz').read_text())
    manager = view['Visualization Manager']
    assert manager['Global Options']['Fixed Frame'] == InverseSolverParams().frame_id
    published = {'/cbha/backbone': ('rviz_default_plugins/MarkerArray', MARKER_QOS),
                 '/cbha/tip/measured': ('rviz_default_plugins/PointStamped', MEASURED_QOS),
                 '/cbha/target': ('rviz_default_plugins/PointStamped', TARGET_QOS)}
    shown = {d['Topic']['Value']: d for d in manager['Displays'] if 'Topic' in d}
    assert set(shown) == set(published)
    for topic, (display_class, qos) in published.items():
        assert shown[topic]['Class'] == display_class
        reliable = qos.reliability == ReliabilityPolicy.RELIABLE
        assert shown[topic]['Topic']['Reliability Policy'] == (
            'Reliable' if reliable else 'Best Effort'), topic


def _user_params(tmp_path, **parameters):
    path = tmp_path / 'my_inverse_solver.yaml'
    path.write_text(yaml.safe_dump({'/**': {'ros__parameters': parameters}}))
    return str(path)


def _solver(processes):
    return next(p for p in processes if p.executable == 'inverse_solver')


@pytest.mark.untimed
def test_robot_driver_none_starts_no_bridge():
    robot = COMPOSITIONS['robot']
    assert 'robotino_bridge' in [p.executable for p in resolve(robot, {})]
    started = [p.executable for p in resolve(robot, {'driver': 'none', 'feedback': 'none'})]
    assert started == ['inverse_solver']
    with pytest.raises(ArgumentError, match='driver:=ros is not one of robotino|none'):
        resolve(robot, {'driver': 'ros'})


@pytest.mark.untimed
def test_a_users_params_file_wins_over_the_compositions_defaults(tmp_path):
    sim = COMPOSITIONS['sim']
    # the installed params file: the composition's defaults apply over it
    assert _solver(resolve(sim, {})).parameters == {'scene': 'cbha.yaml', 'mode': 'closed'}
    params = _user_params(tmp_path, scene='identified.yaml', mode='open', loop_gain=0.2)
    solver = _solver(resolve(sim, {'inverse_solver_params': params}))
    assert solver.params_files == (params,) and solver.parameters == {}
    # what the file does not set still gets the composition's default
    params = _user_params(tmp_path, loop_gain=0.2)
    assert _solver(resolve(sim, {'inverse_solver_params': params})).parameters == {
        'scene': 'cbha.yaml', 'mode': 'closed'}
    # an argument given explicitly applies, to the nodes whose file does not say otherwise
    params = _user_params(tmp_path, scene='identified.yaml')
    processes = resolve(sim, {'inverse_solver_params': params, 'mode': 'open'})
    assert _solver(processes).parameters == {'mode': 'open'}
    plant = next(p for p in processes if p.executable == 'cbha_sim')
    # one scene for the cell: the simulator loads the scene of the controller's file
    assert plant.parameters == {'scene': 'identified.yaml'}


@pytest.mark.untimed
def test_an_explicit_argument_that_contradicts_the_users_params_file_is_a_conflict(tmp_path):
    sim = COMPOSITIONS['sim']
    params = _user_params(tmp_path, scene='identified.yaml', mode='open')
    with pytest.raises(ArgumentError, match=r'scene:=cbha.yaml conflicts with scene: '
                       r'identified.yaml in .*my_inverse_solver.yaml'):
        resolve(sim, {'inverse_solver_params': params, 'scene': 'cbha.yaml'})
    agreed = resolve(sim, {'inverse_solver_params': params, 'scene': 'identified.yaml',
                           'mode': 'open'})
    assert _solver(agreed).parameters == {'scene': 'identified.yaml', 'mode': 'open'}
    result = subprocess.run([sys.executable, '-m', 'cbha_inverse.ros.launch.launcher', 'sim',
                             '--dry-run', f'inverse_solver_params:={params}', 'mode:=closed'],
                            env=child_env(), capture_output=True, text=True, timeout=60)
    assert result.returncode == 2, result
    assert result.stderr == (f'cbha_launch: error: mode:=closed conflicts with mode: open in '
                             f'{params} (give one of them)\n')


@pytest.mark.untimed
def test_dry_run_names_overrides_files_that_exist():
    result = subprocess.run([sys.executable, '-m', 'cbha_inverse.ros.launch.launcher', 'sim',
                             '--dry-run', 'mode:=open'],
                            env=child_env(), capture_output=True, text=True, timeout=60)
    assert result.returncode == 0, result
    files = re.findall(r'--params-file (\S+)', result.stdout)
    assert len(files) == 5, result.stdout
    overrides = [f for f in files if 'cbha_launch_' in f]
    try:
        assert overrides and all(Path(f).is_file() for f in overrides), result.stdout
        solver = next(f for f in overrides if f.endswith('inverse_solver.yaml'))
        assert yaml.safe_load(Path(solver).read_text()) == {
            '/**': {'ros__parameters': {'scene': 'cbha.yaml', 'mode': 'open'}}}
    finally:
        shutil.rmtree(Path(overrides[0]).parent, ignore_errors=True)


def _handles_sigterm(pid):
    """Whether process ``pid`` has a SIGTERM handler (``SigCgt`` of ``/proc/<pid>/status``)."""
    status = Path(f'/proc/{pid}/status').read_text().splitlines()
    caught = next(line.split()[1] for line in status if line.startswith('SigCgt:'))
    return bool(int(caught, 16) >> (signal.SIGTERM - 1) & 1)


@pytest.mark.parametrize('delay', [0.0, 0.3, 0.6, 1.0])
def test_sigint_at_any_moment_of_the_start_is_a_clean_stop(delay):
    """
    SIGINT ``delay`` seconds after cbha_launch's first line: status 0, no traceback.

    The delay counts from the launcher's stop handlers (Python sets none for SIGTERM, the import
    of ``cbha_inverse.ros`` before the launcher's module does): before them the interpreter
    itself still starts (twice: the ROS wheels re-exec it), which no program can stop cleanly,
    and which takes longer than 0.3 s on a loaded machine.
    """
    process = _launch('scene:=tendon_6f_8c')
    deadline = time.monotonic() + 60.0
    while not _handles_sigterm(process.pid) and process.poll() is None:
        assert time.monotonic() < deadline, 'cbha_launch set no stop handler within 60 s'
        time.sleep(0.002)
    time.sleep(delay)
    process.send_signal(signal.SIGINT)
    output, _ = process.communicate(timeout=60)
    assert process.returncode == 0, output
    assert 'Traceback' not in output and 'Fatal Python error' not in output, output
