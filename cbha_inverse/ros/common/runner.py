"""
The Jazzy ``main()`` of every node: ``--help``, params-file checks, spin, clean shutdown.

``<node> --help`` prints the node's parameters (name, type, default, range, description) and
exits 0 without starting ROS; a broken params file, an invalid parameter or an unusable scene
prints one line (:func:`cbha_inverse.errors.report_config_error`) and exits 2.
"""

import sys

from cbha_inverse.errors import ConfigError, report_config_error
from cbha_inverse.ros.common.params import check_params_files, parameter_help, ParameterError
import rclpy
from rclpy.executors import ExternalShutdownException

INTERRUPTED_EXIT = 1
"""Exit status of a node that ends by itself (``done``) when SIGINT/SIGTERM stopped it first."""


def node_help(node_name, node_class, params_class):
    """
    Return the ``--help`` text of a node.

    Parameters
    ----------
    node_name : str
        Executable and node name.
    node_class : type
        The node class (its docstring's summary is the description).
    params_class : type or None
        Its parameters dataclass.

    Returns
    -------
    str
        Usage, description and one entry per parameter.

    """
    summary = (node_class.__doc__ or '').strip().splitlines()[0] if node_class.__doc__ else ''
    lines = [f'usage: {node_name} [-h] [--ros-args [-r __ns:=/cbha] [--params-file FILE] '
             '[-p NAME:=VALUE] ...]', '', f'{node_name}: {summary}', '',
             f'Parameters (name, type, default, range; set them in config/{node_name}.yaml or '
             'with -p):']
    if params_class is not None:
        lines.append(parameter_help(params_class))
    return '\n'.join(lines)


def _user_arguments(argv):
    """Return the arguments before ``--ros-args`` (without the program name)."""
    args = list(argv[1:])
    return args[:args.index('--ros-args')] if '--ros-args' in args else args


def run_node(node_class, node_name, argv=None, *, params_class=None):
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

    Returns
    -------
    int
        0 after SIGINT/SIGTERM or ``--help``, 2 on a bad params file, invalid parameters,
        an unusable scene or a message package that a node imports at start and cannot
        find (``ModuleNotFoundError``). A node with ``done``: its result, or
        :data:`INTERRUPTED_EXIT` (1) after SIGINT/SIGTERM before it was done.

    """
    argv = list(sys.argv if argv is None else argv)
    user = _user_arguments(argv)
    if '-h' in user or '--help' in user:
        print(node_help(node_name, node_class, params_class))
        return 0
    try:
        check_params_files(argv, node_name, params_class)
        # a stop before rclpy handles the signals: a clean stop too
        rclpy.init(args=argv)
    except (ConfigError, ParameterError) as exc:
        return report_config_error(node_name, exc)
    except KeyboardInterrupt:
        rclpy.try_shutdown()
        return 0
    node = done = None
    try:
        node = node_class()
        done = getattr(node, 'done', None)
        if done is None:
            rclpy.spin(node)
        else:
            rclpy.spin_until_future_complete(node, done)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except RuntimeError:
        # A signal that shuts the context down while a callback runs makes the next wait-set
        # construction (RCLError) or message take (a plain RuntimeError from the bindings) fail
        # instead of raising ExternalShutdownException: still a clean stop.
        if rclpy.ok():
            raise
    except (ParameterError, ConfigError, FileNotFoundError, ModuleNotFoundError) as exc:
        return report_config_error(node_name, exc)
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    if done is None:
        return 0
    return int(done.result()) if done.done() else INTERRUPTED_EXIT
