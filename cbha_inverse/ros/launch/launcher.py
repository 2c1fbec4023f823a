"""
``cbha_launch sim|robot [name:=value ...] [-p node.parameter:=value ...]``: the compositions.

The launch files' compositions, without ``launch``. Before any node starts, the params files
and ``-p`` overrides the user gives are checked as the nodes will read them
(:mod:`cbha_inverse.ros.launch.checks`): a section that matches no node, a parameter the node
does not declare or a value it would refuse is one line and exit 2.

Starts every node of :data:`cbha_inverse.ros.launch.compositions.COMPOSITIONS` ``[name]`` as a
process (:class:`cbha_inverse.ros.launch.processes.NodeProcesses`: ``python -m
cbha_inverse.ros.nodes.<node> --ros-args -r __ns:=<namespace> -r __node:=<node> --params-file
<file> --params-file <overrides>``), prefixes each output line with ``[<node>]``, and on SIGINT or
SIGTERM sends SIGINT to every node and waits for them (SIGTERM after
:data:`~cbha_inverse.ros.launch.processes.STOP_TIMEOUT`, SIGKILL after
:data:`~cbha_inverse.ros.launch.processes.TERM_TIMEOUT` more, as ``ros2 launch``). All nodes are
required: when one exits by itself, the others are stopped. Exit status: 0 when every node
stopped cleanly after the signal, else the first non-zero status of a node; 2 on a bad argument,
params file or conflict between them (one line on stderr). ``--dry-run`` prints the command lines
instead, and keeps the overrides params files they name; ``--show-args`` lists the composition's
arguments (as ``ros2 launch ... --show-args``). A stop while the command itself still loads or
checks (until the nodes start) exits 0 with one line (:mod:`cbha_inverse.ros.common.loading`); a
scene set differently on the nodes by the user is one warning line.
"""

import argparse
import shlex
import shutil
import signal
import sys
import tempfile
import time

from cbha_inverse.errors import ConfigError, report_config_error
from cbha_inverse.ros.common.loading import loaded
from cbha_inverse.ros.launch.compositions import ArgumentError, COMPOSITIONS, resolve
from cbha_inverse.ros.launch.processes import command_lines, NodeProcesses

PROGRAM = 'cbha_launch'


def _parser():
    epilog = []
    for composition in COMPOSITIONS.values():
        epilog.append(f'{composition.name}: {composition.description}')
        for argument in composition.all_arguments():
            default = argument.default or '(installed file)'
            choices = f" [{'|'.join(argument.choices)}]" if argument.choices else ''
            yields = ' (when not given: unless a <node>_params file sets it)' \
                if argument.yielding else ''
            epilog.append(f'  {argument.name}:={default}{choices}  {argument.description}'
                          f'{yields}')
    parser = argparse.ArgumentParser(
        prog=PROGRAM, formatter_class=argparse.RawDescriptionHelpFormatter,
        description='Start a composition of cbha_inverse nodes (as launch/<name>.launch.py).',
        epilog='\n'.join(epilog))
    parser.add_argument('composition', choices=sorted(COMPOSITIONS))
    parser.add_argument('arguments', nargs='*', metavar='name:=value')
    parser.add_argument('-p', '--param', action='append', default=[],
                        metavar='NODE.PARAMETER:=VALUE',
                        help='a one-off parameter of a node, applied last (YAML-typed as ros2 '
                        'does: 0.3 double, 3 integer); checked before any node starts')
    parser.add_argument('--dry-run', action='store_true', help='print the commands, start none')
    parser.add_argument('-s', '--show-args', action='store_true',
                        help="list the composition's arguments (as ros2 launch --show-args)")
    return parser


def show_arguments(composition):
    """Return the arguments of a composition, as ``ros2 launch --show-args`` lists them."""
    lines = [f'Arguments of {composition.name} (pass arguments as <name>:=<value>):']
    for argument in composition.all_arguments():
        lines += [f"    '{argument.name}':", f'        {argument.description}']
        if argument.choices:
            lines.append(f'        Valid choices are: {list(argument.choices)}')
        default = argument.default or '(the installed config/ file)'
        lines.append(f"        (default: '{default}'" + (
            ', unless a <node>_params file sets it)' if argument.yielding else ')'))
    return '\n'.join(lines)


def parse_assignments(items):
    """
    Parse ``name:=value`` arguments.

    Parameters
    ----------
    items : list of str
        The arguments.

    Returns
    -------
    dict
        ``name -> value``.

    Raises
    ------
    ArgumentError
        If an item is not of the form ``name:=value``.

    """
    values = {}
    for item in items:
        name, sep, value = item.partition(':=')
        if not sep or not name:
            raise ArgumentError(f'{item!r} is not name:=value')
        values[name] = value
    return values


