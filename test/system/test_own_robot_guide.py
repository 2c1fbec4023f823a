"""
The own-robot guide (docs/own-robot.md) runs as written.

The test copies the guide's example, ``docs/examples/rod_robot/``, to a temporary folder, checks
that the YAML shown in the guide is the files' content, and runs the guide's commands there:
``condense_segment`` (real gmsh and FEM; once, each test gets a copy of its result),
``cbha_scene check`` and ``cbha_launch sim``, the last over real DDS until the controller commands
the simulated rod, then SIGINT; and step 5's commands (``cbha_launch robot driver:=none``,
``trajectory``, the ``cbha_sim`` stand-in for the user's driver and sensor), without a Robotino:
the controller waits (at WARN, the line the guide quotes) and commands nothing until the
stand-in's first measurement, the closed loop runs, and the guide's ``ros2 param set`` (through
rclpy's parameter client: no ``ros2`` CLI here) tunes it live.
"""

from pathlib import Path
import re
import shlex
import shutil
import signal
import subprocess
import sys
import threading

from cbha_inverse.fem.segment_io import load_segment
import numpy as np
import pytest
from ros_helpers import child_env, interrupt, loop_listener, reaped, REPO_ROOT, spin_until
import yaml

GUIDE = REPO_ROOT / 'docs' / 'own-robot.md'
EXAMPLE = REPO_ROOT / 'docs' / 'examples' / 'rod_robot'
SCRIPTS = dict(re.findall(r"'(\w+) = ([\w.]+):main'", (REPO_ROOT / 'setup.py').read_text()))


def _blocks(language):
    return re.findall(rf'```{language}\n(.*?)```', GUIDE.read_text(), re.DOTALL)


def _commands(block=0):
    """Return the commands of a ``sh`` block of the guide, after ``cd``: (executable, args)."""
    lines = [line.split('#')[0].strip() for line in _blocks('sh')[block].splitlines()]
    commands = [shlex.split(line) for line in lines if line and not line.startswith(('cp ', 'cd '))
                and '&&' not in line]
    expected = (['condense_segment', 'cbha_scene', 'cbha_launch'] if block == 0 else
                ['cbha_launch', 'trajectory', 'cbha_sim'])
    assert [c[0] for c in commands] == expected
    return commands


def _run(command, cwd, **kwargs):
    executable, *args = command
    return subprocess.Popen([sys.executable, '-m', SCRIPTS[executable], *args], cwd=cwd,
                            env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True, **kwargs)


@pytest.fixture(scope='module')
def condensed(tmp_path_factory):
    """
    Run the guide's first command, ``condense_segment``, once in a copy of the example.

    Returns
    -------
    work : pathlib.Path
        The copy, with the condensed segment (the tests copy it again: each its own folder).
    result : tuple
        ``condense_segment``'s exit code and stderr.

    """
    work = tmp_path_factory.mktemp('guide') / 'my_robot'
    shutil.copytree(EXAMPLE, work)
    process = _run(_commands()[0], work)
    _, err = process.communicate(timeout=300)
    return work, (process.returncode, err)


def _copy(condensed, tmp_path):
    """Return a fresh copy of the condensed example in ``tmp_path``; assert the condensing."""
    work, (returncode, err) = condensed
    assert returncode == 0, err
    return Path(shutil.copytree(work, tmp_path / 'my_robot'))


@pytest.mark.untimed
def test_guide_shows_the_example_files():
    shown = {block.splitlines()[0]: block for block in _blocks('yaml')}
    for path in sorted(EXAMPLE.iterdir()):
        key = f'# docs/examples/rod_robot/{path.name}: '
        block = next((b for first, b in shown.items() if first.startswith(key)), None)
        assert block is not None, f'the guide does not show {path.name}'
        assert block == path.read_text(), f'the guide shows another {path.name}'


