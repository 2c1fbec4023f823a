"""
``cbha_ctl``: call a node's services and read or set its parameters, without the ``ros2`` CLI.

What ``ros2 service call`` and ``ros2 param`` do on a full install, for the services and
parameters of this package's nodes:

- ``call NODE SERVICE [true|false]``: a ``std_srvs`` service of the node (``Trigger``,
  ``SetBool`` with the value, ``Empty``); its type is read from the graph;
- ``enable``, ``disable``, ``reset``, ``vent``, ``hold`` ``[--node NODE]``: the services
  ``~/enable`` (true, false), ``~/reset``, ``~/vent`` and ``~/hold`` of a node (default
  ``inverse_solver``);
- ``param list NODE``, ``param get NODE NAME``, ``param set NODE NAME VALUE``: the node's
  ``rcl_interfaces`` parameter services; VALUE is YAML text typed as ``ros2 param set`` types it
  (``0.3`` a double, ``3`` an integer, ``true`` a bool, ``[1.0, 2.0]`` a double array).

A relative NODE (``inverse_solver``) is in ``--namespace`` (default ``/cbha``, or the
``-r __ns:=`` of ``--ros-args``, as for the nodes); ``ROS_DOMAIN_ID`` and the discovery
variables apply as for every node. A node, service or parameter that is not there within
``--timeout`` seconds is one line naming the nearest one that is. Exit status: 0 done, 1 absent or
refused (a ``success: false`` answer, a refused value), 2 bad arguments, 128 + the signal number
after SIGINT/SIGTERM (a stop while the command still loads exits 0, one line:
:mod:`cbha_inverse.ros.common.loading`). ``--help`` starts no ROS.
"""

import argparse
import os
import sys
import time

from cbha_inverse.config_files import nearest
from cbha_inverse.ros.common.loading import loaded, split_ros_arguments

PROGRAM = 'cbha_ctl'

DEFAULT_NODE = 'inverse_solver'
DEFAULT_NAMESPACE = '/cbha'
DEFAULT_TIMEOUT = 5.0
SHORTCUTS = {
    'enable': ('enable', 'true', 'resume commanding (SetBool ~/enable true)'),
    'disable': ('enable', 'false', 'stop commanding (SetBool ~/enable false)'),
    'reset': ('reset', None, 'model and correction back to rest (Trigger ~/reset)'),
    'vent': ('vent', None, 'vent the actuators (Trigger ~/vent)'),
    'hold': ('hold', None, 'hold the last command (Trigger ~/hold)'),
}
"""``shortcut -> (service of the node, SetBool value or None, help)``."""
SERVICE_TYPES = ('std_srvs/srv/Trigger', 'std_srvs/srv/SetBool', 'std_srvs/srv/Empty')
"""The service types ``call`` knows."""
POLL_S = 0.05
"""Longest spin slice [s]: how soon a stop signal or an answer is noticed."""


class Failed(Exception):
    """A node, service or parameter is not there in time, or does not fit: one line, exit 1."""


class Stopped(Exception):
    """SIGINT or SIGTERM arrived while the command waited."""


def _parser():
    # the options go before or after the command: a parent parser whose defaults are suppressed
    # below the top level, so that a value given before the command is not reset after it
    options = argparse.ArgumentParser(add_help=False)
    options.add_argument('--timeout', type=float, default=argparse.SUPPRESS,
                         help='seconds to wait for the node, the service and the answer '
                         f'(default {DEFAULT_TIMEOUT:g})')
    options.add_argument('-n', '--namespace', default=argparse.SUPPRESS,
                         help=f'namespace of a relative NODE (default {DEFAULT_NAMESPACE})')
    parser = argparse.ArgumentParser(
        prog=PROGRAM, parents=[options],
        description=__doc__.strip().splitlines()[0],
        epilog='Exit status: 0 done, 1 absent or refused, 2 bad arguments, 130 Ctrl-C. '
        'ROS arguments after --ros-args (e.g. -r __ns:=/left).')
    commands = parser.add_subparsers(dest='command', required=True, metavar='COMMAND')
    call = commands.add_parser('call', parents=[options],
                               help='call a std_srvs service of a node (ros2 service call)')
    call.add_argument('node', metavar='NODE', help='node name (inverse_solver or '
                      '/cbha/inverse_solver)')
    call.add_argument('service', metavar='SERVICE', help="the node's service (enable, ~/enable)"
                      ' or an absolute service name')
    call.add_argument('value', nargs='?', choices=('true', 'false'),
                      help='the data of a SetBool request')
    for name, (service, value, text) in SHORTCUTS.items():
        shortcut = commands.add_parser(name, parents=[options], help=text)
        shortcut.add_argument('--node', default=DEFAULT_NODE,
                              help=f'the node (default {DEFAULT_NODE})')
    param = commands.add_parser('param', parents=[options],
                                help="a node's parameters (ros2 param)")
    actions = param.add_subparsers(dest='action', required=True, metavar='ACTION')
    listing = actions.add_parser('list', parents=[options], help='the names of its parameters')
    listing.add_argument('node', metavar='NODE')
    get = actions.add_parser('get', parents=[options], help='the value of a parameter')
    get.add_argument('node', metavar='NODE')
    get.add_argument('name', metavar='NAME')
    put = actions.add_parser('set', parents=[options],
                             help='set a parameter (YAML text: 0.3, 3, true, [1.0, 2.0])')
    put.add_argument('node', metavar='NODE')
    put.add_argument('name', metavar='NAME')
    put.add_argument('value', metavar='VALUE')
    return parser


