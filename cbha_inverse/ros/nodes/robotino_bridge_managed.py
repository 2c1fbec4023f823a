"""
``robotino_bridge_managed``: ``robotino_bridge`` as a lifecycle (managed) node (``docs/nodes.md``).

The same node, parameters and topics as ``robotino_bridge``, driven by a lifecycle manager
(:mod:`cbha_inverse.ros.common.lifecycle`): ``configure`` imports the driver's messages,
``activate`` starts forwarding, ``deactivate`` and ``shutdown`` (when active) send the vent
set-points to the driver and stop.
"""

import sys

from cbha_inverse.ros.common.lifecycle import Managed, run_managed
from cbha_inverse.ros.nodes.robotino_bridge import (
    NODE_NAME, RobotinoBridgeNode, RobotinoBridgeParams)


class ManagedRobotinoBridgeNode(RobotinoBridgeNode, Managed):
    """``robotino_bridge`` under the lifecycle: unconfigured at construction."""

    node_name = NODE_NAME
    executable = 'robotino_bridge_managed'
    params_class = RobotinoBridgeParams
    __init__ = Managed.__init__

    def _vent(self):
        """Send the vent set-points to the driver; return their publisher."""
        self._send(self.vent_bar)
        return self.driver_publisher


def main(argv=None):
    """Run ``robotino_bridge_managed`` until SIGINT/SIGTERM (0; 2 on invalid parameters)."""
    return run_managed(ManagedRobotinoBridgeNode, argv)


if __name__ == '__main__':
    sys.exit(main())