@pytest.mark.untimed
@pytest.mark.parametrize('index', range(len(_blocks('python'))))
def test_guide_python_runs_as_written(index, tmp_path):
    """Every Python block of the guide runs in the venv and prints what it computes."""
    done = subprocess.run([sys.executable, '-c', _blocks('python')[index]], cwd=tmp_path,
                          env=child_env(), capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert done.stdout.strip(), 'the block printed nothing'


def test_guide_example_runs(condensed, tmp_path, rclpy_context):
    # the guide's first command, condense_segment, ran in the fixture
    work = _copy(condensed, tmp_path)
    _, check, launch = _commands()
    segment = load_segment(work / 'segments' / 'rod_segment.yaml')
    assert np.allclose(segment.rest_offset, [0.02, 0.0, 0.0])

    process = _run(check, work)
    out, err = process.communicate(timeout=300)
    assert process.returncode == 0, err
    for claim in ('tip at rest: [120.0, 0.0, -1.8] mm',
                  'workspace centre: [119.4, -0.0, -1.7] mm'):
        assert claim in out, out
    reach = [float(v) for v in re.findall(r'\|(\d+\.\d) mm\|', out)]
    assert len(reach) == 4 and all(36.0 < v < 38.0 for v in reach), out

    executor, listener, commands, tips = loop_listener(rclpy_context)
    process = _run(launch, work)
    try:
        with reaped(process):
            ran = spin_until(executor, lambda: len(commands) >= 20 and len(tips) >= 20
                             or process.poll() is not None, 90.0)
            alive = process.poll() is None
            out, err = interrupt(process)
    finally:
        executor.shutdown()
        listener.destroy_node()
    assert ran and alive, f'{len(commands)} commands, {len(tips)} tips:\n{out}\n{err}'
    assert process.returncode == 0, out
    assert 'scene rod_robot: 4 valves' in out, out
    # Ctrl-C stops all three, cleanly
    assert 'exit statuses: trajectory 0, inverse_solver 0, cbha_sim 0' in out, out
    assert 'Traceback' not in out + err, out + err
    assert all(len(c.data) == 4 for c in commands)


def test_guide_error_example_is_what_the_command_prints(condensed, tmp_path):
    work = _copy(condensed, tmp_path)
    scene = work / 'rod_robot.yaml'
    text = scene.read_text()
    second = text.index('name: tendon_90')
    scene.write_text(text[:second] + text[second:].replace('max_tension: 10.0',
                                                           'max_tension: -10.0', 1))
    shown = re.search(r'`(cbha_scene: error: [^`]+)`', GUIDE.read_text()).group(1)
    process = _run(['cbha_scene', 'check', 'rod_robot.yaml'], work)
    out, err = process.communicate(timeout=120)
    assert process.returncode == 2
    assert err.strip() == shown


class _Output:
    """The lines a child process prints (stdout and stderr), read as they come."""

    def __init__(self, process):
        self.lines = []
        self.threads = [threading.Thread(target=self._read, args=(stream,), daemon=True)
                        for stream in (process.stdout, process.stderr)]
        for thread in self.threads:
            thread.start()

    def _read(self, stream):
        for line in stream:
            self.lines.append(line.rstrip('\n'))

    def text(self):
        for thread in self.threads:
            thread.join(timeout=30)
        return '\n'.join(self.lines)


def _guide_claims():
    """Return what step 5 says the controller logs while it waits, and its live-parameter set."""
    text = GUIDE.read_text()
    waiting = re.search(r'\(`(closed loop, no measurement yet on [^`]+)`, at WARN\)', text)
    node, name, value = re.search(r'`ros2 param set (\S+) (\w+) (\S+)`', text).groups()
    return waiting.group(1), node, name, yaml.safe_load(value)


def test_guide_own_driver_step_runs_without_a_robotino(condensed, tmp_path, rclpy_context):
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    waiting, node, name, value = _guide_claims()
    work = _copy(condensed, tmp_path)
    executor, listener, commands, tips = loop_listener(rclpy_context)
    launch, trajectory, stand_in = _commands(1)
    # the controller and the targets first: it waits, at WARN, and commands nothing
    processes = [_run(launch, work), _run(trajectory, work)]
    outputs = [_Output(p) for p in processes]
    try:
        told = spin_until(executor, lambda: any(waiting in line and 'WARN' in line
                                                for line in outputs[0].lines)
                          or any(p.poll() is not None for p in processes), 120.0)
        spin_until(executor, lambda: False, 0.5)
        assert told and not commands, (len(commands), outputs[0].lines)
        # then the stand-in for the user's driver and sensor: the closed loop runs
        processes.append(_run(stand_in, work))
        outputs.append(_Output(processes[-1]))
        ran = spin_until(executor, lambda: len(commands) >= 20 and len(tips) >= 20
                         or any(p.poll() is not None for p in processes), 120.0)
        # the guide's live tuning (ros2 param set, here through rclpy's parameter client)
        client = AsyncParameterClient(listener, node)
        assert client.wait_for_services(timeout_sec=20.0)
        future = client.set_parameters([Parameter(name, value=value)])
        assert spin_until(executor, future.done, 20.0)
        [result] = future.result().results
        assert result.successful, result.reason
        alive = [p.poll() is None for p in processes]
        for process in processes:
            process.send_signal(signal.SIGINT)
        for process in processes:
            process.wait(timeout=30)
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.wait()
        executor.shutdown()
        listener.destroy_node()
    texts = [output.text() for output in outputs]
    launch_out = texts[0]
    assert ran and all(alive), f'{len(commands)} commands, {len(tips)} tips: {texts}'
    assert [p.returncode for p in processes] == [0, 0, 0], texts
    # the controller only: no bridge, no tracker; the params file's scene and closed loop hold
    assert re.search(r'\] robot: inverse_solver \(/cbha\)$', launch_out, re.MULTILINE), launch_out
    assert 'scene rod_robot: 4 valves' in launch_out and 'closed loop' in launch_out, launch_out
    assert f'parameters set: {name} {value}' in launch_out, launch_out
    assert 'exit statuses: inverse_solver 0' in launch_out, launch_out
    assert 'Traceback' not in '\n'.join(texts), texts
    assert all(len(c.data) == 4 and max(c.data) <= 10.0 for c in commands)
