"""
Declare a node's parameters from a frozen dataclass and read them back into it once.

The idea of generate_parameter_library without the library: each field of a frozen dataclass
carries its ROS description and range in its ``metadata`` (see :func:`param`);
:func:`declare_parameters` declares every field on the node as a strictly typed parameter with a
``ParameterDescriptor`` (description, ``FloatingPointRange`` / ``IntegerRange``, allowed
choices) and returns the dataclass filled with the values that the params file and ``-p``
overrides gave. Callbacks read that dataclass, never the parameter server.

A field made with ``live=True`` (a tuning parameter) accepts ``set_parameters`` on the running
node when the node passes ``on_change``: the new values get the start-up checks (type, range,
choices, the dataclass's ``__post_init__``), then ``on_change(old, new)`` applies them (it may
refuse with ``ValueError``); a refused change keeps the old value and answers with the reason.
Every other field (structural: the scene, the valve order, ...) is read-only.
"""

from dataclasses import field, fields, replace

from rcl_interfaces.msg import (
    FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult)
from rclpy.exceptions import (
    InvalidParameterTypeException, InvalidParameterValueException,
    ParameterAlreadyDeclaredException, ParameterUninitializedException)
from rclpy.parameter import Parameter

# ROS type names of the Python defaults, for messages and --help
_TYPE_NAMES = {bool: 'bool', int: 'integer', float: 'double', str: 'string'}
_UNSET_TYPES = {'string_array': Parameter.Type.STRING_ARRAY,
                'double_array': Parameter.Type.DOUBLE_ARRAY}
# what rclpy itself declares on every node (or reads as QoS overrides)
_ROS_PARAMETERS = ('use_sim_time', 'start_type_description_service')
_ROS_PREFIXES = ('qos_overrides.',)


class ParameterError(ValueError):
    """A parameter has the wrong type, is outside its range or not one of its choices."""


def param(default, description, *, low=None, high=None, choices=None, ros_name=None,
          unset_type=None, live=False):
    """
    Return a dataclass field that describes one ROS parameter.

    Parameters
    ----------
    default : bool, int, float, str, tuple or None
        Default value; its type is the parameter's type (a tuple of floats is a double array, of
        str a string array). Write floats as floats (``1.0``), as ROS parameters are strictly
        typed. ``None``: no default (the parameter is unset unless given; needs
        ``unset_type``).
    description : str
        What the parameter means, with its unit.
    low, high : float or int, optional
        Inclusive range of a scalar int or float parameter (both or neither).
    choices : tuple of str, optional
        Allowed values of a string parameter.
    ros_name : str, optional
        Parameter name when it differs from the field name (e.g. dotted names).
    unset_type : str, optional
        ROS type of a parameter without default: ``'string_array'`` or ``'double_array'``.
    live : bool
        A tuning parameter, settable on the running node (see the module docstring).

    Returns
    -------
    dataclasses.Field
        The field, for use in a frozen dataclass.

    """
    if (low is None) != (high is None):
        raise TypeError('give both low and high, or neither')
    if (default is None) != (unset_type is not None):
        raise TypeError('a parameter without default needs unset_type, and only it')
    return field(default=default, metadata={
        'description': description, 'low': low, 'high': high,
        'choices': tuple(choices) if choices is not None else None, 'ros_name': ros_name,
        'unset_type': unset_type, 'live': bool(live)})


def type_name(default, metadata):
    """
    Return the ROS type name of a parameter (``double``, ``string_array``, ...).

    Parameters
    ----------
    default : object
        The parameter's default (``None`` if it has none).
    metadata : mapping
        The field metadata written by :func:`param`.

    Returns
    -------
    str
        The type name as ROS writes it.

    """
    if default is None:
        return metadata['unset_type']
    if isinstance(default, tuple):
        item = type(default[0]) if default else str
        return f'{_TYPE_NAMES[item]}_array'
    return _TYPE_NAMES[type(default)]


def _value_text(value):
    """Write a default as it is written in a params file."""
    if value is None:
        return 'unset'
    if isinstance(value, bool):
        return str(value).lower()
    if isinstance(value, tuple):
        return '[' + ', '.join(_value_text(v) for v in value) + ']'
    return repr(value) if isinstance(value, str) else f'{value!r}'


def parameter_help(params_class):
    """
    Describe every parameter of a node for ``--help``: name, type, default, range, description.

    Parameters
    ----------
    params_class : type
        A frozen dataclass whose fields were made with :func:`param`.

    Returns
    -------
    str
        One entry per parameter (two lines each), in declaration order.

    """
    entries = []
    for spec in fields(params_class):
        metadata = spec.metadata
        name = metadata.get('ros_name') or spec.name
        facts = [type_name(spec.default, metadata), f'default {_value_text(spec.default)}']
        if metadata.get('low') is not None:
            facts.append(f"range [{metadata['low']:g}, {metadata['high']:g}]")
        if metadata.get('choices'):
            facts.append('one of ' + '|'.join(metadata['choices']))
        facts.append('live' if metadata.get('live') else 'read-only')
        entries.append(f"  {name} ({', '.join(facts)})\n      {metadata['description']}")
    return '\n'.join(entries)


