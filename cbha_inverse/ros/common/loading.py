"""
A stop signal while a node executable still loads ends it with status 0 and one line.

Loading a node (numpy, scipy, numba's cached kernels, rclpy) takes a second or more before its
``main`` installs its own handling (:class:`cbha_inverse.ros.common.runner.StopRequest`); a
Ctrl-C in that time would end in a ``KeyboardInterrupt`` traceback from deep inside an import.
:func:`quiet_while_loading` runs when the package of the node modules is imported, before any of
them: when this process is a node executable (``inverse_solver``, or ``python -m
cbha_inverse.ros.nodes.inverse_solver``), SIGINT and SIGTERM print
``<executable>: stopped by SIGINT while loading`` and end the process with status 0 until the
node's ``main`` takes them over. Any other process (a test importing a node class,
``cbha_launch``'s :mod:`cbha_inverse.ros.launch.node_process`) keeps its handlers.
"""

import atexit
import os
import signal
import sys

STOP_SIGNALS = (signal.SIGINT, signal.SIGTERM)


def stopped_message(executable, signal_name):
    """Return the one line of a node stopped while it loads."""
    return f'{executable}: stopped by {signal_name} while loading'


def node_executable(argv0, node_names):
    """
    Return the node executable this process runs, or None.

    Parameters
    ----------
    argv0 : str
        ``sys.argv[0]`` while the node package is imported: the console script's path, or ``-m``
        while ``python -m`` locates its module.
    node_names : collection of str
        The node executables (the modules of the node package).

    Returns
    -------
    str or None
        The executable's name (for ``-m``, the module named on the command line).

    """
    name = os.path.basename(argv0)
    if name in node_names:
        return name
    if argv0 == '-m':
        module = _module_argument(getattr(sys, 'orig_argv', []))
        name = module.rsplit('.', 1)[-1] if module else ''
        return name if name in node_names else None
    return None


def _module_argument(orig_argv):
    """Return the module of ``python -m MODULE`` in the interpreter's own command line."""
    for i, arg in enumerate(orig_argv[:-1]):
        if arg == '-m':
            return orig_argv[i + 1]
    return ''


def quiet_while_loading(node_names):
    """
    Install the quiet stop for the loading of a node executable (nothing in other processes).

    Parameters
    ----------
    node_names : collection of str
        The node executables.

    Returns
    -------
    str or None
        The executable, when the handlers were installed.

    """
    executable = node_executable(sys.argv[0], node_names)
    if executable is None:
        return None
    # a handler the process was given (an ignored SIGINT in a background job) stays
    install_quiet_stop(executable, keep_given=True)
    return executable


def install_quiet_stop(executable, keep_given=False):
    """
    Make SIGINT and SIGTERM print :func:`stopped_message` and end the process with status 0.

    The one quiet stop of a program that still loads: a node executable
    (:func:`quiet_while_loading`), ``cbha_launch`` before it starts the nodes, and
    :mod:`cbha_inverse.ros.launch.node_process` while it imports a node module.

    Parameters
    ----------
    executable : str
        The program's name, first word of the line.
    keep_given : bool
        Leave a signal alone whose handler is not Python's default (one the process was given).

    Returns
    -------
    dict
        The replaced handlers by signal, for :func:`restore_handlers`.

    """
    def stop(signum, frame):
        print(stopped_message(executable, signal.Signals(signum).name), file=sys.stderr,
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
