"""
A stop signal while a program of the package still loads ends it with status 0 and one line.

Loading a node (numpy, scipy, numba's cached kernels, rclpy) takes a second or more before its
``main`` installs its own handling (:class:`cbha_inverse.ros.common.runner.StopRequest`); a
Ctrl-C in that time would end in a ``KeyboardInterrupt`` traceback from deep inside an import.
:func:`quiet_while_loading` runs once, when :mod:`cbha_inverse.ros` is imported, before any node
module or ``cbha_launch``'s: when this process is one of the programs it is given (a node
executable: ``inverse_solver``, ``ros2 run cbha_inverse inverse_solver`` or ``python -m
cbha_inverse.ros.nodes.inverse_solver``; ``cbha_launch``), SIGINT and SIGTERM print
``<program>: stopped by SIGINT while loading`` and end the process with status 0 until the
program takes them over (a node's ``main``; ``cbha_launch``'s, through :func:`loaded`). Any other
process (a test importing a node class) keeps its handlers.

The launcher starts the nodes with SIGINT and SIGTERM blocked
(:class:`cbha_inverse.ros.launch.processes.NodeProcesses`), so that a stop during the
interpreter's own start (where it would end in a fatal error) waits: :func:`quiet_while_loading`
unblocks them once the quiet stop is installed, and a signal that came meanwhile is then a stop
while loading.
"""

import atexit
import os
import signal
import sys

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)

_REPLACED = {}
"""The handlers :func:`quiet_while_loading` replaced, for :func:`loaded`."""


def stopped_message(program, signal_name):
    """Return the one line of a program stopped while it loads."""
    return f'{program}: stopped by {signal_name} while loading'


def program_name(argv0, programs):
    """
    Return the program of the package this process runs, or None.

    Parameters
    ----------
    argv0 : str
        ``sys.argv[0]`` while :mod:`cbha_inverse.ros` is imported: the console script's path, or
        ``-m`` while ``python -m`` locates its module.
    programs : mapping of str to str
        ``module -> program`` (the console script's name).

    Returns
    -------
    str or None
        The program's name (for ``-m``, the one of the module named on the command line).

    """
    name = os.path.basename(argv0)
    if name in programs.values():
        return name
    if argv0 == '-m':
        return programs.get(_module_argument(getattr(sys, 'orig_argv', [])))
    return None


def _module_argument(orig_argv):
    """Return the module of ``python -m MODULE`` in the interpreter's own command line."""
    for i, arg in enumerate(orig_argv[:-1]):
        if arg == '-m':
            return orig_argv[i + 1]
    return ''


def quiet_while_loading(programs):
    """
    Install the quiet stop for the loading of a program (nothing in other processes).

    Also unblocks SIGINT and SIGTERM, which the launcher blocks in the nodes it starts.

    Parameters
    ----------
    programs : mapping of str to str
        ``module -> program`` (:func:`program_name`).

    Returns
    -------
    str or None
        The program, when the handlers were installed.

    """
    program = program_name(sys.argv[0], programs)
    if program is None:
        return None
    # a handler the process was given (an ignored SIGINT in a background job) stays
    _REPLACED.update(install_quiet_stop(program, keep_given=True))
    signal.pthread_sigmask(signal.SIG_UNBLOCK, STOP_SIGNALS)
    return program


def split_ros_arguments(argv):
    """
    Split a command's arguments at ``--ros-args``: its own, then the ROS ones.

    Parameters
    ----------
    argv : sequence of str
        The arguments after the program name.

    Returns
    -------
    own : list of str
    ros : list of str
        ``--ros-args`` and what follows it (empty without it).

    """
    argv = list(argv)
    cut = argv.index('--ros-args') if '--ros-args' in argv else len(argv)
    return argv[:cut], argv[cut:]


def loaded():
    """Put back the handlers :func:`quiet_while_loading` replaced: the program handles stops."""
    restore_handlers(_REPLACED)
    _REPLACED.clear()


def install_quiet_stop(program, keep_given=False):
    """
    Make SIGINT and SIGTERM print :func:`stopped_message` and end the process with status 0.

    Parameters
    ----------
    program : str
        The program's name, first word of the line.
    keep_given : bool
        Leave a signal alone whose handler is not Python's default (one the process was given).

    Returns
    -------
    dict
        The replaced handlers by signal, for :func:`restore_handlers`.

    """
    def stop(signum, frame):
        print(stopped_message(program, signal.Signals(signum).name), file=sys.stderr,
              flush=True)
        # not SystemExit: raised while the interpreter compiles a module (``python -m`` compiles
        # the node's own module), it is lost and the node would go on loading and run
        end_process(0)

    previous = {}
    for sig in STOP_SIGNALS:
        if not keep_given or signal.getsignal(sig) in (signal.default_int_handler, signal.SIG_DFL):
            previous[sig] = signal.signal(sig, stop)
    return previous


def end_process(code):
    """
    End this process with ``code`` after the ``atexit`` handlers, without finalizing Python.

    For a node process whose node has been shut down, or stopped while it loads
    (:func:`install_quiet_stop`): the handlers run (coverage's data file of
    a measured run, rclpy's), the standard streams are flushed, and ``os._exit`` skips the
    module teardown and final garbage collection of the interpreter.

    Parameters
    ----------
    code : int
        Exit status.

    """
    atexit._run_exitfuncs()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):  # a closed or broken pipe: nothing more to say there
            pass
    os._exit(code)


def restore_handlers(previous):
    """Put back the handlers :func:`install_quiet_stop` replaced."""
    for sig, handler in previous.items():
        signal.signal(sig, handler)