def describe(name, default, metadata, live=False):
    """
    Build the ``ParameterDescriptor`` of one parameter.

    Parameters
    ----------
    name : str
        Parameter name.
    default : object
        Default value (decides which range type applies).
    metadata : mapping
        The field metadata written by :func:`param`.
    live : bool
        Whether the node accepts changes of it (else it is read-only).

    Returns
    -------
    rcl_interfaces.msg.ParameterDescriptor
        Descriptor with description, range and choices.

    """
    description = metadata.get('description', '')
    choices = metadata.get('choices')
    descriptor = ParameterDescriptor(
        name=name, description=description if live else
        f'{description} (read-only: restart the node to change it)', read_only=not live)
    low, high = metadata.get('low'), metadata.get('high')
    if low is not None and isinstance(default, bool):
        raise TypeError(f'parameter {name}: a bool has no range')
    if low is not None and isinstance(default, int):
        descriptor.integer_range = [IntegerRange(from_value=int(low), to_value=int(high), step=1)]
    elif low is not None and isinstance(default, float):
        descriptor.floating_point_range = [
            FloatingPointRange(from_value=float(low), to_value=float(high), step=0.0)]
    if choices:
        descriptor.additional_constraints = 'one of: ' + ', '.join(choices)
    return descriptor


def declare_parameters(node, params_class, on_change=None):
    """
    Declare every field of ``params_class`` on ``node`` and return the filled dataclass.

    Parameters
    ----------
    node : rclpy.node.Node
        The node (its params file overrides are applied by rclpy at declaration).
    params_class : type
        A frozen dataclass whose fields were made with :func:`param`.
    on_change : callable, optional
        ``on_change(old, new)``: applies accepted changes of the ``live`` fields (raises
        ``ValueError`` to refuse one). Without it, every parameter is read-only.

    Returns
    -------
    params_class
        The values, read once (tuples for array parameters).

    Raises
    ------
    ParameterError
        If a value has the wrong type, lies outside its range or is not one of its choices; the
        message names the parameter, the value and what was expected. The dataclass's own
        ``__post_init__`` checks (if any) may raise ``ValueError`` as well.

    """
    values = {}
    for spec in fields(params_class):
        name = spec.metadata.get('ros_name') or spec.name
        default = spec.default
        ros_default = list(default) if isinstance(default, tuple) else default
        if default is None:
            ros_default = _UNSET_TYPES[spec.metadata['unset_type']]
        live = on_change is not None and spec.metadata.get('live', False)
        descriptor = describe(name, default, spec.metadata, live)
        try:
            value = node.declare_parameter(name, ros_default, descriptor).value
        except InvalidParameterTypeException:
            expected = type_name(default, spec.metadata)
            hint = ' (write floats with a decimal point: 1.0, not 1)' if 'double' in expected \
                else ''
            given = getattr(node, '_parameter_overrides', {}).get(name)
            got = '' if given is None else f', got {given.type_.name.lower()} {given.value!r}'
            raise ParameterError(
                f'parameter {name!r} must be of type {expected}{hint}{got}') from None
        except InvalidParameterValueException as exc:
            raise ParameterError(f'parameter {name!r} is out of range: {exc}') from None
        except (ParameterAlreadyDeclaredException, ParameterUninitializedException) as exc:
            raise ParameterError(f'parameter {name!r}: {exc}') from None
        choices = spec.metadata.get('choices')
        if choices and value not in choices:
            raise ParameterError(
                f'parameter {name!r} must be one of {list(choices)}, got {value!r}')
        values[spec.name] = tuple(value) if isinstance(value, list) else value
    try:
        values = params_class(**values)
    except ValueError as exc:
        raise ParameterError(str(exc)) from None
    if on_change is not None:
        # after the declarations: rclpy runs these callbacks for declare_parameter too
        node.add_on_set_parameters_callback(LiveParameters(values, on_change))
    return values


class LiveParameters:
    """
    The ``add_on_set_parameters_callback`` of a node's live parameters.

    Parameters
    ----------
    current : object
        The node's parameters dataclass as declared.
    on_change : callable
        ``on_change(old, new)``, see :func:`declare_parameters`.

    """

    def __init__(self, current, on_change):
        """Hold the current values."""
        self.current = current
        self.on_change = on_change
        self.specs = {spec.metadata.get('ros_name') or spec.name: spec
                      for spec in fields(type(current))}

    def __call__(self, parameters):
        """Check and apply changed parameters; refuse them all, with the reason, if one is bad."""
        changes = {}
        for parameter in parameters:
            spec = self.specs.get(parameter.name)
            if spec is None:
                continue
            if not spec.metadata.get('live'):
                return SetParametersResult(successful=False, reason=(
                    f'{parameter.name} is read-only: restart the node to change it'))
            value = parameter.value
            if not isinstance(value, (str, bool, int, float)) and value is not None:
                value = list(value)  # arrays arrive as array.array or list
            problem = value_problem(value, spec)
            if problem:
                return SetParametersResult(successful=False,
                                           reason=f'{parameter.name} {problem}')
            changes[spec.name] = tuple(value) if isinstance(value, list) else value
        if not changes:
            return SetParametersResult(successful=True)
        try:
            new = replace(self.current, **changes)
            self.on_change(self.current, new)
        except ValueError as exc:
            return SetParametersResult(successful=False, reason=str(exc))
        self.current = new
        return SetParametersResult(successful=True)


