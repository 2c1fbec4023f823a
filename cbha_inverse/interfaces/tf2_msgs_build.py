"""
Build the shipped ``tf2_msgs`` (its ``TFMessage``) with colcon (``cbha_build_tf2_msgs``).

``tf2_msgs/TFMessage``, the type of ``/tf`` and ``/tf_static``, is not on PyPI. On a ROS 2 install
the system ``tf2_msgs`` is used and nothing needs building. Elsewhere this command builds the
package's own copy of ``TFMessage`` (``cbha_inverse/interfaces/tf2_msgs``: same package name,
message name, field name and type, hence the same type hash; ``geometry_msgs/TransformStamped``
comes from the common_interfaces wheels) into a colcon workspace with
:func:`cbha_inverse.interfaces.colcon_build.build_interface_package` (``build``: its options,
what it needs and raises) and :func:`~cbha_inverse.interfaces.colcon_build.build_command`: source
``install/setup.sh`` before starting the nodes that publish TF (``inverse_solver``,
``stereo_tracker``, ``docs/nodes.md``).
"""

import sys

from cbha_inverse.interfaces.colcon_build import build_command, build_interface_package

PACKAGE = 'tf2_msgs'
DEPENDENCIES = ('geometry_msgs',)
"""The interface packages its message uses (``TransformStamped``)."""


def build_tf2_msgs(workspace, **options):
    """Build the shipped package into a workspace; return its install prefix (see ``build``)."""
    return build_interface_package(PACKAGE, workspace, DEPENDENCIES, **options)


def main(argv=None):
    """Run ``cbha_build_tf2_msgs [--workspace WS]``; return 0, or 2 with one line saying why."""
    return build_command(
        PACKAGE, DEPENDENCIES, "Build tf2_msgs's TFMessage (the type of /tf and /tf_static) "
        'shipped with cbha_inverse into a colcon workspace (a ROS 2 install has its own).',
        'before starting the nodes that publish TF', argv)


if __name__ == '__main__':
    sys.exit(main())