def full_name(name, namespace):
    """
    Return the fully qualified name of a node, or of a service of it.

    Parameters
    ----------
    name : str
        ``/ns/node`` (kept) or ``node`` (in ``namespace``).
    namespace : str
        The namespace of relative names.

    Returns
    -------
    str

    """
    if name.startswith('/'):
        return name
    return f"{namespace.rstrip('/')}/{name}"


def service_name(node, service):
    """Return the full name of a node's service: ``enable`` or ``~/enable`` of ``node``."""
    if service.startswith('/'):
        return service
    return f"{node}/{service[2:] if service.startswith('~/') else service}"


PARAMETER_SERVICES = ('/describe_parameters', '/get_parameter_types', '/get_parameters',
                      '/list_parameters', '/set_parameters', '/set_parameters_atomically',
                      '/get_type_description')
"""The services rclpy gives every node: not named as the nearest of a node's own."""


def did_you_mean(name, known, quote=False):
    """Return ``; did you mean X?`` (the nearest of ``known``), or the list of ``known``."""
    near = nearest(name, known)
    if near is not None:
        return f'; did you mean {near!r}?' if quote else f'; did you mean {near}?'
    return f" (there: {', '.join(sorted(known))})" if known else ' (none there)'


def value_text(value):
    """Return a parameter value as ``ros2 param get`` prints it (``Double value is: 0.1``)."""
    from rcl_interfaces.msg import ParameterType
    from rclpy.parameter import parameter_value_to_python
    kinds = {ParameterType.PARAMETER_BOOL: 'Boolean', ParameterType.PARAMETER_INTEGER: 'Integer',
             ParameterType.PARAMETER_DOUBLE: 'Double', ParameterType.PARAMETER_STRING: 'String',
             ParameterType.PARAMETER_BYTE_ARRAY: 'Byte values',
             ParameterType.PARAMETER_BOOL_ARRAY: 'Boolean values',
             ParameterType.PARAMETER_INTEGER_ARRAY: 'Integer values',
             ParameterType.PARAMETER_DOUBLE_ARRAY: 'Double values',
             ParameterType.PARAMETER_STRING_ARRAY: 'String values'}
    if value.type == ParameterType.PARAMETER_NOT_SET:
        return 'Parameter not set.'
    python = parameter_value_to_python(value)
    if isinstance(python, bool):
        python = str(python).lower()
    elif not isinstance(python, (int, float, str)):
        python = list(python)
    verb = 'are' if value.type >= ParameterType.PARAMETER_BYTE_ARRAY else 'value is'
    return f'{kinds[value.type]} {verb}: {python}'


