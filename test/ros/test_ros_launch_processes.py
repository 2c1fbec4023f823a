"""
``NodeProcesses``: how ``cbha_launch`` and ``cbha_demo`` start and stop node processes.

A node is ``python -m cbha_inverse.ros.nodes.<node>`` with its params files and overrides; it
starts with SIGINT and SIGTERM blocked until its quiet stop while loading is installed, so a stop
at once, during the interpreter's own start-up, is a quiet exit 0; a stop signal that reaches the
starting program while it stops its processes waits for the end of the stop.
"""

import io
import subprocess
import sys
import time

from cbha_inverse.paths import config_path
from cbha_inverse.ros.launch.compositions import NodeProcess
from cbha_inverse.ros.launch.processes import node_command, NodeProcesses
import pytest
from ros_helpers import child_env


def test_a_nodes_command_names_its_module_params_files_and_overrides(tmp_path):
    plain = NodeProcess('trajectory', '/cbha', ('a.yaml',), {})
    assert node_command(plain, tmp_path) == [
        sys.executable, '-m', 'cbha_inverse.ros.nodes.trajectory', '--ros-args',
        '-r', '__ns:=/cbha', '-r', '__node:=trajectory', '--params-file', 'a.yaml']
    assert not list(tmp_path.iterdir())
    solver = NodeProcess('inverse_solver', '/cbha', ('b.yaml',), {'mode': 'open'}, {'X': '1'})
    argv = node_command(solver, tmp_path)
    assert argv[:3] == ['env', 'X=1', sys.executable]
    assert argv[-2:] == ['--params-file', str(tmp_path / 'inverse_solver.yaml')]
    assert (tmp_path / 'inverse_solver.yaml').read_text() == (
        '/**:\n  ros__parameters:\n    mode: open\n')


@pytest.mark.parametrize('delay', [0.0, 0.5])
def test_a_node_stopped_at_any_moment_of_its_start_exits_0_quietly(delay, tmp_path):
    """At once (the interpreter still starts: the signal waits) or while the node loads."""
    out = io.StringIO()
    processes = NodeProcesses('test', env=child_env(), out=out)
    node = NodeProcess('trajectory', '/quiet_start', (str(config_path('trajectory.yaml')),), {})
    try:
        processes.start_node(node, tmp_path)
        time.sleep(delay)
    finally:
        statuses = processes.stop()
    output = out.getvalue()
    assert statuses == [('trajectory', 0)], output
    assert 'Traceback' not in output and 'Fatal Python error' not in output, output
    assert not processes.escalated, output
    if delay == 0.0:
        assert output == '[trajectory] trajectory: stopped by SIGINT while loading\n'


STOPPED_DURING_THE_STOP = """
import os, signal, sys, threading, time
from cbha_inverse.ros.launch import processes
processes.STOP_TIMEOUT = 1.0
group = processes.NodeProcesses('test', out=sys.stdout)
log = sys.argv[1]
child = group.start('probe', [sys.executable, '-c', sys.argv[2]], log=log, node=False)
while open(log).read() != 'ready\\n':
    time.sleep(0.01)
threading.Timer(0.3, os.kill, (os.getpid(), signal.SIGINT)).start()
try:
    group.stop()
except KeyboardInterrupt:
    print('KeyboardInterrupt after the stop, probe', child.returncode, flush=True)
"""
PROBE = """
import signal, sys, time
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, lambda *_: sys.exit(3))
print('ready', flush=True)
while True:
    time.sleep(0.01)
"""


def test_a_ctrl_c_during_the_stop_waits_for_its_end(tmp_path):
    result = subprocess.run(
        [sys.executable, '-c', STOPPED_DURING_THE_STOP, str(tmp_path / 'probe.log'), PROBE],
        env=child_env(), capture_output=True, text=True, timeout=60)
    assert result.stdout.splitlines() == [
        '[test] probe still running 1 s after SIGINT: SIGTERM',
        'KeyboardInterrupt after the stop, probe 3'], result
