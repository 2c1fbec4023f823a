"""
Node processes started together and stopped together: what ``cbha_launch`` and ``cbha_demo`` run.

Each node of a resolved composition (:func:`cbha_inverse.ros.launch.compositions.resolve`) runs as
``python -m cbha_inverse.ros.nodes.<node> --ros-args -r __ns:=<namespace> -r __node:=<node>
--params-file <file> [--params-file <overrides>]`` (:func:`node_command`): its params file, then
the overrides written into a second one, which wins; the node's own environment variables are
set through ``env(1)``, so that a dry run shows them. :class:`NodeProcesses` starts such commands
(and others, such as ``cbha_bag record``), sends their output either to one stream, each line
prefixed with ``[<name>]`` (``cbha_launch``), or to a log file per process (``cbha_demo``), and
stops them all as ``ros2 launch`` does: SIGINT, SIGTERM after :data:`STOP_TIMEOUT`, SIGKILL after
:data:`TERM_TIMEOUT` more.

Every process runs in its own session: a Ctrl-C in the terminal reaches the nodes once, through
the program that started them. A node starts with SIGINT and SIGTERM blocked, so that a stop
during the interpreter's own start-up (where Python cannot handle it) waits until the node's
quiet stop while loading is installed, which unblocks them
(:mod:`cbha_inverse.ros.common.loading`): a stop at any moment of a node's start exits 0 with at
most one line.
"""

import os
from pathlib import Path
import signal
import subprocess
import sys
import threading
import time

from cbha_inverse.config_files import read_yaml
from cbha_inverse.ros.common.loading import STOP_SIGNALS
from cbha_inverse.ros.launch.compositions import node_module
import yaml

STOP_TIMEOUT = 15.0
"""Seconds a process has to stop after SIGINT before it gets SIGTERM."""
TERM_TIMEOUT = 5.0
"""Seconds a process has to stop after SIGTERM before it is killed (SIGKILL)."""


def node_command(process, overrides_dir):
    """
    Return the command line of a node and write its overrides params file.

    Parameters
    ----------
    process : cbha_inverse.ros.launch.compositions.NodeProcess
        The node, as the resolved composition starts it.
    overrides_dir : str or pathlib.Path
        Where its overrides are written, as ``<node>.yaml`` (none without overrides).

    Returns
    -------
    list of str

    """
    prefix = (['env', *(f'{name}={value}' for name, value in process.environment.items())]
              if process.environment else [])
    argv = [*prefix, sys.executable, '-m', node_module(process.executable),
            '--ros-args', '-r', f'__ns:={process.namespace}',
            '-r', f'__node:={process.executable}']
    for params in process.params_files:
        argv += ['--params-file', str(params)]
    if process.parameters:
        overrides = Path(overrides_dir) / f'{process.executable}.yaml'
        overrides.write_text(yaml.safe_dump(
            {'/**': {'ros__parameters': process.parameters}}, sort_keys=False))
        argv += ['--params-file', str(overrides)]
    return argv


def command_lines(processes, overrides_dir):
    """
    Return the command line of each node, once every params file has been read.

    Parameters
    ----------
    processes : list of cbha_inverse.ros.launch.compositions.NodeProcess
        The resolved composition.
    overrides_dir : str or pathlib.Path
        Where the overrides params files are written (:func:`node_command`).

    Returns
    -------
    list of (str, list of str)
        ``(executable, argv)`` per node.

    Raises
    ------
    cbha_inverse.errors.ConfigError
        If a params file is missing or not valid YAML (then no overrides file is written).

    """
    for process in processes:
        for params in process.params_files:
            read_yaml(params)
    return [(process.executable, node_command(process, overrides_dir)) for process in processes]


def child_environment(environment):
    """Return the environment of the processes: the rclpy wheels re-bootstrap in each child."""
    env = dict(environment)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    env['PYTHONUNBUFFERED'] = '1'
    return env


