"""
The Jazzy ``main()`` of every node: ``--help``, params-file checks, spin, clean shutdown.

``<node> --help`` prints the node's parameters (name, type, default, range, description) and
exits 0 without starting ROS; a broken params file, an invalid parameter or an unusable scene
prints one line (:func:`cbha_inverse.errors.report_config_error`) and exits 2.

SIGINT and SIGTERM only set a flag (:class:`StopRequest`) that the spin loop polls every
:data:`SPIN_POLL_S`: rclpy's own handlers are not installed, because they raise
``KeyboardInterrupt`` at whatever Python line runs when the signal lands (inside rclpy's executor,
a message conversion, a lock) and shut the context down from another thread: a stop could then
fail with a ``RuntimeError`` from a half-taken message. The handler takes no lock
(:class:`SignalSafeEvent`): Python runs it in the main thread between two bytecodes of whatever
that thread runs, and a lock that line holds would never be released. The node is destroyed and
the context shut down in order, on the main thread. A second signal stops at once
(``KeyboardInterrupt``).
Once the node is built its objects leave the garbage collector's generations (``gc.freeze``),
so no collection walks them again; after the node's clean shutdown the process ends at once
(:func:`end_process`: the ``atexit`` handlers, then ``os._exit``) instead of finalizing the
interpreter, which would take seconds on a loaded machine and report the frozen extension
objects as leaks (proxsuite's nanobind prints ~30 lines of them).
"""

import gc
import signal
import sys
import threading

from cbha_inverse.errors import ConfigError, report_config_error
from cbha_inverse.ros.common.loading import (end_process, loaded, split_ros_arguments,
                                             STOP_SIGNALS)
from cbha_inverse.ros.common.params import check_params_files, parameter_help, ParameterError
import rclpy
from rclpy.executors import ExternalShutdownException
from rclpy.experimental import EventsExecutor
from rclpy.signals import SignalHandlerOptions

INTERRUPTED_EXIT = 1
"""Exit status of a node that ends by itself (``done``) when SIGINT/SIGTERM stopped it first."""


SPIN_POLL_S = 0.1
"""Longest time [s] between a stop signal and the spin loop noticing it."""
TEARDOWN_TIMEOUT_S = 5.0
"""Longest wait [s] for ``destroy_node`` and rclpy's shutdown when a node process ends."""


class SignalSafeEvent:
    """
    A one-shot event that a signal handler may trigger: it takes no lock.

    Python runs a signal handler in the main thread between two bytecodes of whatever that thread
    runs. ``rclpy.task.Future`` takes its (non-reentrant) lock in ``add_done_callback`` and
    ``remove_done_callback``, which the events executor calls at every spin slice: a handler
    that completed such a future while the interrupted line held that lock would wait for it for
    ever (a node that never stops). This event offers the same ``done``, ``add_done_callback``
    and ``remove_done_callback``, so ``spin_until_future_complete`` can wait for it, and every
    interleaving of :meth:`trigger` with them runs each callback exactly once: a callback is taken
    off the list (``list.pop``, one bytecode) before it runs.
    """

    def __init__(self):
        self._triggered = False
        self._callbacks = []

    def done(self):
        """Whether :meth:`trigger` was called."""
        return self._triggered

    def trigger(self):
        """Set the event and run its callbacks (each with the event as argument)."""
        self._triggered = True
        self._run_callbacks()

    def add_done_callback(self, callback):
        """Call ``callback(event)`` when the event is triggered (now, if it is)."""
        self._callbacks.append(callback)
        if self._triggered:
            self._run_callbacks()

    def remove_done_callback(self, callback):
        """Remove a callback that has not run; return whether it was there."""
        try:
            self._callbacks.remove(callback)
        except ValueError:
            return False
        return True

    def _run_callbacks(self):
        while True:
            try:
                callback = self._callbacks.pop()
            except IndexError:
                return
            callback(self)


