"""
The node compositions of ``launch/*.launch.py`` and of ``cbha_launch``, described once.

ROS 2's ``launch`` is not installable from PyPI, so each composition is a small table here, read
by both: the launch files of a full ROS install turn it into ``launch_ros`` ``Node`` actions, and
``cbha_launch`` (:mod:`cbha_inverse.ros.launch.launcher`) into processes. Pure Python, no ROS
import.

- ``sim``: ``trajectory`` + ``inverse_solver`` + ``cbha_sim`` (the simulated CBHA), and
  ``stereo_tracker`` when ``feedback:=stereo`` (``cbha_sim`` then renders the cameras of
  ``config/cameras/demo_rig.yaml``, ``tip_output: stereo``; the tracker reads their models from
  the camera_info topics), or ``shape_estimator`` when ``feedback:=proprio`` (``cbha_sim``
  publishes no tip, ``tip_output: none``; ``inverse_solver`` closes its loop on
  ``tip/estimated``, the string-pot estimate, ``docs/proprioception.md``).
- ``robot``: ``inverse_solver`` + ``robotino_bridge`` (the Robotino driver's 8-channel bar
  message; ``driver:=none``: no bridge, your own driver subscribes ``pressure_command``) for a
  real arm, and ``stereo_tracker`` when ``feedback:=stereo`` (the default), or
  ``shape_estimator`` on the driver's string pots when ``feedback:=proprio``.

Every node gets its params file (argument ``<node>_params``, default the installed
``config/<node>.yaml``), then the composition's overrides as a second params file, which wins, as
a ``parameters=[file, {...}]`` list does in a launch file; ``cbha_launch``'s one-off ``-p
<node>.<parameter>:=<value>`` overrides (the ``parameters`` of :func:`resolve`) come last. What
the user sets on a node is its ``<node>_params`` file and its ``-p`` overrides. The overrides of
a *yielding* argument (``scene``, ``mode``) are weaker: given explicitly, they apply, and a node
on which the user sets the parameter otherwise is a conflict (:func:`resolve` raises); not given,
the value the user sets on one node is the argument's for the others (one scene for the cell:
the controller, the simulator and the estimator load the same), and the composition's default
applies only when the user sets it on none. Nodes on which the user sets different scenes keep
them; :func:`resolve` then adds a one-line warning.

``solver_transport:=udp-loopback`` starts ``inverse_solver`` with the environment of
:func:`cbha_inverse.ros.common.transport.loopback_udp_variables`: UDP on 127.0.0.1 alone, no
shared memory, the shortest target -> command tail when every node runs on this host
(``docs/nodes.md``, "Latency"). It needs ``role:=all``: on a split cell the controller would
hear no other machine.
"""

from dataclasses import dataclass, field
from pathlib import Path
from string import Formatter

from cbha_inverse.paths import config_path
from cbha_inverse.ros.common.params_files import node_values
from cbha_inverse.ros.common.transport import loopback_udp_variables


@dataclass(frozen=True)
class Argument:
    """
    A launch argument (``name:=value``).

    Attributes
    ----------
    name : str
    default : str
        Its value when not given ('' for the params-file arguments: the installed file).
    description : str
    choices : tuple of str or None
        The allowed values, if restricted.
    yielding : bool
        Its overrides apply only when it is given, or where no ``<node>_params`` file given by
        the user sets the parameter (see the module docstring); '' means "not given".

    """

    name: str
    default: str
    description: str
    choices: tuple = None
    yielding: bool = False

    def declaration(self):
        """Return the ``DeclareLaunchArgument`` keywords (a yielding argument defaults to '')."""
        if self.yielding:
            return {'default_value': '', 'description': f'{self.description} (default: '
                    f'{self.default}, unless a <node>_params file sets it)'}
        return {'default_value': self.default, 'description': self.description,
                **({'choices': list(self.choices)} if self.choices else {})}


@dataclass(frozen=True)
class Override:
    """
    A parameter a composition sets on a node: ``value`` is a template of argument values.

    Attributes
    ----------
    name : str
        The parameter.
    value : str
        ``str.format`` template, e.g. ``'{scene}'``.
    when : tuple of (str, str) or None
        Only if argument ``when[0]`` equals ``when[1]``.

    """

    name: str
    value: str
    when: tuple = None


