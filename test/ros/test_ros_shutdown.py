"""Every node as a real process: starts, works, and exits 0 on SIGINT and on SIGTERM."""

import signal
import time

from cbha_inverse.scene import load_scene
from ros_helpers import REPO_ROOT, start_node

SCENE = 'tendon_6f_8c'


def _wait_for_line(process, text, timeout):
    """Read the merged output until a line contains ``text``; return all lines read."""
    lines = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        line = process.stdout.readline()
        if not line:
            break
        lines.append(line)
        if text in line:
            return True, lines
    return False, lines


def test_nodes_exit_cleanly_on_sigint_and_sigterm():
    names = ','.join(load_scene(SCENE).actuator_names)
    valves = f'valve_names:=[{names}]'
    cases = [
        ('cbha_inverse.ros.nodes.trajectory', signal.SIGINT,
         ['--params-file', str(REPO_ROOT / 'config' / 'trajectory.yaml')]),
        ('cbha_inverse.ros.nodes.trajectory', signal.SIGTERM, []),
        ('cbha_inverse.ros.nodes.inverse_solver', signal.SIGINT,
         ['-p', f'scene:={SCENE}', '-p', valves]),
        ('cbha_inverse.ros.nodes.inverse_solver', signal.SIGTERM,
         ['-p', f'scene:={SCENE}', '-p', valves]),
        ('cbha_inverse.ros.nodes.cbha_sim', signal.SIGINT,
         ['-p', f'scene:={SCENE}', '-p', valves, '-p', 'max_pressure:=10.0']),
        ('cbha_inverse.ros.nodes.cbha_sim', signal.SIGTERM,
         ['-p', f'scene:={SCENE}', '-p', valves, '-p', 'max_pressure:=10.0']),
    ]
    processes = [(module, sig, start_node(module, '-r', f'__ns:=/shutdown{i}', *args))
                 for i, (module, sig, args) in enumerate(cases)]
    try:
        for module, sig, process in processes:
            # every node logs one INFO line once its publishers and timers exist
            ok, lines = _wait_for_line(process, '[INFO]', 60.0)
            assert ok, f'{module} did not start:\n{"".join(lines)}'
        time.sleep(0.5)
        for _, sig, process in processes:
            process.send_signal(sig)
        for module, sig, process in processes:
            output, _ = process.communicate(timeout=20)
            assert process.returncode == 0, (
                f'{module} exited {process.returncode} on {sig.name}:\n{output}')
            assert 'Traceback' not in output, output
    finally:
        for _, _, process in processes:
            if process.poll() is None:
                process.kill()
                process.communicate()
