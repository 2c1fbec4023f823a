"""
``--help`` of every executable, report and subcommand prints its usage and does no work.

No work, measured without a clock: after each ``--help`` not one numba kernel of the package has
been compiled or loaded from its cache (every dispatcher's ``signatures`` is still empty) and no
node has logged. ``cbha_report all --help`` used to run every benchmark first (minutes): its
kernels would be compiled here.
"""

import ast
import json
import subprocess
import sys

from ros_helpers import child_env, REPO_ROOT

# every console script with --help, then the groups and subcommands that have their own usage
EXTRA = [['cbha_report', name, '--help'] for name in (
    'all', 'bench', 'core', 'inverse', 'estimator', 'fem', 'stability', 'accuracy',
    'rao2021', 'touch')] + [
    ['cbha_bag', name, '--help'] for name in ('record', 'play', 'info', 'eval')] + [
    ['cbha_launch', name, '--help'] for name in ('sim', 'robot')] + [
    ['cbha_scene', 'check', '--help']]

PROBE = r"""
import contextlib, importlib, io, json, sys
from numba.core.dispatcher import Dispatcher

def compiled():
    names = []
    for name, module in list(sys.modules.items()):
        if name.startswith('cbha_inverse'):
            names += [f'{name}.{k}' for k, v in vars(module).items()
                      if isinstance(v, Dispatcher) and v.signatures]
    return names

def dispatchers():
    return sum(isinstance(v, Dispatcher) for name, module in list(sys.modules.items())
               if name.startswith('cbha_inverse') for v in vars(module).values())

results = []
for command, target in json.loads(sys.argv[1]):
    module, _, function = target.partition(':')
    sys.argv = list(command)
    out = io.StringIO()
    code = None
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(out):
        try:
            code = importlib.import_module(module).__dict__[function]()
        except SystemExit as exc:
            code = exc.code
    results.append({'command': command, 'code': code, 'out': out.getvalue(),
                    'compiled': compiled()})
print(json.dumps({'results': results, 'dispatchers': dispatchers()}))
"""


def _entry_points():
    tree = ast.parse((REPO_ROOT / 'setup.py').read_text())
    for node in ast.walk(tree):
        if (isinstance(node, ast.Assign) and len(node.targets) == 1
                and getattr(node.targets[0], 'id', None) == 'CONSOLE_SCRIPTS'):
            return dict(entry.replace(' ', '').split('=') for entry in
                        ast.literal_eval(node.value))
    raise AssertionError('setup.py has no CONSOLE_SCRIPTS list')


def test_help_compiles_nothing_and_runs_nothing():
    entries = _entry_points()
    commands = [[name, '--help'] for name in sorted(entries)] + EXTRA
    process = subprocess.run(
        [sys.executable, '-c', PROBE, json.dumps([[c, entries[c[0]]] for c in commands])],
        cwd=REPO_ROOT, env=child_env(), capture_output=True, text=True, timeout=300)
    assert process.returncode == 0, process.stderr
    report = json.loads(process.stdout.splitlines()[-1])
    # the scan sees the package's kernels (imported by the helps of the reports and nodes)
    assert report['dispatchers'] > 20, report['dispatchers']
    for result in report['results']:
        command, out = ' '.join(result['command']), result['out']
        assert result['code'] in (0, None), f'{command}: exit {result["code"]}\n{out}'
        assert 'usage: ' in out, f'{command} printed no usage:\n{out}'
        assert not result['compiled'], f'{command} compiled {result["compiled"]}'
        assert '[INFO]' not in out, f'{command} started a node:\n{out}'
