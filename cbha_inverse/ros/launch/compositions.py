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
  message) for a real arm, and ``stereo_tracker`` when ``feedback:=stereo`` (the default), or
  ``shape_estimator`` on the driver's string pots when ``feedback:=proprio``.

Every node gets its params file (argument ``<node>_params``, default the installed
``config/<node>.yaml``), then the composition's overrides (scene, mode, ...) as a second params
file, which wins, as a ``parameters=[file, {...}]`` list does in a launch file.
"""

from dataclasses import dataclass, field
from pathlib import Path

from cbha_inverse.paths import config_path


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

    """

    name: str
    default: str
    description: str
    choices: tuple = None


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

    """

    executable: str
    namespace: str
    params_files: tuple
    parameters: dict


ROLES = ('robot', 'control', 'cameras')
"""The machines of a cell (``docs/multi-host.md``): the arm's driver or plant, the controller,
the camera PC."""


def _common(feedback_default, feedback_choices, mode_default):
    return (
        Argument('role', 'all', 'the nodes of one machine (docs/multi-host.md), or all',
                 (*ROLES, 'all')),
        Argument('namespace', '/cbha', 'namespace of every node (topics are relative)'),
        Argument('scene', 'cbha.yaml', 'scene YAML of the model (and the plant): a path, or a '
                 'name in config/scenes'),
        Argument('mode', mode_default, 'inverse_solver loop: open (model only) or closed '
                 '(integral correction from tip/measured; without feedback it holds, so use '
                 'open with feedback:=none)', ('open', 'closed')),
        Argument('feedback', feedback_default, 'source of the tip feedback (proprio: the '
                 'string-pot estimate tip/estimated)', feedback_choices),
    )


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
        _common('stereo', ('stereo', 'none', 'proprio'), 'closed'),
        (NodeEntry('inverse_solver', (SCENE, Override('mode', '{mode}'), ESTIMATED)),
         NodeEntry('stereo_tracker', when=STEREO, role='cameras'),
         NodeEntry('shape_estimator', (SCENE,), when=PROPRIO),
         NodeEntry('robotino_bridge', role='robot'))),
}


class ArgumentError(ValueError):
    """A launch argument is unknown or has a value outside its choices."""


def resolve(composition, values):
    """
    Return the node processes of a composition for given argument values.

    Parameters
    ----------
    composition : Composition
        The composition.
    values : dict
        ``name -> value`` (str); missing arguments take their defaults.

    Returns
    -------
    list of NodeProcess
        The nodes to start, in table order.

    Raises
    ------
    ArgumentError
        On an unknown argument or a value outside its choices.

    """
    arguments = {argument.name: argument for argument in composition.all_arguments()}
    unknown = sorted(set(values) - set(arguments))
    if unknown:
        raise ArgumentError(f'unknown argument {unknown[0]!r} of {composition.name} (known: '
                            f"{', '.join(arguments)})")
    chosen = {name: str(values.get(name, argument.default))
              for name, argument in arguments.items()}
    for name, argument in arguments.items():
        if argument.choices and chosen[name] not in argument.choices:
            raise ArgumentError(f'{name}:={chosen[name]} is not one of '
                                f"{'|'.join(argument.choices)}")

    def applies(when):
        return when is None or chosen[when[0]] == when[1]

    processes = []
    for node in composition.nodes:
        if not applies(node.when) or chosen['role'] not in ('all', node.role):
            continue
        params = chosen[f'{node.executable}_params'] or str(config_path(f'{node.executable}.yaml'))
        processes.append(NodeProcess(
            node.executable, chosen['namespace'], (str(Path(params)),),
            {o.name: o.value.format(**chosen) for o in node.overrides if applies(o.when)}))
    return processes


def node_module(executable):
    """Return the module of a node executable: ``cbha_inverse.ros.nodes.<executable>``."""
    return f'cbha_inverse.ros.nodes.{executable}'
