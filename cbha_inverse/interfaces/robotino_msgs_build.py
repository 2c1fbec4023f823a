"""
Build the shipped ``robotino_msgs`` interface package with colcon (``cbha_build_robotino_msgs``).

The Robotino ROS 2 driver's ``robotino_msgs`` is not on PyPI. Where the driver's source is not at
hand, this command builds the package's own copy of its two CBHA messages
(``cbha_inverse/interfaces/robotino_msgs``: same package name, message names, field names and
types, hence the same type hashes) into a colcon workspace with
:func:`cbha_inverse.interfaces.colcon_build.build_interface_package` (``build``: its options,
what it needs and raises, and how a process then finds the built libraries): source
``install/setup.sh`` (or set the variables of :func:`interface_environment`) before starting a
node.
"""

import sys

from cbha_inverse.interfaces.colcon_build import (  # noqa: F401 (the build API of this package)
    build_command, build_environment, build_interface_package, BuildError, check_build_tools,
    install_prefix as _install_prefix, interface_environment, SHIPPED)

PACKAGE = 'robotino_msgs'
SOURCE = SHIPPED / PACKAGE
"""The shipped ament_cmake package (package.xml, CMakeLists.txt, msg/)."""

DEPENDENCIES = ('builtin_interfaces',)
"""The interface packages its messages use (a stamp)."""


def install_prefix(workspace):
    """Return the install prefix of the package in a workspace (``install/robotino_msgs``)."""
    return _install_prefix(workspace, PACKAGE)


def build_robotino_msgs(workspace, timeout=600.0, env=None):
    """Build the shipped package into a workspace; return its install prefix (see ``build``)."""
    return build_interface_package(PACKAGE, workspace, DEPENDENCIES, timeout, env)


def main(argv=None):
    """
    Build ``robotino_msgs`` into a workspace and say how to use it.

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
        PACKAGE, DEPENDENCIES, "Build the Robotino driver's CBHA messages (robotino_msgs) "
        'shipped with cbha_inverse into a colcon workspace.', 'before starting robotino_bridge',
        argv)


if __name__ == '__main__':
    sys.exit(main())
