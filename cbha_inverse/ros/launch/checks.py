"""
What ``cbha_launch`` checks before it starts a node: the params files and ``-p`` overrides.

A node checks its own params files when it starts (:func:`cbha_inverse.ros.common.params.
check_params_files`), but then the other nodes of the composition are already running, and a
section whose name matches no node (``/cbha/solver:`` for ``/cbha/inverse_solver``) is silently
ignored by ROS. Here, before any node starts:

- every top-level key of a ``<node>_params`` file must match a node of the composition as ROS
  matches it (:func:`section_matches`: ``/**``, ``/<namespace>/<node>``, ``*`` one name,
  ``**`` any; a key without the leading ``/`` is from the root namespace); one that matches
  none is named with the nearest that would;
- every parameter such a file gives a started node, and every ``-p <node>.<parameter>:=<value>``,
  must be one that the node declares (its parameters dataclass,
  :mod:`cbha_inverse.ros.common.params`), with its type, range and choices; an unknown one is
  named with the nearest the node has.

The node modules are imported for their parameters dataclasses (about a second, no node starts).
"""

from dataclasses import fields, is_dataclass
import importlib
import re

from cbha_inverse.config_files import nearest, read_yaml, unknown_key
from cbha_inverse.errors import ConfigError
from cbha_inverse.ros.launch.compositions import ArgumentError, node_module

ROS_PARAMETERS = ('use_sim_time', 'start_type_description_service')
"""Parameters rclpy declares on every node (and ``qos_overrides.*``)."""


def section_matches(key, node):
    """
    Return whether a params-file section applies to a node, as ROS (rcl) decides.

    Parameters
    ----------
    key : str
        The section: a fully qualified node name, where ``*`` stands for one name and ``**``
        for any number of them (``/**``, ``/cbha/*``, ``/**/inverse_solver``); without a leading
        ``/`` it is one from the root namespace (``inverse_solver`` = ``/inverse_solver``).
    node : str
        The fully qualified node name (``/cbha/inverse_solver``).

    Returns
    -------
    bool

    """
    names = str(key).strip('/').split('/')
    pattern = ''.join('(/[^/]+)*' if name == '**' else '/[^/]+' if name == '*'
                      else '/' + re.escape(name) for name in names)
    return re.fullmatch(pattern, node) is not None


def full_name(namespace, executable):
    """Return ``/<namespace>/<node>`` (the node is named after its executable)."""
    return f"{namespace.rstrip('/')}/{executable}"


def check_sections(composition, processes):
    """
    Refuse a section of a params file that applies to no node of the composition.

    Parameters
    ----------
    composition : cbha_inverse.ros.launch.compositions.Composition
        Its nodes (all of them, whatever the role and arguments: a file may serve the cell).
    processes : list of cbha_inverse.ros.launch.compositions.NodeProcess
        The resolved composition (their params files; the namespace).

    Raises
    ------
    cbha_inverse.errors.ConfigError
        Naming the file, the key and the nearest key that would match a node.

    """
    if not processes:
        return
    namespace = processes[0].namespace
    nodes = [full_name(namespace, node.executable) for node in composition.nodes]
    for process in processes:
        for path in process.params_files:
            for key in read_yaml(path):
                if any(section_matches(key, node) for node in nodes):
                    continue
                valid = ['/**', *nodes]
                near = nearest(key, valid) or full_name(namespace, process.executable)
                raise ConfigError(path, key, f'applies to no node of {composition.name} '
                                  f'({", ".join(nodes)}); did you mean {near!r}?')


def params_class(executable):
    """
    Return the parameters dataclass of a node executable (imports its module).

    The node module defines one frozen dataclass whose name ends with ``Params``
    (``InverseSolverParams``), which its ``main`` gives :func:`cbha_inverse.ros.common.runner.
    run_node`.
    """
    module = importlib.import_module(node_module(executable))
    found = [value for name, value in vars(module).items() if name.endswith('Params')
             and is_dataclass(value) and value.__module__ == module.__name__]
    if len(found) != 1:
        raise LookupError(f'{module.__name__} defines {len(found)} *Params dataclasses')
    return found[0]


def parameter_value(text):
    """
    Type a ``-p`` value as ``ros2 param set`` and ``--ros-args -p`` do (YAML).

    Parameters
    ----------
    text : str
        ``0.3`` (double), ``3`` (integer), ``true`` (bool), ``[1.0, 2.0]`` (double array),
        anything else a string.

    Returns
    -------
    bool, int, float, str or list

    """
    import yaml
    try:
        value = yaml.safe_load(text)
    except yaml.YAMLError:
        return text
    scalars = (bool, int, float, str)
    if isinstance(value, scalars):
        return value
    if isinstance(value, list) and value and any(
            all(type(item) is kind for item in value) for kind in scalars):
        return value
    return text


def parse_overrides(items):
    """
    Parse ``-p <node>.<parameter>:=<value>`` items.

    Parameters
    ----------
    items : list of str
        The items.

    Returns
    -------
    dict
        ``node -> {parameter: typed value}`` (:func:`parameter_value`).

    Raises
    ------
    cbha_inverse.ros.launch.compositions.ArgumentError
        If an item is not of that form.

    """
    parameters = {}
    for item in items:
        target, sep, text = item.partition(':=')
        node, dot, name = target.partition('.')
        if not sep or not dot or not node or not name:
            raise ArgumentError(f'-p {item}: write -p <node>.<parameter>:=<value> '
                                '(-p inverse_solver.loop_gain:=0.2)')
        parameters.setdefault(node, {})[name] = parameter_value(text)
    return parameters


def check_parameters(processes, parameters, user_files):
    """
    Refuse a parameter that a node does not declare, or a value it would refuse.

    Parameters
    ----------
    processes : list of cbha_inverse.ros.launch.compositions.NodeProcess
        The resolved composition.
    parameters : dict
        ``node -> {parameter: value}`` of the ``-p`` overrides (:func:`parse_overrides`).
    user_files : dict
        ``node -> params file`` the user gave (``<node>_params``); the installed ones hold the
        code's defaults.

    Raises
    ------
    cbha_inverse.errors.ConfigError
        On a file's parameter: the file, the key, the nearest valid name or what is wrong.
    cbha_inverse.ros.common.params.ParameterError
        On a ``-p`` override: the item and the nearest valid name or what is wrong.

    """
    from cbha_inverse.ros.common.params import check_params_files, ParameterError, value_problem
    for process in processes:
        node = process.executable
        given = parameters.get(node, {})
        if not given and not user_files.get(node):
            continue
        specs = {spec.metadata.get('ros_name') or spec.name: spec
                 for spec in fields(params_class(node))}
        if user_files.get(node):
            check_params_files(['--ros-args', '--params-file', user_files[node]], node,
                               params_class(node))
        for name, value in given.items():
            item = f'-p {node}.{name}:={_text(value)}'
            if name in ROS_PARAMETERS or name.startswith('qos_overrides.'):
                continue
            if name not in specs:
                raise ParameterError(f'{item}: {unknown_key(name, specs, f"parameter of {node}")}')
            problem = value_problem(value, specs[name])
            if problem:
                raise ParameterError(f'{item}: {name} {problem}')


def _text(value):
    """Write a typed value back as it was given."""
    import yaml
    return yaml.safe_dump(value, default_flow_style=True).strip().removesuffix('...').strip()
