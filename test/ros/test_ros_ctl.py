"""
``cbha_ctl`` over real DDS: a running controller's services and parameters from a shell.

The controller (``inverse_solver``, idle commands on: it publishes its vent command at ``rate_hz``)
runs in this process; ``cbha_ctl`` runs as the console script setup.py installs (the same three
lines pip writes, from its ``CONSOLE_SCRIPTS`` entry), one process per command, as a user would
type it. Each command's effect is seen on the node: ``disable`` holds the last command, ``vent``
publishes the vent command and ``enable`` resumes the ticks, ``reset`` counts a reset, ``param
set`` changes the vent command it publishes. Absent nodes, services and parameters are one line
naming the nearest one, exit 1.
"""

import ast
import subprocess
import sys

from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.console.ctl import full_name, service_name, value_text
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.scene import load_scene
import pytest
from ros_helpers import child_env, make_node, REPO_ROOT, spin_for, spin_until

SCENE = 'tendon_6f_8c'


def console_script(folder, name):
    """Write the console script ``name`` as pip installs it from setup.py; return its path."""
    tree = ast.parse((REPO_ROOT / 'setup.py').read_text())
    entries = next(ast.literal_eval(node.value) for node in ast.walk(tree)
                   if isinstance(node, ast.Assign) and len(node.targets) == 1
                   and getattr(node.targets[0], 'id', None) == 'CONSOLE_SCRIPTS')
    target = dict(entry.replace(' ', '').split('=') for entry in entries)[name]
    module, _, function = target.partition(':')
    script = folder / name
    script.write_text(f'#!{sys.executable}\nimport sys\nfrom {module} import {function}\n'
                      f'sys.exit({function}())\n')
    script.chmod(0o755)
    return script


@pytest.fixture(scope='module')
def ctl(tmp_path_factory):
    """Return the path of the ``cbha_ctl`` console script."""
    return console_script(tmp_path_factory.mktemp('bin'), 'cbha_ctl')


def _run(executor, ctl, *args):
    """Run ``cbha_ctl args`` while spinning ``executor``; return (status, stdout, stderr)."""
    [result] = _run_all(executor, ctl, [args])
    return result


def _run_all(executor, ctl, commands):
    """
    Run ``cbha_ctl args`` for every ``args`` of ``commands`` at once while spinning ``executor``.

    Returns
    -------
    list of tuple
        ``(status, stdout, stderr)`` of each command, in their order.

    """
    processes = [subprocess.Popen([str(ctl), *args], env=child_env(), stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True) for args in commands]
    try:
        assert spin_until(executor, lambda: all(p.poll() is not None for p in processes),
                          60.0), commands
        outputs = [process.communicate(timeout=10) for process in processes]
    finally:
        for process in processes:
            if process.poll() is None:
                process.kill()
                process.communicate()
    return [(process.returncode, out, err) for process, (out, err) in zip(processes, outputs)]


@pytest.fixture
def solver(rclpy_context):
    """Yield ``(executor, solver, commands)``: an idle controller and what it publishes."""
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from std_msgs.msg import Float64MultiArray
    names = list(load_scene(SCENE).actuator_names)
    node = make_node(InverseSolverNode, rclpy_context, scene=SCENE, valve_names=names,
                     publish_idle=True, rate_hz=50.0)
    listener = Node('ctl_listener', context=rclpy_context, namespace='/cbha')
    commands = []
    listener.create_subscription(Float64MultiArray, 'pressure_command', commands.append,
                                 COMMAND_QOS)
    executor = SingleThreadedExecutor(context=rclpy_context)
    executor.add_node(node)
    executor.add_node(listener)
    try:
        yield executor, node, commands
    finally:
        executor.shutdown()
        node.destroy_node()
        listener.destroy_node()


