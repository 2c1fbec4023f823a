"""
``inverse_solver_managed``: ``inverse_solver`` as a lifecycle (managed) node (``docs/nodes.md``).

The same node, parameters and topics as ``inverse_solver``, driven by a lifecycle manager
(:mod:`cbha_inverse.ros.common.lifecycle`): ``configure`` loads the scene and warms the solver
up, ``activate`` starts commanding, ``deactivate`` and ``shutdown`` (when active) publish the
vent command (``vent_pressure``) and stop.
"""

import sys

from cbha_inverse.ros.common.lifecycle import Managed, run_managed
from cbha_inverse.ros.nodes.inverse_solver import (
    InverseSolverNode, InverseSolverParams, NODE_NAME)


class ManagedInverseSolverNode(InverseSolverNode, Managed):
    """``inverse_solver`` under the lifecycle: unconfigured at construction."""

    node_name = NODE_NAME
    executable = 'inverse_solver_managed'
    params_class = InverseSolverParams
    __init__ = Managed.__init__

    def _vent(self):
        """Publish the vent command; return its publisher."""
        self._publish(self.vent_command)
        return self.command_publisher


def main(argv=None):
    """Run ``inverse_solver_managed`` until SIGINT/SIGTERM (0; 2 on invalid parameters)."""
    return run_managed(ManagedInverseSolverNode, argv)


if __name__ == '__main__':
    sys.exit(main())