class StopRequest:
    """
    SIGINT/SIGTERM as a flag: the first signal asks the spin loop to stop, a second one raises.

    Use as a context manager: the handlers are installed on entry and the previous ones restored
    on exit.
    """

    def __init__(self):
        self.signal_name = None
        # set by the first signal: it ends a spin at once
        self.event = SignalSafeEvent()
        self._previous = {}

    @property
    def requested(self):
        """Whether a stop signal has arrived."""
        return self.signal_name is not None

    def _on_signal(self, signum, frame):
        if self.requested:
            raise KeyboardInterrupt(signal.Signals(signum).name)
        self.signal_name = signal.Signals(signum).name
        self.event.trigger()

    def __enter__(self):
        self._previous = {sig: signal.signal(sig, self._on_signal) for sig in STOP_SIGNALS}
        return self

    def __exit__(self, *exc):
        for sig, handler in self._previous.items():
            signal.signal(sig, handler)
        return False


def run_until_stopped(body):
    """
    Run a command once it is loaded, ``body(stop)``: a stop signal is then a polled flag.

    The quiet stop while loading (:func:`cbha_inverse.ros.common.loading.loaded`) gives way
    to a :class:`StopRequest` that ``body`` polls; a second signal, a ``KeyboardInterrupt``,
    ends it with status 0.

    Parameters
    ----------
    body : callable
        ``body(stop) -> int``, the command's exit status.

    Returns
    -------
    int

    """
    loaded()
    try:
        with StopRequest() as stop:
            return body(stop)
    except KeyboardInterrupt:
        return 0


def spin_until_stopped(node, stop, done=None):
    """
    Run a node's callbacks in rclpy's events executor until a stop, ``done`` or shutdown.

    The events executor (``rclpy.experimental``) dispatches each message and timer from C++
    as it comes, without rebuilding a wait set in Python per callback: less time between a
    message's arrival and its callback, and less CPU per callback (``docs/nodes.md``).
    Its callbacks run one at a time in this thread (one mutually exclusive group). It spins in
    slices of :data:`SPIN_POLL_S` (the events executor of rclpy 7.1 runs no callback when it
    spins without a timeout), and ``stop`` is polled between them. A slice ends at its timeout
    only when no event is queued: a node whose callbacks cannot keep up (a timer callback longer
    than its period on a loaded machine) would spin one slice for ever. So the stop signal and
    ``done`` also set the event the slice waits for (a :class:`SignalSafeEvent`), which ends it
    after the callback that runs (Python runs a signal handler in this thread, during that
    callback).

    Parameters
    ----------
    node : rclpy.node.Node
        The node.
    stop : StopRequest
        Polled every :data:`SPIN_POLL_S`.
    done : rclpy.task.Future, optional
        A node that ends by itself completes it.

    """
    executor = EventsExecutor(context=node.context)
    executor.add_node(node)
    until = SignalSafeEvent()

    def end_the_slice(_):
        until.trigger()

    stop.event.add_done_callback(end_the_slice)
    if done is not None:
        done.add_done_callback(end_the_slice)
    try:
        while not stop.requested and node.context.ok() and not until.done():
            executor.spin_until_future_complete(until, timeout_sec=SPIN_POLL_S)
    except ExternalShutdownException:
        pass
    finally:
        executor.shutdown()


def tear_down(node, timeout):
    """
    Destroy a node (if any) and shut rclpy down, waiting at most ``timeout`` seconds.

    Now and then rclpy's ``destroy_node`` does not return after the events executor stopped
    (it waits for the node's handle to be free); a process that ends right after
    (:func:`~cbha_inverse.ros.common.loading.end_process`) must not hang on it. The teardown
    then runs in a daemon thread, and a process that waited for it in vain says so on stderr
    and ends all the same. ``timeout`` None: in this thread, without a bound.
    """
    def run():
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()

    if timeout is None:
        run()
        return
    worker = threading.Thread(target=run, name='teardown', daemon=True)
    worker.start()
    worker.join(timeout)
    if worker.is_alive():
        print(f'rclpy teardown did not return within {timeout:g} s: ending the process without '
              'it', file=sys.stderr)