def test_disable_enable_and_reset_act_on_the_running_controller(solver, ctl):
    executor, node, commands = solver
    assert spin_until(executor, lambda: len(commands) >= 3, 20.0), 'no idle commands'

    status, out, err = _run(executor, ctl, 'disable')
    assert (status, err) == (0, ''), (status, out, err)
    assert out == ('/cbha/inverse_solver/enable: success: disabled: holding the last command '
                   'until ~/enable true\n')
    assert not node.enabled
    spin_for(executor, 0.2)     # a command already on its way
    commands.clear()
    spin_for(executor, 0.5)
    # on_disable: hold, the last command again at rate_hz (a silent controller looks lost)
    held = list(node.command)
    assert commands and all(list(c.data) == held for c in commands), len(commands)

    # vent: the vent command (vent_pressure, 0 Pa, within the bounds) until enabled again
    status, out, err = _run(executor, ctl, 'vent')
    assert (status, out, err) == (
        0, '/cbha/inverse_solver/vent: success: disabled: venting until ~/enable true\n', '')
    spin_for(executor, 0.2)
    commands.clear()
    spin_for(executor, 0.3)
    assert commands and all(list(c.data) == list(node.vent_command) for c in commands)

    status, out, err = _run(executor, ctl, 'enable', '--node', '/cbha/inverse_solver')
    assert (status, err) == (0, ''), (status, out, err)
    assert out.endswith('success: enabled: commanding\n')
    assert spin_until(executor, lambda: len(commands) >= 3, 5.0), 'commands did not resume'

    resets = node.resets
    status, out, err = _run(executor, ctl, 'reset')
    assert status == 0 and out.startswith('/cbha/inverse_solver/reset: success: model and '
                                          'correction at rest'), (status, out, err)
    assert node.resets == resets + 1

    # the generic call: the type of the service is read from the graph
    status, out, err = _run(executor, ctl, 'call', 'inverse_solver', '~/enable', 'false')
    assert status == 0 and 'disabled' in out, (status, out, err)
    assert not node.enabled
    status, _, err = _run(executor, ctl, 'call', 'inverse_solver', 'enable')
    assert status == 1 and err == ('cbha_ctl: /cbha/inverse_solver/enable is a SetBool: give '
                                   'true or false\n'), err


def test_a_parameter_set_from_the_shell_changes_the_running_node(solver, ctl):
    executor, node, commands = solver
    size = len(load_scene(SCENE).actuator_names)
    status, out, err = _run(executor, ctl, 'param', 'get', 'inverse_solver', 'vent_pressure')
    assert (status, out) == (0, 'Double value is: 0.0\n'), (status, out, err)

    status, out, err = _run(executor, ctl, 'param', 'set', 'inverse_solver', 'vent_pressure',
                            '1.5')
    assert (status, out, err) == (0, 'Set parameter successful\n', '')
    assert node.params.vent_pressure == 1.5
    commands.clear()
    assert spin_until(executor, lambda: len(commands) >= 3, 10.0)
    assert list(commands[-1].data) == [1.5] * size
    # the rest changes nothing (two sets the node refuses): run at once
    got, typed, read_only, listed, names = _run_all(executor, ctl, [
        ['param', 'get', '/cbha/inverse_solver', 'vent_pressure'],
        # refused by the node: the type (as ros2 param set types 2), and a read-only parameter
        ['param', 'set', 'inverse_solver', 'vent_pressure', '2'],
        ['param', 'set', 'inverse_solver', 'scene', 'cbha'],
        ['param', 'list', 'inverse_solver'],
        ['param', 'get', 'inverse_solver', 'valve_names']])
    assert got[1] == 'Double value is: 1.5\n', got
    status, out, err = typed
    assert status == 1 and err.startswith('cbha_ctl: Setting parameter failed: '), err
    status, out, err = read_only
    assert status == 1 and 'read-only' in err, err
    assert node.params.vent_pressure == 1.5 and node.get_parameter('scene').value == SCENE

    status, out, err = listed
    assert status == 0 and '  loop_gain\n' in out and '  vent_pressure\n' in out, out
    status, out, err = names
    assert out == f'String values are: {list(load_scene(SCENE).actuator_names)}\n', out


def test_absent_nodes_services_and_parameters_are_named_with_the_nearest(solver, ctl):
    executor, _, _ = solver
    spin_for(executor, 0.2)
    cases = [
        (['param', 'get', 'inverse_solver', 'loop_gian'],
         "node /cbha/inverse_solver has no parameter 'loop_gian'; did you mean 'loop_gain'?"),
        (['param', 'set', 'solver', 'loop_gain', '0.2', '--timeout', '1.5'],
         'no node /cbha/solver within 1.5 s; did you mean /cbha/inverse_solver?'),
        (['--namespace', '/left', 'disable', '--timeout', '1.5'],
         'no node /left/inverse_solver within 1.5 s; did you mean /cbha/inverse_solver?'),
        (['call', 'inverse_solver', 'vnet', '--timeout', '1.5'],
         'node /cbha/inverse_solver has no service /cbha/inverse_solver/vnet within 1.5 s; '
         'did you mean /cbha/inverse_solver/vent?'),
    ]
    # independent commands, run at once: three of them wait out their 1.5 s
    results = _run_all(executor, ctl, [args for args, _ in cases])
    for (args, message), result in zip(cases, results):
        assert result == (1, '', f'cbha_ctl: {message}\n'), args


