"""
``robotino_bridge_managed``: ``robotino_bridge`` as a lifecycle (managed) node (``docs/nodes.md``).

The same node, parameters and topics as ``robotino_bridge``, driven by a lifecycle manager
(:mod:`cbha_inverse.ros.common.lifecycle`): ``configure`` imports the driver's messages,
``activate`` starts forwarding, ``deactivate`` and ``shutdown`` (when active) send the vent
set-points to the driver and stop.
"""

import sys

from cbha_inverse.ros.common.lifecycle import Managed
from cbha_inverse.ros.common.runner import run_node
from cbha_inverse.ros.nodes.robotino_bridge import (
    NODE_NAME, RobotinoBridgeNode, RobotinoBridgeParams)


class ManagedRobotinoBridgeNode(RobotinoBridgeNode, Managed):
    """
    ``robotino_bridge`` under the lifecycle: unconfigured at construction.

    Parameters
    ----------
    **kwargs
        Passed to ``rclpy.lifecycle.LifecycleNode`` (``context``, ``namespace``,
        ``parameter_overrides``).

    Raises
    ------
    ParameterError
        On invalid parameters (the node is destroyed first).

    """

    def __init__(self, **kwargs):
        self._init_managed(NODE_NAME, RobotinoBridgeParams, **kwargs)

    def _vent(self):
        """Send the vent set-points to the driver; return their publisher."""
        self._send(self.vent_bar)
        return self.driver_publisher


def main(argv=None):
    """
    Run ``robotino_bridge_managed`` until SIGINT/SIGTERM (transitions come from its manager).

    Returns
    -------
    int
        0 on a clean shutdown, 2 on invalid parameters.

    """
    return run_node(ManagedRobotinoBridgeNode, NODE_NAME, argv,
                    params_class=RobotinoBridgeParams, executable='robotino_bridge_managed')


if __name__ == '__main__':
    sys.exit(main())