def changes_text(old, new):
    """
    Name the parameters that differ between two values of a node's dataclass, for the log.

    Parameters
    ----------
    old, new : object
        Two instances of the node's parameters dataclass.

    Returns
    -------
    str
        ``name value, ...`` of the changed fields, in declaration order ('' if none).

    """
    return ', '.join(f'{spec.name} {getattr(new, spec.name)}' for spec in fields(new)
                     if getattr(new, spec.name) != getattr(old, spec.name))


def value_problem(value, spec):
    """
    Return why a value does not fit a parameter field ('' if it does).

    Parameters
    ----------
    value : object
        The value as a params file or a parameter message gives it (lists for arrays).
    spec : dataclasses.Field
        A field made with :func:`param`.

    Returns
    -------
    str
        ``must be of type double ...``, ``must lie in [lo, hi] ...``, ``must be one of ...``
        or ''.

    """
    problem = _type_problem(value, type_name(spec.default, spec.metadata))
    low, high = spec.metadata.get('low'), spec.metadata.get('high')
    choices = spec.metadata.get('choices')
    if not problem and low is not None and not low <= value <= high:
        problem = f'must lie in [{low:g}, {high:g}], got {value!r}'
    if not problem and choices and value not in choices:
        problem = f'must be one of {list(choices)}, got {value!r}'
    return problem


def _type_problem(value, expected):
    """Return why ``value`` is not of ROS type ``expected`` ('' if it is)."""
    checks = {'double': lambda v: isinstance(v, float), 'integer': lambda v: isinstance(v, int)
              and not isinstance(v, bool), 'bool': lambda v: isinstance(v, bool),
              'string': lambda v: isinstance(v, str)}
    if expected.endswith('_array'):
        item = checks[expected[:-len('_array')]]
        if isinstance(value, list) and value and all(item(v) for v in value):
            return ''
    elif checks[expected](value):
        return ''
    items = value if isinstance(value, list) else [value]
    integers = any(isinstance(v, int) and not isinstance(v, bool) for v in items)
    hint = ' (write floats with a decimal point: 1.0, not 1)' if (
        'double' in expected and integers) else ''
    return f'must be of type {expected}{hint}, got {value!r}'


def check_params_files(argv, node_name, params_class):
    """
    Check every ``--params-file`` of a node's command line before rclpy reads it.

    rclpy reports a broken params file as a traceback and a wrong-typed entry without the file,
    and ignores a parameter the node does not declare; this names the file and the key.
    Applicable sections are ``/**`` and those whose last name is the node's; there, every
    parameter of ``params_class`` must have its type, range and choices, and no other key may
    appear (but those rclpy declares itself, ``use_sim_time``, ``qos_overrides.*``): a typo is
    named with the nearest parameter. Every ``-p name:=value`` must name a parameter too.

    Parameters
    ----------
    argv : list of str
        The command line (``--ros-args ... --params-file FILE ...``).
    node_name : str
        The node's name.
    params_class : type or None
        Its parameters dataclass (None: check the file structure only).

    Raises
    ------
    cbha_inverse.errors.ConfigError
        Naming the file, the key and what is wrong.
    ParameterError
        On a ``-p`` override of a parameter the node does not have.

    """
    from cbha_inverse.config_files import unknown_key
    from cbha_inverse.errors import ConfigError
    from cbha_inverse.ros.common.params_files import node_entries
    files = [argv[i + 1] for i, arg in enumerate(argv[:-1]) if arg == '--params-file']
    specs = {} if params_class is None else {
        spec.metadata.get('ros_name') or spec.name: spec for spec in fields(params_class)}

    what = f'parameter of {node_name}'

    def unknown(name):
        return params_class is not None and name not in specs and name not in (
            _ROS_PARAMETERS) and not name.startswith(_ROS_PREFIXES)

    for path in files:
        for section, name, value in node_entries(path, node_name):
            key = f'{section}.ros__parameters.{name}'
            if unknown(name):
                raise ConfigError(path, key, unknown_key(name, specs, what))
            spec = specs.get(name)
            if spec is None:
                continue
            problem = value_problem(value, spec)
            if problem:
                raise ConfigError(path, key, problem)
    for item in _parameter_overrides(argv):
        name = item.partition(':=')[0]
        if unknown(name):
            raise ParameterError(f'-p {item}: {unknown_key(name, specs, what)}')


def _parameter_overrides(argv):
    """Return the ``name:=value`` items of the ``-p``/``--param`` ROS arguments."""
    names, inside = [], False
    for i, arg in enumerate(argv):
        if arg == '--ros-args':
            inside = True
        elif arg == '--':
            inside = False
        elif inside and arg in ('-p', '--param') and i + 1 < len(argv):
            names.append(argv[i + 1])
    return names
