"""
Build the shipped ``tf2_msgs`` (its ``TFMessage``) with colcon (``cbha_build_tf2_msgs``).

``tf2_msgs/TFMessage``, the type of ``/tf`` and ``/tf_static``, is not on PyPI. On a ROS 2 install
the system ``tf2_msgs`` is used and nothing needs building. Elsewhere this command builds the
package's own copy of ``TFMessage`` (``cbha_inverse/interfaces/tf2_msgs``: same package name,
message name, field name and type, hence the same type hash; ``geometry_msgs/TransformStamped``
comes from the common_interfaces wheels) into a colcon workspace with
:func:`cbha_inverse.interfaces.colcon_build.build_interface_package`: source
``install/setup.sh`` before starting the nodes that publish TF (``inverse_solver``,
``stereo_tracker``, ``docs/nodes.md``).
"""

import sys

from cbha_inverse.interfaces.colcon_build import build_command, build_interface_package

PACKAGE = 'tf2_msgs'
DEPENDENCIES = ('geometry_msgs',)
"""The interface packages its message uses (``TransformStamped``)."""


def build_tf2_msgs(workspace, timeout=600.0, env=None):
    """
    Copy the shipped ``tf2_msgs`` into ``<workspace>/src`` and build it with colcon.

    Parameters
    ----------
    workspace : str or os.PathLike
        Workspace folder (created if missing; an earlier build there is reused by colcon).
    timeout : float  [s]
        Longest build.
    env : mapping, optional
        Starting environment (default ``os.environ``).

    Returns
    -------
    pathlib.Path
        The install prefix (``<workspace>/install/tf2_msgs``).

    Raises
    ------
    cbha_inverse.interfaces.colcon_build.BuildError
        If a build tool is missing, the export files are not repaired, or colcon fails.

    """
    return build_interface_package(PACKAGE, workspace, DEPENDENCIES, timeout, env)


def main(argv=None):
    """
    Build ``tf2_msgs`` into a workspace and say how to use it.

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on success, 2 when the package cannot be built here (one line says why).

    """
    return build_command(
        PACKAGE, DEPENDENCIES, "Build tf2_msgs's TFMessage (the type of /tf and /tf_static) "
        'shipped with cbha_inverse into a colcon workspace (a ROS 2 install has its own).',
        'before starting the nodes that publish TF', argv)


if __name__ == '__main__':
    sys.exit(main())