@dataclass(frozen=True)
class NodeEntry:
    """
    One node of a composition.

    Attributes
    ----------
    executable : str
        Console script = node name = params-file stem.
    overrides : tuple of Override
    when : tuple of (str, str) or None
        Only started if argument ``when[0]`` equals ``when[1]``.
    role : str
        The machine that runs it (:data:`ROLES`): with ``role:=<it>`` or ``role:=all``.

    """

    executable: str
    overrides: tuple = ()
    when: tuple = None
    role: str = 'control'


@dataclass(frozen=True)
class Composition:
    """
    A set of nodes started together, with its arguments.

    Attributes
    ----------
    name : str
    description : str
    arguments : tuple of Argument
        The composition's own arguments; one ``<node>_params`` argument per node is added by
        :meth:`all_arguments`.
    nodes : tuple of NodeEntry

    """

    name: str
    description: str
    arguments: tuple
    nodes: tuple = field(default=())

    def all_arguments(self):
        """Return the arguments, then one ``<node>_params`` per node (in node order)."""
        params = tuple(Argument(f'{node.executable}_params', '',
                                f'params file of {node.executable} (default: the installed '
                                f'config/{node.executable}.yaml)') for node in self.nodes)
        return self.arguments + params


@dataclass(frozen=True)
class NodeProcess:
    """
    A node as the resolved composition starts it.

    Attributes
    ----------
    executable : str
    namespace : str
    params_files : tuple of str
        In order; later files win.
    parameters : dict
        Overrides (string values), applied after the files.
    environment : dict
        Environment variables set for this node only (str to str; empty: the launcher's).

    """

    executable: str
    namespace: str
    params_files: tuple
    parameters: dict
    environment: dict = field(default_factory=dict)


ROLES = ('robot', 'control', 'cameras')
"""The machines of a cell (``docs/multi-host.md``): the arm's driver or plant, the controller,
the camera PC."""


def _common(feedback_default, feedback_choices, mode_default):
    return (
        Argument('role', 'all', 'the nodes of one machine (docs/multi-host.md), or all',
                 (*ROLES, 'all')),
        Argument('namespace', '/cbha', 'namespace of every node (topics are relative)'),
        Argument('scene', 'cbha.yaml', 'scene YAML of the model (and the plant): a path, or a '
                 'name in config/scenes', yielding=True),
        Argument('mode', mode_default, 'inverse_solver loop: open (model only) or closed '
                 '(integral correction from the tip feedback; it waits for the first one)',
                 ('open', 'closed'), yielding=True),
        Argument('feedback', feedback_default, 'source of the tip feedback (proprio: the '
                 'string-pot estimate tip/estimated)', feedback_choices),
        Argument('solver_transport', 'default', "inverse_solver's DDS transport: default (the "
                 "environment's), or udp-loopback: UDP on 127.0.0.1 alone, no shared memory "
                 '(config/fastdds/udp_loopback.xml; the shortest latency tail with every node on '
                 'this host, role:=all)', ('default', 'udp-loopback')),
    )


SOLVER = 'inverse_solver'
"""The node ``solver_transport`` applies to."""
SCENE = Override('scene', '{scene}')
STEREO = ('feedback', 'stereo')
PROPRIO = ('feedback', 'proprio')
ESTIMATED = Override('feedback_topic', 'tip/estimated', PROPRIO)

COMPOSITIONS = {
    'sim': Composition(
        'sim', 'simulation: trajectory + inverse_solver + cbha_sim (+ stereo_tracker or '
        'shape_estimator)',
        _common('sim', ('sim', 'stereo', 'proprio'), 'closed'),
        (NodeEntry('trajectory'),
         NodeEntry('inverse_solver', (SCENE, Override('mode', '{mode}'), ESTIMATED)),
         # the demo rig (640x512, f = 700 px) renders at 30 frames/s on two cores; the full
         # 1280x1024 default rig reached ~12 pairs/s there with many images dropped
         NodeEntry('cbha_sim', (SCENE, Override('tip_output', 'stereo', STEREO),
                                Override('camera_rig', 'cameras/demo_rig.yaml', STEREO),
                                Override('tip_output', 'none', PROPRIO)),
                   role='robot'),
         NodeEntry('stereo_tracker', when=STEREO, role='cameras'),
         NodeEntry('shape_estimator', (SCENE,), when=PROPRIO))),
    'robot': Composition(
        'robot', 'real arm: inverse_solver + robotino_bridge (+ stereo_tracker or '
        'shape_estimator)',
        _common('stereo', ('stereo', 'none', 'proprio'), 'closed') + (
            Argument('driver', 'robotino', 'robotino: robotino_bridge to the Robotino driver; '
                     'none: no bridge (your driver subscribes pressure_command)',
                     ('robotino', 'none')),),
        (NodeEntry('inverse_solver', (SCENE, Override('mode', '{mode}'), ESTIMATED)),
         NodeEntry('stereo_tracker', when=STEREO, role='cameras'),
         NodeEntry('shape_estimator', (SCENE,), when=PROPRIO),
         NodeEntry('robotino_bridge', when=('driver', 'robotino'), role='robot'))),
}


