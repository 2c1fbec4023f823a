"""
``inverse_solver_managed``: ``inverse_solver`` as a lifecycle (managed) node (``docs/nodes.md``).

The same node, parameters and topics as ``inverse_solver``, driven by a lifecycle manager
(:mod:`cbha_inverse.ros.common.lifecycle`): ``configure`` loads the scene and warms the solver
up, ``activate`` starts commanding, ``deactivate`` and ``shutdown`` (when active) publish the
vent command (``vent_pressure``) and stop.
"""

import sys

from cbha_inverse.ros.common.lifecycle import Managed
from cbha_inverse.ros.common.runner import run_node
from cbha_inverse.ros.nodes.inverse_solver import (
    InverseSolverNode, InverseSolverParams, NODE_NAME)


class ManagedInverseSolverNode(InverseSolverNode, Managed):
    """
    ``inverse_solver`` under the lifecycle: unconfigured at construction.

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
        self._init_managed(NODE_NAME, InverseSolverParams, **kwargs)

    def _vent(self):
        """Publish the vent command; return its publisher."""
        self._publish(self.vent_command)
        return self.command_publisher


def main(argv=None):
    """
    Run ``inverse_solver_managed`` until SIGINT/SIGTERM (transitions come from its manager).

    Returns
    -------
    int
        0 on a clean shutdown, 2 on invalid parameters.

    """
    return run_node(ManagedInverseSolverNode, NODE_NAME, argv, params_class=InverseSolverParams,
                    executable='inverse_solver_managed')


if __name__ == '__main__':
    sys.exit(main())