class Session:
    """
    One short-lived ROS node that looks the graph up and calls services, until a deadline.

    Parameters
    ----------
    context : rclpy.Context
        An initialised context (no signal handlers).
    namespace : str
        Its namespace (relative node names resolve there).
    timeout : float  [s]
        The time every wait of the command shares.
    stop : cbha_inverse.ros.common.runner.StopRequest
        Polled between spin slices.

    """

    def __init__(self, context, namespace, timeout, stop):
        """Create the node and its executor."""
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node
        # the context's --ros-args apply to it (a __ns remapping wins over ``namespace``)
        self.node = Node(f'cbha_ctl_{os.getpid()}', namespace=namespace, context=context,
                         start_parameter_services=False, enable_rosout=False)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)
        self.timeout = timeout
        self.deadline = time.monotonic() + timeout
        self.stop = stop

    @property
    def namespace(self):
        """Return the namespace of relative names."""
        return self.node.get_namespace()

    def destroy(self):
        """Shut the executor down and destroy the node."""
        self.executor.shutdown()
        self.node.destroy_node()

    def spin_until(self, done):
        """Spin until ``done()`` or the deadline; return ``done()``; raise :class:`Stopped`."""
        while True:
            if self.stop.requested:
                raise Stopped(self.stop.signal_name)
            if done():
                return True
            left = self.deadline - time.monotonic()
            if left <= 0.0:
                return False
            self.executor.spin_once(timeout_sec=min(POLL_S, left))

    def nodes(self):
        """Return the fully qualified names of the nodes in the graph."""
        return {full_name(name, namespace) for name, namespace
                in self.node.get_node_names_and_namespaces()}

    def find_node(self, name):
        """Wait until node ``name`` (fully qualified) is in the graph; raise :class:`Failed`."""
        if self.spin_until(lambda: name in self.nodes()):
            return name
        others = sorted(self.nodes() - {self.node.get_fully_qualified_name()})
        raise Failed(f'no node {name} within {self.timeout:g} s{did_you_mean(name, others)}')

    def services_of(self, name):
        """Return ``{service name: type}`` of a node (fully qualified)."""
        namespace, _, node = name.rpartition('/')
        from rclpy.node import NodeNameNonExistentError
        try:
            found = self.node.get_service_names_and_types_by_node(node, namespace or '/')
        except NodeNameNonExistentError:    # not (or no longer) in the graph
            return {}
        return {service: types[0] for service, types in found if types}

    def find_service(self, node, service):
        """Wait for a node's service; return its type; raise :class:`Failed`."""
        self.find_node(node)
        if self.spin_until(lambda: service in self.services_of(node)):
            return self.services_of(node)[service]
        own = sorted(s for s in self.services_of(node) if not s.endswith(PARAMETER_SERVICES))
        raise Failed(f'node {node} has no service {service} within {self.timeout:g} s'
                     f'{did_you_mean(service, own)}')

    def call(self, service_type, service, request):
        """Call a service and return its response; raise :class:`Failed` without one in time."""
        client = self.node.create_client(service_type, service)
        try:
            if not self.spin_until(client.service_is_ready):
                raise Failed(f'service {service} is not ready within {self.timeout:g} s')
            future = client.call_async(request)
            if not self.spin_until(future.done):
                raise Failed(f'no answer from {service} within {self.timeout:g} s')
            return future.result()
        finally:
            self.node.destroy_client(client)


def call_service(session, node, service, value):
    """
    Call a ``std_srvs`` service of a node; return the lines to print and the exit status.

    Parameters
    ----------
    session : Session
        The command's ROS node and deadline.
    node : str
        The node (relative or fully qualified).
    service : str
        Its service (``enable``, ``~/enable``) or an absolute service name.
    value : str or None
        ``'true'`` or ``'false'`` for a ``SetBool``.

    Returns
    -------
    (str, int)

    Raises
    ------
    Failed
        If the node or the service is not there, its type is not a std_srvs one, or the value
        does not fit its type.

    """
    node = full_name(node, session.namespace)
    service = service_name(node, service)
    found = session.find_service(node, service)
    if found not in SERVICE_TYPES:
        raise Failed(f'{service} is a {found}; {PROGRAM} calls {", ".join(SERVICE_TYPES)}')
    from std_srvs.srv import Empty, SetBool, Trigger
    if found == 'std_srvs/srv/SetBool':
        if value is None:
            raise Failed(f'{service} is a SetBool: give true or false')
        response = session.call(SetBool, service, SetBool.Request(data=value == 'true'))
    else:
        if value is not None:
            raise Failed(f'{service} is a {found.rsplit("/", 1)[-1]}: it takes no value')
        service_type = Trigger if found == 'std_srvs/srv/Trigger' else Empty
        response = session.call(service_type, service, service_type.Request())
    if not hasattr(response, 'success'):
        return f'{service}: done', 0
    verdict = 'success' if response.success else 'refused'
    return f'{service}: {verdict}: {response.message}', 0 if response.success else 1


def _parameter_client(session, node):
    from rclpy.parameter_client import AsyncParameterClient
    node = full_name(node, session.namespace)
    session.find_service(node, f'{node}/list_parameters')
    client = AsyncParameterClient(session.node, node)
    if not session.spin_until(client.services_are_ready):
        raise Failed(f'the parameter services of {node} are not ready within '
                     f'{session.timeout:g} s')
    return node, client


