"""
``cbha_launch``'s node runner (``python -m cbha_inverse.ros.launch.node_process MODULE ...``).

A stand-in node module, written into a temporary folder, prints a line while it is imported and
then sleeps: a SIGINT or SIGTERM during that import ends the runner with status 0 and one line
(no traceback); once imported, its ``main`` gets ``[executable, *arguments]`` and its exit status
is the runner's.
"""

import os
import signal
import subprocess
import sys
import textwrap

import pytest
from ros_helpers import child_env

LOADING = 'stand-in node: loading'
SLOW_NODE = textwrap.dedent(f"""
    import sys
    import time
    print({LOADING!r}, flush=True)
    time.sleep(float(__import__('os').environ.get('STAND_IN_LOAD_SECONDS', '0')))


    def main(argv):
        print('main', argv, flush=True)
        return 3
    """)


def _runner(tmp_path, load_seconds, *args):
    (tmp_path / 'stand_in_node.py').write_text(SLOW_NODE)
    env = child_env()
    env['PYTHONPATH'] = os.pathsep.join([str(tmp_path), env['PYTHONPATH']])
    env['STAND_IN_LOAD_SECONDS'] = str(load_seconds)
    return subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.launch.node_process', 'stand_in_node', *args],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)


@pytest.mark.parametrize('signum', [signal.SIGINT, signal.SIGTERM])
def test_a_stop_while_the_node_loads_is_quiet(tmp_path, signum):
    process = _runner(tmp_path, 60.0, '--ros-args')
    try:
        assert process.stdout.readline().strip() == LOADING
        process.send_signal(signum)
        output, _ = process.communicate(timeout=30)
    finally:
        process.kill()
    assert process.returncode == 0, output
    assert output.strip() == (f'stand_in_node: stopped by {signal.Signals(signum).name} '
                              'while loading')


def test_the_loaded_node_runs_with_its_executable_name_and_arguments(tmp_path):
    process = _runner(tmp_path, 0.0, '--ros-args', '-r', '__ns:=/cbha')
    output, _ = process.communicate(timeout=60)
    assert process.returncode == 3, output
    assert output.splitlines() == [LOADING, "main ['stand_in_node', '--ros-args', '-r', "
                                            "'__ns:=/cbha']"]


def test_without_a_module_it_prints_its_usage():
    result = subprocess.run([sys.executable, '-m', 'cbha_inverse.ros.launch.node_process'],
                            env=child_env(), capture_output=True, text=True, timeout=60)
    assert result.returncode == 2
    assert result.stderr.startswith('usage: python -m cbha_inverse.ros.launch.node_process')
