"""
Every installed executable, started the way ``ros2 run cbha_inverse <exe>`` starts it.

After a colcon build, ``<prefix>/lib/cbha_inverse`` must hold exactly the console scripts of
setup.py. Every executable is run with ``--help`` (exit 0, its usage). A node (it has a params
file ``config/<exe>.yaml``) must list every parameter of its installed params file there, and is
then started with its params file and one parameter below its range (read from that help), so
its ``main`` runs up to parameter validation and exits 2 naming the parameter. A renamed or
missing entry point, a module that no longer imports or a ``main`` that does not reach the node
fails here.
"""

import ast
import os
from pathlib import Path
import re
import shutil
import subprocess

import pytest
from ros_helpers import colcon_build, install_env, REPO_ROOT
import yaml

PACKAGE = 'cbha_inverse'


def _console_scripts():
    """Return the executable names of setup.py's CONSOLE_SCRIPTS (read, not imported)."""
    tree = ast.parse((REPO_ROOT / 'setup.py').read_text())
    for node in ast.walk(tree):
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and getattr(node.targets[0], 'id', None) == 'CONSOLE_SCRIPTS'):
            return sorted(entry.split('=')[0].strip() for entry in ast.literal_eval(node.value))
    raise AssertionError('setup.py has no CONSOLE_SCRIPTS list')


@pytest.fixture(scope='module')
def installed_prefix(tmp_path_factory):
    """Build the package with colcon; yield the package prefix found through the ament index."""
    from ament_index_python.packages import get_package_prefix
    work = tmp_path_factory.mktemp('colcon_executables')
    install = colcon_build(work)
    previous = os.environ.get('AMENT_PREFIX_PATH')
    os.environ['AMENT_PREFIX_PATH'] = str(install / PACKAGE)
    try:
        prefix = Path(get_package_prefix(PACKAGE))
    finally:
        if previous is None:
            os.environ.pop('AMENT_PREFIX_PATH')
        else:
            os.environ['AMENT_PREFIX_PATH'] = previous
    yield prefix
    shutil.rmtree(work, ignore_errors=True)


def _run_all(executables, env, cwd, arguments):
    """Start every ``(name, argument list)`` at once; return ``{name: (exit code, output)}``."""
    processes = {name: subprocess.Popen([str(executables / name), *args], env=env, cwd=cwd,
                                        stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                                        text=True)
                 for name, args in arguments.items()}
    return {name: (process.wait(timeout=120), process.stdout.read())
            for name, process in processes.items()}


def test_every_installed_executable_starts(installed_prefix):
    executables = installed_prefix / 'lib' / PACKAGE
    names = _console_scripts()
    assert sorted(p.name for p in executables.iterdir()) == names
    config = installed_prefix / 'share' / PACKAGE / 'config'
    nodes = [name for name in names if (config / f'{name}.yaml').is_file()]
    assert {'trajectory', 'inverse_solver', 'cbha_sim'} <= set(nodes)
    env = install_env(installed_prefix)
    helps = _run_all(executables, env, installed_prefix, {name: ['--help'] for name in names})
    below_range = {}
    for name, (code, output) in helps.items():
        assert code == 0, f'{name}: exit {code}\n{output}'
        assert output.startswith(f'usage: {name}'), f'{name}:\n{output}'
        if name in nodes:
            params = yaml.safe_load((config / f'{name}.yaml').read_text())['/**']
            for key in params['ros__parameters']:
                assert re.search(rf'^  {re.escape(key)} \(', output, re.MULTILINE), (
                    f'{name} --help does not list {key}')
            ranged = re.search(r'^  (\w+) \(double, default [^,]+, range \[([-+\d.e]+),',
                               output, re.MULTILINE)
            assert ranged, f'{name} lists no ranged double parameter'
            low = float(ranged.group(2))
            below_range[name] = (ranged.group(1), low - 1.0 - abs(low))
    starts = _run_all(executables, env, installed_prefix, {
        name: ['--ros-args', '--params-file', str(config / f'{name}.yaml'), '-p',
               f'{key}:={value!r}'] for name, (key, value) in below_range.items()})
    for name, (code, output) in starts.items():
        key = below_range[name][0]
        assert code == 2, f'{name} -p {key}: exit {code}\n{output}'
        assert key in output and 'Traceback' not in output, f'{name}:\n{output}'