def test_help_starts_no_ros_and_names_every_command(ctl):
    probe = ('import sys\nsys.argv = ["cbha_ctl", "--help"]\n'
             'from cbha_inverse.ros.console.ctl import main\n'
             'try:\n    main()\nexcept SystemExit as exc:\n'
             '    print("exit", exc.code, "rclpy" in sys.modules)\n')
    result = subprocess.run([sys.executable, '-c', probe], env=child_env(),
                            capture_output=True, text=True, timeout=60)
    assert result.stdout.startswith('usage: cbha_ctl'), result
    assert result.stdout.rstrip().endswith('exit 0 False'), result.stdout
    for command in ('call', 'enable', 'disable', 'reset', 'vent', 'hold', 'param'):
        assert command in result.stdout
    done = subprocess.run([str(ctl), 'param', 'set', '--help'], env=child_env(),
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and 'VALUE' in done.stdout, done


def test_names_resolve_as_for_the_nodes():
    assert full_name('inverse_solver', '/cbha') == '/cbha/inverse_solver'
    assert full_name('/left/inverse_solver', '/cbha') == '/left/inverse_solver'
    assert full_name('inverse_solver', '/') == '/inverse_solver'
    assert service_name('/cbha/inverse_solver', '~/enable') == '/cbha/inverse_solver/enable'
    assert service_name('/cbha/inverse_solver', 'enable') == '/cbha/inverse_solver/enable'
    assert service_name('/cbha/inverse_solver', '/other/enable') == '/other/enable'


def test_values_print_as_ros2_param_get_prints_them():
    from rclpy.parameter import get_parameter_value
    assert value_text(get_parameter_value('0.3')) == 'Double value is: 0.3'
    assert value_text(get_parameter_value('3')) == 'Integer value is: 3'
    assert value_text(get_parameter_value('true')) == 'Boolean value is: true'
    assert value_text(get_parameter_value('cbha')) == 'String value is: cbha'
    assert value_text(get_parameter_value('[1.0, 2.0]')) == 'Double values are: [1.0, 2.0]'


def _handles_sigterm(pid):
    """Whether process ``pid`` handles SIGTERM: its quiet stop while loading is installed."""
    from pathlib import Path
    import signal
    try:
        status = Path(f'/proc/{pid}/status').read_text().splitlines()
    except OSError:
        return False
    caught = next(line.split()[1] for line in status if line.startswith('SigCgt:'))
    return bool(int(caught, 16) >> (signal.SIGTERM - 1) & 1)


@pytest.mark.parametrize('delay', [0.0, 0.05, 0.1, 0.3, 1.0])
def test_ctrl_c_at_any_moment_of_the_commands_is_quiet(delay, tmp_path):
    """
    SIGINT ``delay`` seconds into ``cbha_ctl``, ``cbha_status`` and ``cbha_bag record``.

    Each runs as its console script and waits for something that never comes (a node, a
    diagnostic, a message). The delay counts from the program's quiet stop (its SIGTERM handler,
    installed when ``cbha_inverse.ros`` is imported, a few tens of ms in): before it the
    interpreter itself starts (twice, the ROS wheels re-execute it), which no program of the
    package can stop cleanly. Then: rclpy's import and start, the graph look-up, the wait.
    """
    import signal
    import time
    commands = {
        'cbha_ctl': (['param', 'get', 'absent_node', 'x', '--timeout', '30'], (0, 130)),
        'cbha_status': ([], (0,)),
        'cbha_bag': (['record', '/cbha/never', '-o', str(tmp_path / 'bag'), '--allow-empty'],
                     (0,)),
    }
    processes = {name: subprocess.Popen(
        [str(console_script(tmp_path, name)), *args], env=child_env(), stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True) for name, (args, _) in commands.items()}
    try:
        for name, process in processes.items():
            deadline = time.monotonic() + 30.0
            while not _handles_sigterm(process.pid) and process.poll() is None:
                assert time.monotonic() < deadline, f'{name} set no stop handler within 30 s'
                time.sleep(0.002)
        time.sleep(delay)
        for process in processes.values():
            process.send_signal(signal.SIGINT)
        outputs = {name: process.communicate(timeout=60)[0]
                   for name, process in processes.items()}
    finally:
        for process in processes.values():
            if process.poll() is None:
                process.kill()
                process.communicate()
    for name, process in processes.items():
        output = outputs[name]
        assert process.returncode in commands[name][1], (name, process.returncode, output)
        assert 'Traceback' not in output and 'Fatal Python error' not in output, (name, output)
        if 'while loading' in output:
            assert output == f'{name}: stopped by SIGINT while loading\n', (name, output)
