"""
The commands the README and docs/ show: each runs in the venv as written, or says it needs ROS.

Every line of a shell block (```sh) of README.md and docs/*.md is read as the user would type it
(continuations joined, ``&&`` / ``;`` / ``|`` split, ``VAR=value`` prefixes and a trailing
``&`` dropped). A command of this package names a console script of setup.py, a make target
of the Makefile or a file of the repository; its subcommand and every option it uses are in
that program's ``--help``, every ``NAME:=VALUE`` of ``cbha_launch`` in the composition's
``--show-args``, and every ``-p NAME:=VALUE`` of a node in the node's ``--help``. Commands of a
ROS 2 install (``ros2``, ``colcon``, ``source``) sit in a block that says so: a comment in the
block, or the paragraph or heading just before it, names a "ROS 2 install" (or "ROS install").
Shell and system tools (``cd``, ``git``, ``sudo``, ...) are left alone.
"""

import functools
from pathlib import Path
import re
import shlex
import subprocess
import sys

import pytest

REPO = Path(__file__).resolve().parents[2]
DOCUMENTS = [REPO / 'README.md'] + sorted((REPO / 'docs').glob('*.md'))
ROS_INSTALL = {'ros2', 'colcon', 'source'}
SYSTEM = {'cd', 'cp', 'mkdir', 'git', 'pip', 'sudo', 'chronyc', 'grep', 'export', 'kill', 'ls',
          'cat', 'mv', 'rm', 'python3'}
MARKER = re.compile(r'ROS( 2)?( Jazzy)? install', re.IGNORECASE)


def _console_scripts():
    """Return the console scripts of setup.py by name."""
    text = (REPO / 'setup.py').read_text()
    return dict(re.findall(r"'(\w+) = ([\w.]+):main'", text))


def _make_targets():
    """Return the targets of the Makefile."""
    return set(re.findall(r'^([\w-]+):', (REPO / 'Makefile').read_text(), re.MULTILINE))


def _blocks():
    """Yield (document, line number, block text, whether the block is marked as ROS install)."""
    for document in DOCUMENTS:
        text = document.read_text()
        for match in re.finditer(r'```sh\n(.*?)```', text, re.DOTALL):
            before = text[:match.start()].rstrip().rsplit('\n\n', 1)[-1]
            heading = re.findall(r'^#+ .*$', text[:match.start()], re.MULTILINE)
            marked = bool(MARKER.search(match.group(1)) or MARKER.search(before)
                          or (heading and MARKER.search(heading[-1])))
            yield document, text[:match.start()].count('\n') + 2, match.group(1), marked


def _commands():
    """Return every command of the documents' shell blocks, as pytest parameters."""
    commands = []
    for document, first_line, block, marked in _blocks():
        joined = re.sub(r'\\\n\s*', ' ', block)
        for offset, line in enumerate(joined.splitlines()):
            words = shlex.split(line, comments=True)
            for command in _split_commands(words):
                where = f'{document.relative_to(REPO)}:{first_line + offset}'
                commands.append(pytest.param(command, marked, id=f'{where} {command[0]}'))
    return commands


def _split_commands(words):
    """Split a line's words at ``&&``, ``;``, ``|`` and ``&``; drop ``VAR=value`` prefixes."""
    command = []
    for word in words + [';']:
        if word in ('&&', ';', '|', '&', '||'):
            while command and re.fullmatch(r'[A-Z_][A-Z0-9_]*=.*', command[0]):
                command.pop(0)
            if command:
                yield command
            command = []
        else:
            command.append(word)


@functools.lru_cache(maxsize=None)
def _help(*program):
    """Return the ``--help`` text of a console script (and subcommand) of this package."""
    module = _console_scripts()[program[0]]
    out = subprocess.run([sys.executable, '-c', f'import sys; from {module} import main; '
                          f'sys.argv[0] = {program[0]!r}; sys.exit(main())', *program[1:],
                          '--help'], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, f'{" ".join(program)} --help: {out.stdout}{out.stderr}'
    return out.stdout


@functools.lru_cache(maxsize=None)
def _launch_arguments(composition):
    """Return the ``NAME:=VALUE`` argument names of a ``cbha_launch`` composition."""
    module = _console_scripts()['cbha_launch']
    out = subprocess.run([sys.executable, '-c', f'import sys; from {module} import main; '
                          f'sys.argv[0] = "cbha_launch"; sys.exit(main())', composition,
                          '--show-args'], capture_output=True, text=True, cwd=REPO, timeout=120)
    assert out.returncode == 0, out.stdout + out.stderr
    return set(re.findall(r"^    '(\w+)':$", out.stdout, re.MULTILINE))


def _subcommand(program, words):
    """Return the subcommand among ``words`` that the program's --help lists, or None."""
    listed = re.search(r'\{([\w,-]+)\}', _help(program))
    names = set(listed.group(1).split(',')) if listed else set(
        re.findall(r'^    (\w+)\s', _help(program), re.MULTILINE))
    return words[0] if words and words[0] in names else None


@pytest.mark.parametrize('command, marked', _commands())
def test_a_documented_command_runs_in_the_venv_as_written(command, marked):
    program, arguments = Path(command[0]).name, command[1:]
    if program in ROS_INSTALL or command[0] == '.':
        assert marked, f'{" ".join(command)}: a ROS 2 install command in a block not marked so'
        return
    if marked or program in SYSTEM:
        return
    if program == 'make':
        assert set(arguments) <= _make_targets(), f'make: no target {arguments}'
        return
    if program == 'python':
        assert (REPO / arguments[0]).is_file(), f'{arguments[0]} is not a file'
        return
    assert program in _console_scripts(), f'{program}: no console script of that name'
    ros_arguments = arguments.index('--ros-args') if '--ros-args' in arguments else None
    own = arguments[:ros_arguments]
    sub = _subcommand(program, own)
    text = _help(program, sub) if sub else _help(program)
    for word in own:
        option = word.split('=', 1)[0]
        if option.startswith('-') and option not in ('-', '-h', '--help'):
            assert re.search(rf'(^|[\s,\[]){re.escape(option)}\b', text), (
                f'{program} {sub or ""}: no option {option} in its --help')
    if program == 'cbha_launch' and own and not own[0].startswith('-'):
        given = [w.split(':=', 1)[0] for w in own[1:] if ':=' in w and '.' not in w.split(
            ':=', 1)[0]]
        for name in given:
            assert name in _launch_arguments(own[0]), f'cbha_launch {own[0]}: no argument {name}'
    if ros_arguments is not None:
        ros = arguments[ros_arguments + 1:]
        for flag, value in zip(ros, ros[1:]):
            if flag == '-p' and ':=' in value:
                name = value.split(':=', 1)[0].strip("'")
                assert re.search(rf'^  {re.escape(name)} \(', text, re.MULTILINE), (
                    f'{program}: no parameter {name} in its --help')
