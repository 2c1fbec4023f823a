"""
Every installed executable, started the way ``ros2 run cbha_inverse <exe>`` starts it.

After a colcon build, ``<prefix>/lib/cbha_inverse`` must hold exactly the console scripts of
setup.py. A command is run with ``--help`` (exit 0, its usage); a node (it has a params file
``config/<exe>.yaml``) is started with an out-of-range ``rate_hz``, so it runs its ``main`` up to
parameter validation and exits 2 naming the parameter. A renamed or missing entry point, a
module that no longer imports or a ``main`` that does not reach the node fails here.
"""

import ast
import os
from pathlib import Path
import shutil
import subprocess
import sys

import pytest

REPO_ROOT = Path(__file__).resolve().parents[1]
PACKAGE = 'cbha_inverse'


def _console_scripts():
    """Return the executable names of setup.py's CONSOLE_SCRIPTS (read, not imported)."""
    tree = ast.parse((REPO_ROOT / 'setup.py').read_text())
    for node in ast.walk(tree):
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and getattr(node.targets[0], 'id', None) == 'CONSOLE_SCRIPTS'):
            return sorted(entry.split('=')[0].strip() for entry in ast.literal_eval(node.value))
    raise AssertionError('setup.py has no CONSOLE_SCRIPTS list')


def _child_env(prefix):
    """Return the environment install/setup.sh would give, minus the wheels' bootstrap flag."""
    env = dict(os.environ)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    site = prefix / 'lib' / f'python{sys.version_info.major}.{sys.version_info.minor}'
    env['PYTHONPATH'] = os.pathsep.join([str(site / 'site-packages'), env.get('PYTHONPATH', '')])
    env['AMENT_PREFIX_PATH'] = os.pathsep.join([str(prefix), env.get('AMENT_PREFIX_PATH', '')])
    env['PYTHONUNBUFFERED'] = '1'
    return env


@pytest.fixture(scope='module')
def installed_prefix(tmp_path_factory):
    """Build the package with colcon; yield the package prefix found through the ament index."""
    from ament_index_python.packages import get_package_prefix
    colcon = Path(sys.executable).with_name('colcon')
    work = tmp_path_factory.mktemp('colcon_executables')
    result = subprocess.run(
        [str(colcon), '--log-base', str(work / 'log'), 'build', '--paths', str(REPO_ROOT),
         '--build-base', str(work / 'build'), '--install-base', str(work / 'install')],
        cwd=work, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, f'colcon build failed:\n{result.stdout}\n{result.stderr}'
    previous = os.environ.get('AMENT_PREFIX_PATH')
    os.environ['AMENT_PREFIX_PATH'] = str(work / 'install' / PACKAGE)
    try:
        prefix = Path(get_package_prefix(PACKAGE))
    finally:
        if previous is None:
            os.environ.pop('AMENT_PREFIX_PATH')
        else:
            os.environ['AMENT_PREFIX_PATH'] = previous
    yield prefix
    shutil.rmtree(work, ignore_errors=True)


def test_every_installed_executable_starts(installed_prefix):
    executables = installed_prefix / 'lib' / PACKAGE
    names = _console_scripts()
    assert sorted(p.name for p in executables.iterdir()) == names
    config = installed_prefix / 'share' / PACKAGE / 'config'
    nodes = [name for name in names if (config / f'{name}.yaml').is_file()]
    assert {'trajectory', 'inverse_solver', 'cbha_sim'} <= set(nodes)
    env = _child_env(installed_prefix)
    processes = {}
    for name in names:
        arguments = (['--ros-args', '--params-file', str(config / f'{name}.yaml'), '-p',
                      'rate_hz:=-1.0'] if name in nodes else ['--help'])
        processes[name] = subprocess.Popen(
            [str(executables / name), *arguments], env=env, cwd=installed_prefix,
            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    outcomes = {name: (process.wait(timeout=120), process.stdout.read())
                for name, process in processes.items()}
    for name, (code, output) in outcomes.items():
        if name in nodes:
            assert code == 2, f'{name}: exit {code}\n{output}'
            assert 'rate_hz' in output and 'Traceback' not in output, f'{name}:\n{output}'
        else:
            assert code == 0, f'{name}: exit {code}\n{output}'
            assert output.startswith(f'usage: {name}'), f'{name}:\n{output}'
