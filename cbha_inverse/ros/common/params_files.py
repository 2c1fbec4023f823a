"""
Read ROS 2 params files (``<section>: {ros__parameters: {...}}``) without rclpy.

A params file holds sections named by node (``/**``, ``*``, ``/cbha/inverse_solver``,
``inverse_solver``); a section applies to a node when its last name is ``**``, ``*`` or the
node's name. :func:`node_entries` yields the parameters of the applicable sections, with dotted
names for nested mappings, so that the node's start-up check
(:func:`cbha_inverse.ros.common.params.check_params_files`) and ``cbha_launch`` (which must know
what a user's params file sets) read a file the same way.
"""

from cbha_inverse.config_files import read_yaml
from cbha_inverse.errors import ConfigError


def applies_to(section, node_name):
    """Return whether a params-file section (``/**``, ``/ns/node``, ...) applies to the node."""
    return str(section).split('/')[-1] in ('**', '*', node_name)


def flatten(mapping, prefix=''):
    """Yield (dotted name, value) of a nested ``ros__parameters`` mapping."""
    for key, value in mapping.items():
        name = f'{prefix}{key}'
        if isinstance(value, dict):
            yield from flatten(value, f'{name}.')
        else:
            yield name, value


def node_entries(path, node_name):
    """
    Yield every parameter a params file gives a node.

    Parameters
    ----------
    path : str or os.PathLike
        The params file.
    node_name : str
        The node's name (its sections are those of :func:`applies_to`).

    Yields
    ------
    (str, str, object)
        ``(section, dotted parameter name, value)``, in file order (a later one wins in ROS).

    Raises
    ------
    cbha_inverse.errors.ConfigError
        If the file is missing, not YAML, or a section holds no ``ros__parameters`` mapping.

    """
    for section, content in read_yaml(path).items():
        if not isinstance(content, dict) or not isinstance(content.get('ros__parameters'), dict):
            raise ConfigError(path, f'{section}', 'must hold a ros__parameters: mapping')
        if applies_to(section, node_name):
            for name, value in flatten(content['ros__parameters']):
                yield section, name, value


def node_values(path, node_name):
    """Return ``{parameter: value}`` that a params file gives a node (see :func:`node_entries`)."""
    return {name: value for _, name, value in node_entries(path, node_name)}