def supervise(lines, out=None):
    """
    Run the node processes until a signal or until one of them exits; stop all of them.

    Parameters
    ----------
    lines : list of (str, list of str)
        From :func:`cbha_inverse.ros.launch.processes.command_lines`.
    out : file-like, optional
        Where the prefixed output goes (default ``sys.stdout``).

    Returns
    -------
    int
        0 if every node stopped cleanly after SIGINT/SIGTERM, else the first non-zero status.

    """
    # the handler only appends (no lock): Python runs it between two bytecodes of this thread,
    # and a threading.Event's set() would wait for the lock its own wait() may hold there
    stopping = []
    previous = {sig: signal.signal(sig, lambda signum, _: stopping.append(signum))
                for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        with NodeProcesses(PROGRAM, out=out) as processes:
            for name, argv in lines:
                processes.start(name, argv)
            first_exit = None
            while not stopping and first_exit is None:
                first_exit = processes.exited()
                time.sleep(0.1)
            if first_exit is not None:
                processes.write(f'{first_exit[0]} exited with status {first_exit[1]}: '
                                'stopping the others')
            statuses = processes.stop()
    finally:
        for sig, handler in previous.items():
            signal.signal(sig, handler)
    failed = [(name, code) for name, code in statuses if code != 0]
    processes.write('exit statuses: ' + ', '.join(f'{name} {code}' for name, code in statuses))
    if first_exit is not None and first_exit[1] != 0:
        return first_exit[1]
    return failed[0][1] if failed else 0


def main(argv=None):
    """
    Run the ``cbha_launch`` command.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        See the module docstring.

    """
    try:
        return _main(argv)
    except KeyboardInterrupt:      # before the nodes start: nothing to stop
        print(f'{PROGRAM}: stopped before starting the nodes', file=sys.stderr)
        return 0


def _resolved(composition, args, overrides_dir):
    """
    Resolve a composition, check what the user gives the nodes, and write the command lines.

    Returns
    -------
    processes : list of NodeProcess
    lines : list of (str, list of str)

    Raises
    ------
    ArgumentError, ConfigError
        On a bad argument, params file or parameter (:mod:`cbha_inverse.ros.launch.checks`).

    """
    from cbha_inverse.ros.common.params import ParameterError
    from cbha_inverse.ros.launch.checks import (
        check_parameters, check_sections, parse_overrides)
    values = parse_assignments(args.arguments)
    parameters = parse_overrides(args.param)
    warnings = []
    processes = resolve(composition, values, parameters, warnings)
    user_files = {p.executable: values[f'{p.executable}_params'] for p in processes
                  if values.get(f'{p.executable}_params')}
    check_sections(composition, [p for p in processes if p.executable in user_files])
    try:
        check_parameters(processes, parameters, user_files)
    except ParameterError as exc:
        raise ArgumentError(str(exc)) from None
    for warning in warnings:
        print(f'{PROGRAM}: warning: {warning}', file=sys.stderr, flush=True)
    return processes, command_lines(processes, overrides_dir)


def _main(argv):
    args = _parser().parse_intermixed_args(argv)
    composition = COMPOSITIONS[args.composition]
    if args.show_args:
        print(show_arguments(composition))
        return 0
    if args.dry_run:
        # the printed command lines name the overrides files: they must outlive this command
        overrides_dir = tempfile.mkdtemp(prefix='cbha_launch_')
        try:
            _, lines = _resolved(composition, args, overrides_dir)
        except (ArgumentError, ConfigError) as exc:
            shutil.rmtree(overrides_dir, ignore_errors=True)
            return report_config_error(PROGRAM, exc)
        for name, argv_line in lines:
            print(f'{name}: {shlex.join(argv_line)}')
        return 0
    with tempfile.TemporaryDirectory(prefix='cbha_launch_') as overrides_dir:
        try:
            processes, lines = _resolved(composition, args, overrides_dir)
        except (ArgumentError, ConfigError) as exc:
            return report_config_error(PROGRAM, exc)
        # from here this command handles its stops (:mod:`cbha_inverse.ros.common.loading`):
        # until now a stop was a quiet exit 0, the node modules' imports for the checks included
        loaded()
        print(f'[{PROGRAM}] {composition.name}: ' + ', '.join(
            f'{p.executable} ({p.namespace})' for p in processes), flush=True)
        return supervise(lines)


if __name__ == '__main__':
    sys.exit(main())