def _answer(session, future, what):
    if not session.spin_until(future.done):
        raise Failed(f'no answer to {what} within {session.timeout:g} s')
    return future.result()


def parameter_names(session, client, node):
    """Return the sorted names of a node's parameters."""
    return sorted(_answer(session, client.list_parameters(), f'list_parameters of {node}')
                  .result.names)


def _known(session, client, node, name):
    names = parameter_names(session, client, node)
    if name not in names:
        raise Failed(f'node {node} has no parameter {name!r}'
                     f'{did_you_mean(name, names, quote=True)}')


def parameter_command(session, action, node, name=None, value=None):
    """
    Run ``param list|get|set``; return the lines to print and the exit status.

    Parameters
    ----------
    session : Session
        The command's ROS node and deadline.
    action : str
        ``list``, ``get`` or ``set``.
    node : str
        The node (relative or fully qualified).
    name : str, optional
        The parameter (get, set).
    value : str, optional
        Its new value as YAML text (set), typed as ``ros2 param set`` types it.

    Returns
    -------
    (str, int)

    Raises
    ------
    Failed
        If the node or the parameter is not there.

    """
    node, client = _parameter_client(session, node)
    if action == 'list':
        return '\n'.join(f'  {n}' for n in parameter_names(session, client, node)), 0
    _known(session, client, node, name)
    if action == 'get':
        [found] = _answer(session, client.get_parameters([name]), f'get_parameters of {node}'
                          ).values
        return value_text(found), 0
    from rcl_interfaces.msg import Parameter
    from rclpy.parameter import get_parameter_value
    [result] = _answer(session, client.set_parameters(
        [Parameter(name=name, value=get_parameter_value(value))]),
        f'set_parameters of {node}').results
    if result.successful:
        return 'Set parameter successful', 0
    return f'{PROGRAM}: Setting parameter failed: {result.reason}', 1


def run(args, ros_args):
    """Run a parsed command in a private context; return ``(output, exit status)``."""
    import rclpy
    from cbha_inverse.ros.common.runner import StopRequest
    from rclpy.signals import SignalHandlerOptions
    # from here a stop signal is a flag this command polls: the quiet stop while loading ends
    # (before StopRequest saves the handlers it replaces)
    loaded()
    with StopRequest() as stop:
        context = rclpy.Context()
        rclpy.init(args=['cbha_ctl', *ros_args], context=context,
                   signal_handler_options=SignalHandlerOptions.NO)
        session = None
        try:
            session = Session(context, args.namespace, args.timeout, stop)
            if args.command == 'param':
                return parameter_command(session, args.action, args.node,
                                         getattr(args, 'name', None),
                                         getattr(args, 'value', None))
            if args.command == 'call':
                return call_service(session, args.node, args.service, args.value)
            service, value, _ = SHORTCUTS[args.command]
            return call_service(session, args.node, service, value)
        finally:
            if session is not None:
                session.destroy()
            rclpy.try_shutdown(context=context)


def main(argv=None):
    """
    Run ``cbha_ctl``.

    Parameters
    ----------
    argv : list of str, optional
        Arguments (default ``sys.argv[1:]``); ROS arguments after ``--ros-args``.

    Returns
    -------
    int
        See the module docstring.

    """
    import signal
    own, ros_args = split_ros_arguments(sys.argv[1:] if argv is None else argv)
    args = _parser().parse_args(own)
    args.timeout = getattr(args, 'timeout', DEFAULT_TIMEOUT)
    args.namespace = getattr(args, 'namespace', DEFAULT_NAMESPACE)
    if args.timeout <= 0.0:
        print(f'{PROGRAM}: error: --timeout must be positive', file=sys.stderr)
        return 2
    try:
        output, status = run(args, ros_args)
    except Failed as exc:
        print(f'{PROGRAM}: {exc}', file=sys.stderr)
        return 1
    except Stopped as exc:
        print(f'{PROGRAM}: stopped by {exc}', file=sys.stderr)
        return 128 + signal.Signals[str(exc)].value
    except KeyboardInterrupt:        # a second signal
        print(f'{PROGRAM}: stopped', file=sys.stderr)
        return 128 + signal.SIGINT
    print(output, file=sys.stdout if status == 0 else sys.stderr, flush=True)
    return status


if __name__ == '__main__':
    sys.exit(main())