class ArgumentError(ValueError):
    """A launch argument is unknown, has a value outside its choices or conflicts with a file."""


def _yielding_overrides(node, chosen, arguments, explicit, from_nodes):
    """
    Return the overrides of a node, the yielding ones as the module docstring says.

    Parameters
    ----------
    node : NodeEntry
        The node.
    chosen : dict
        Argument values ('' for a yielding argument not given; the cell's value for one that
        the user sets on a node, :func:`_cell_values`).
    arguments : dict
        ``name -> Argument``.
    explicit : dict
        ``parameter -> (value, where)`` that the user sets on this node: its ``<node>_params``
        file or a ``-p`` override (:func:`_explicit`).
    from_nodes : set of str
        The yielding arguments whose value in ``chosen`` comes from a node, not the user.

    Returns
    -------
    dict
        ``parameter -> value`` (str).

    Raises
    ------
    ArgumentError
        If a yielding argument is given and the user sets its parameter otherwise.

    """
    overrides = {}
    for override in node.overrides:
        if override.when is not None and chosen[override.when[0]] != override.when[1]:
            continue
        names = {f for _, f, _, _ in Formatter().parse(override.value) if f}
        yielding = [name for name in names if arguments[name].yielding]
        value = override.value.format(**{
            name: chosen[name] or arguments[name].default for name in chosen})
        if yielding and override.name in explicit:
            # the user's own value for this node stays, unless an argument given says otherwise
            given = all(chosen[name] != '' and name not in from_nodes for name in yielding)
            mine, where = explicit[override.name]
            if given and str(mine) != value:
                raise ArgumentError(
                    f'{yielding[0]}:={chosen[yielding[0]]} conflicts with {override.name}: '
                    f'{mine} in {where} (give one of them)')
            if not given:
                continue
        overrides[override.name] = value
    return overrides


def _explicit(node, given_file, parameters):
    """
    Return what the user sets on a node: ``parameter -> (value, where)``.

    The ``<node>_params`` file (every section that applies to the node), then the ``-p
    <node>.<parameter>:=<value>`` overrides, which win.
    """
    explicit = {}
    if given_file:
        explicit.update({name: (value, given_file)
                         for name, value in node_values(given_file, node.executable).items()})
    explicit.update({name: (value, f'-p {node.executable}.{name}')
                     for name, value in parameters.get(node.executable, {}).items()})
    return explicit


def _cell_values(nodes, chosen, arguments, explicit, warnings):
    """
    Give each yielding argument not given the value a node's explicit parameter sets.

    One scene for the cell: when the user sets ``scene`` on one node (its params file, ``-p``),
    every node of the composition that takes the argument loads it too, unless the user sets
    another one on it, which :func:`scene_disagreement` reports in ``warnings``.

    Returns
    -------
    chosen : dict
        ``chosen`` with those values.
    from_nodes : set of str
        The arguments whose value comes from a node.

    """
    chosen = dict(chosen)
    from_nodes = set()
    for name, argument in arguments.items():
        if not argument.yielding or chosen[name] != '':
            continue
        sets = [(node.executable, *explicit[node.executable][override.name])
                for node in nodes for override in node.overrides
                if override.value == f'{{{name}}}' and override.name in explicit[node.executable]]
        if sets:
            chosen[name] = str(sets[0][1])
            from_nodes.add(name)
            if name == 'scene':
                disagreement = scene_disagreement(sets)
                if disagreement:
                    warnings.append(disagreement)
    return chosen, from_nodes