def node_help(node_name, node_class, params_class, executable=None):
    """
    Return the ``--help`` text of a node.

    Parameters
    ----------
    node_name : str
        Node name (and params-file stem).
    node_class : type
        The node class (its docstring's summary is the description).
    params_class : type or None
        Its parameters dataclass.
    executable : str, optional
        Executable name, when it differs from the node name.

    Returns
    -------
    str
        Usage, description and one entry per parameter.

    """
    summary = (node_class.__doc__ or '').strip().splitlines()[0] if node_class.__doc__ else ''
    executable = executable or node_name
    lines = [f'usage: {executable} [-h] [--ros-args [-r __ns:=/cbha] [--params-file FILE] '
             '[-p NAME:=VALUE] ...]', '', f'{executable}: {summary}', '',
             f'Parameters (name, type, default, range; set them in config/{node_name}.yaml or '
             'with -p):']
    if params_class is not None:
        lines.append(parameter_help(params_class))
    return '\n'.join(lines)


def _user_arguments(argv):
    """Return the arguments before ``--ros-args`` (without the program name)."""
    return split_ros_arguments(argv[1:])[0]


def run_node(node_class, node_name, argv=None, *, params_class=None, executable=None):
    """
    Create one node, spin it until SIGINT/SIGTERM and shut down cleanly.

    Parameters
    ----------
    node_class : callable
        ``node_class() -> rclpy.node.Node``; raises ``ParameterError`` on invalid parameters.
        A node that ends by itself (``cbha_excite``) has a ``done`` attribute, an
        ``rclpy.task.Future`` whose result is the exit code: it is spun until that completes.
    node_name : str
        Node name (``--help`` and error lines).
    argv : list of str, optional
        Command line (default ``sys.argv``), with ``--ros-args ...``.
    params_class : type, optional
        The node's parameters dataclass: ``--help`` lists it, params files are checked against it.
    executable : str, optional
        Executable name for ``--help``, when it differs from the node name.

    Returns
    -------
    int
        0 after ``--help``, 2 on a bad params file, invalid parameters, an unusable scene or a
        message package that a node imports at start and cannot find (``ModuleNotFoundError``).
        Once a node has run, the process ends here (:func:`end_process`) with 0 after
        SIGINT/SIGTERM; for a node with ``done``, its result, or :data:`INTERRUPTED_EXIT` (1)
        after SIGINT/SIGTERM before it was done.

    """
    argv = list(sys.argv if argv is None else argv)
    user = _user_arguments(argv)
    if '-h' in user or '--help' in user:
        print(node_help(node_name, node_class, params_class, executable))
        return 0
    try:
        check_params_files(argv, node_name, params_class)
    except (ConfigError, ParameterError) as exc:
        return report_config_error(node_name, exc)
    except KeyboardInterrupt:
        # a stop while the params files are read, before the stop flag is installed
        return 0
    node = done = None
    spun = False
    with StopRequest() as stop:
        rclpy.init(args=argv, signal_handler_options=SignalHandlerOptions.NO)
        try:
            node = node_class()
            done = getattr(node, 'done', None)
            # the ~10^5 objects of the imports and the node's setup leave the cyclic garbage
            # collector's generations: a full collection, the interpreter's at exit included,
            # no longer walks them (~0.1 s each, seconds at exit on a loaded machine)
            gc.freeze()
            spun = True
            spin_until_stopped(node, stop, done)
        except (KeyboardInterrupt, ExternalShutdownException):
            pass
        except (ParameterError, ConfigError, FileNotFoundError, ModuleNotFoundError) as exc:
            return report_config_error(node_name, exc)
        finally:
            tear_down(node, TEARDOWN_TIMEOUT_S if spun else None)
    code = 0
    if done is not None:
        code = int(done.result()) if done.done() else INTERRUPTED_EXIT
    if spun:
        end_process(code)
    return code