class NodeProcesses:
    """
    Processes started together, stopped together (SIGINT, then SIGTERM, then SIGKILL).

    Use as a context manager: the processes still running are stopped when the block ends.

    Parameters
    ----------
    program : str
        The starting program: the ``[<program>]`` of its own lines.
    env : mapping of str to str, optional
        The processes' environment (default this process's); see :func:`child_environment`.
    out : file-like, optional
        Where the output of a process without a log file goes, each line prefixed with its name,
        and the lines about a stop that had to escalate (default ``sys.stdout``).

    Attributes
    ----------
    escalated : dict of str to str
        ``name -> signal`` of each process that did not stop after SIGINT in time (the last
        signal it got: ``SIGTERM`` or ``SIGKILL``).

    """

    def __init__(self, program, env=None, out=None):
        self.program = program
        self.env = child_environment(os.environ if env is None else env)
        self.out = sys.stdout if out is None else out
        self.escalated = {}
        self._lock = threading.Lock()
        self._children = []
        self._relays = []
        self._logs = []

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.stop()
        return False

    def start(self, name, argv, log=None, node=True):
        """
        Start one process.

        Parameters
        ----------
        name : str
            Its name in the output, the statuses and the lines about its stop.
        argv : list of str
            Its command line (:func:`node_command` for a node).
        log : str or pathlib.Path, optional
            A file that gets its output (stdout and stderr); default: :attr:`out`, prefixed.
        node : bool
            A node of this package (or any program whose quiet stop while loading unblocks
            SIGINT and SIGTERM): started with them blocked, see the module docstring.

        Returns
        -------
        subprocess.Popen

        """
        stream = open(log, 'w') if log is not None else None
        blocked = signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS) if node else None
        try:
            child = subprocess.Popen(
                argv, env=self.env, stdout=subprocess.PIPE if stream is None else stream,
                stderr=subprocess.STDOUT, text=True, start_new_session=True)
        except BaseException:
            if stream is not None:
                stream.close()
            raise
        finally:
            if blocked is not None:
                signal.pthread_sigmask(signal.SIG_SETMASK, blocked)
        self._children.append((name, child))
        if stream is not None:
            self._logs.append(stream)
        else:
            relay = threading.Thread(target=self._relay, args=(name, child.stdout), daemon=True)
            relay.start()
            self._relays.append(relay)
        return child

    def start_node(self, process, overrides_dir, log=None):
        """
        Start one node of a resolved composition (:func:`command_lines`).

        Parameters
        ----------
        process : cbha_inverse.ros.launch.compositions.NodeProcess
            The node.
        overrides_dir : str or pathlib.Path
            Where its overrides params file is written.
        log : str or pathlib.Path, optional
            A file for its output (see :meth:`start`).

        Returns
        -------
        subprocess.Popen

        """
        ((name, argv),) = command_lines([process], overrides_dir)
        return self.start(name, argv, log)

    def exited(self):
        """Return ``(name, exit status)`` of the first process that has ended, or None."""
        return next(((name, child.returncode) for name, child in self._children
                     if child.poll() is not None), None)

    def write(self, line):
        """Write ``[<program>] <line>`` to :attr:`out`."""
        with self._lock:
            self.out.write(f'[{self.program}] {line}\n')
            self.out.flush()

    def _relay(self, name, stream):
        """Copy a child's output line by line, prefixed with its name."""
        for line in stream:
            with self._lock:
                self.out.write(f'[{name}] {line}')
                self.out.flush()

    def stop(self):
        """
        Stop every running process as ``ros2 launch`` does; return ``[(name, exit status)]``.

        SIGINT; a process still running after :data:`STOP_TIMEOUT` gets SIGTERM (for a node of
        this package a second stop signal: a ``KeyboardInterrupt`` where its Python code waits),
        and SIGKILL after :data:`TERM_TIMEOUT` more; each escalation is one line
        (:meth:`write`) and an entry of :attr:`escalated`. A stop signal that reaches this
        process meanwhile waits for the end of the stop (in the main thread).

        Returns
        -------
        list of (str, int)
            In start order.

        """
        arrived = []
        previous = {}
        if threading.current_thread() is threading.main_thread():
            # (a handler installed outside Python, None here, could not be put back)
            previous = {sig: signal.signal(sig, lambda signum, _: arrived.append(signum))
                        for sig in STOP_SIGNALS if signal.getsignal(sig) is not None}
        try:
            statuses = self._stop_all()
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
            for relay in self._relays:
                relay.join(timeout=5.0)
            for stream in self._logs:
                stream.close()
            self._relays, self._logs = [], []
        for signum in arrived[:1]:
            signal.raise_signal(signum)
        return statuses

    def _stop_all(self):
        running = [(name, child) for name, child in self._children if child.poll() is None]
        for _, child in running:
            child.send_signal(signal.SIGINT)
        for escalation, timeout, after in ((signal.SIGTERM, STOP_TIMEOUT, 'SIGINT'),
                                           (signal.SIGKILL, TERM_TIMEOUT, 'SIGTERM')):
            deadline = time.monotonic() + timeout
            for _, child in running:
                try:
                    child.wait(timeout=max(0.1, deadline - time.monotonic()))
                except subprocess.TimeoutExpired:
                    pass
            running = [(name, child) for name, child in running if child.poll() is None]
            for name, child in running:
                self.escalated[name] = escalation.name
                self.write(f'{name} still running {timeout:g} s after {after}: '
                           f'{escalation.name}')
                child.send_signal(escalation)
        return [(name, child.wait()) for name, child in self._children]