def scene_disagreement(sets):
    """
    Return a one-line warning when nodes of a cell are given different scenes, else ''.

    Parameters
    ----------
    sets : list of (str, str, str)
        ``(node, scene, where)``: the scenes the user sets, node by node.

    Returns
    -------
    str

    """
    def same(scene):
        from cbha_inverse.scene.loader import resolve_scene_path
        try:
            return str(Path(resolve_scene_path(scene)).resolve())
        except FileNotFoundError:       # the node itself reports it
            return str(scene)

    if len({same(scene) for _, scene, _ in sets}) < 2:
        return ''
    return 'the nodes load different scenes: ' + ', '.join(
        f'{node} {scene} ({where})' for node, scene, where in sets)


def resolve(composition, values, parameters=None, warnings=None):
    """
    Return the node processes of a composition for given argument values.

    Parameters
    ----------
    composition : Composition
        The composition.
    values : dict
        ``name -> value`` (str); missing arguments take their defaults.
    parameters : dict, optional
        ``node -> {parameter: value}``: one-off overrides (``cbha_launch -p
        <node>.<parameter>:=<value>``), applied last; typed values.
    warnings : list, optional
        Gets one line per thing the user should know (different scenes on the nodes of the cell).

    Returns
    -------
    list of NodeProcess
        The nodes to start, in table order.

    Raises
    ------
    ArgumentError
        On an unknown argument, a value outside its choices, a yielding argument that
        conflicts with what the user sets on a node, or a ``-p`` override of a node that the
        composition does not start.
    cbha_inverse.errors.ConfigError
        If a user's params file cannot be read.

    """
    parameters = parameters or {}
    warnings = [] if warnings is None else warnings
    arguments = {argument.name: argument for argument in composition.all_arguments()}
    unknown = sorted(set(values) - set(arguments))
    if unknown:
        raise ArgumentError(f'unknown argument {unknown[0]!r} of {composition.name} (known: '
                            f"{', '.join(arguments)})")
    chosen = {name: str(values.get(name, '' if argument.yielding else argument.default))
              for name, argument in arguments.items()}
    for name, argument in arguments.items():
        if argument.choices and chosen[name] not in argument.choices + (
                ('',) if argument.yielding else ()):
            raise ArgumentError(f'{name}:={chosen[name]} is not one of '
                                f"{'|'.join(argument.choices)}")

    def applies(when):
        return when is None or chosen[when[0]] == when[1]

    loopback = chosen['solver_transport'] == 'udp-loopback'
    if loopback and chosen['role'] != 'all':
        raise ArgumentError(f"solver_transport:=udp-loopback keeps inverse_solver's traffic on "
                            '127.0.0.1: it needs every node on this host (role:=all), not '
                            f"role:={chosen['role']}")

    started = [node for node in composition.nodes
               if applies(node.when) and chosen['role'] in ('all', node.role)]
    names = [node.executable for node in started]
    for executable in parameters:
        if executable not in names:
            from cbha_inverse.config_files import nearest
            near = nearest(executable, names)
            raise ArgumentError(f'-p {executable}.<parameter>: {composition.name} starts no node '
                                f'{executable}' + (f', did you mean {near!r}?' if near else
                                                   f" (it starts {', '.join(names)})"))
    explicit = {node.executable: _explicit(node, chosen[f'{node.executable}_params'],
                                           parameters) for node in started}
    chosen, from_nodes = _cell_values(started, chosen, arguments, explicit, warnings)
    processes = []
    for node in started:
        given = chosen[f'{node.executable}_params']
        params = given or str(config_path(f'{node.executable}.yaml'))
        environment = (loopback_udp_variables()
                       if loopback and node.executable == SOLVER else {})
        overrides = _yielding_overrides(node, chosen, arguments, explicit[node.executable],
                                        from_nodes)
        overrides.update(parameters.get(node.executable, {}))
        processes.append(NodeProcess(
            node.executable, chosen['namespace'], (str(Path(params)),), overrides, environment))
    return processes


def node_module(executable):
    """Return the module of a node executable: ``cbha_inverse.ros.nodes.<executable>``."""
    return f'cbha_inverse.ros.nodes.{executable}'
