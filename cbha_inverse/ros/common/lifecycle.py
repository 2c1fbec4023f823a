"""
Managed (lifecycle) variants of the commanding nodes, for cells brought up by a lifecycle manager.

A managed node is its plain node driven through the ROS 2 lifecycle (``rclpy.lifecycle``):

- constructed: **unconfigured**, its parameters declared (a bad one fails at once, as for the
  plain node), nothing loaded, no topic;
- ``configure``: the slow part (scene, solver warm-up, message imports): **inactive**, still no
  topic (a failure: the transition fails with one logged line, the node stays unconfigured);
- ``activate``: its topics, services and timers are created: it runs as the plain node does;
- ``deactivate``: it vents the arm (its vent command, acknowledged by the subscribers within a
  second), then its topics, services and timers go: **inactive**;
- ``cleanup``: back to unconfigured; ``shutdown`` from any state: vents first when active.

Live parameters (``param(live=True)``) are settable in every state, with the plain node's checks:
a change reaches what the state has built (configured: the model's bounds and gains, the
plain node's ``_retune_model``; active: its timers and watchdogs, ``_retune_interfaces``), and
what is built later reads the new values. Unconfigured, only the checks of the parameters
themselves apply; those that need the scene run at ``configure``.

The plain node class provides ``_setup_model()``, ``_setup_interfaces()`` and the two
``_retune_*(params)``; the managed class
(``class ManagedX(XNode, Managed)``) names the node, its parameters and its executable and adds
``_vent()`` (which returns the publisher it vented on); :class:`Managed` adds the transitions.
"""

from cbha_inverse.ros.common.params import changes_text, declare_parameters, ParameterError
from cbha_inverse.ros.common.runner import run_node
from rclpy.duration import Duration
from rclpy.lifecycle import LifecycleNode, TransitionCallbackReturn
from rclpy.publisher import Publisher
from rclpy.service import Service
from rclpy.subscription import Subscription
from rclpy.timer import Timer

VENT_ACK_TIMEOUT = 1.0
"""Longest wait for the subscribers to acknowledge the vent command [s]."""


def _interfaces(node):
    return [*node.publishers, *node.subscriptions, *node.timers, *node.services]


def _destroy(node, entity):
    for kind, destroy in ((Publisher, node.destroy_publisher),
                          (Subscription, node.destroy_subscription),
                          (Timer, node.destroy_timer), (Service, node.destroy_service)):
        if isinstance(entity, kind):
            destroy(entity)
            return


class Managed(LifecycleNode):
    """
    The lifecycle transitions of a managed node (base class after the plain node's class).

    Use as ``class ManagedX(XNode, Managed)``, with ``__init__ = Managed.__init__`` (the plain
    node's constructor would set everything up at once) and the class attributes below.

    Attributes
    ----------
    node_name, executable : str
        Node name (that of the plain node, for its params files) and executable name.
    params_class : type
        The plain node's parameters dataclass.

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

    node_name = None
    executable = None
    params_class = None

    def __init__(self, **kwargs):
        LifecycleNode.__init__(self, self.node_name, **kwargs)
        self._active_interfaces = None
        self._configured = False
        try:
            self.params = declare_parameters(self, self.params_class, self._on_live_change)
        except ParameterError:
            self.destroy_node()
            raise

    @property
    def active(self):
        """Return True while the node runs, its topics created."""
        return self._active_interfaces is not None

    def _on_live_change(self, old, new):
        """Apply live parameters to what the current state has built (``ValueError``: refused)."""
        if self._configured:
            self._retune_model(new)
        if self.active:
            self._retune_interfaces(new)
        self.params = new
        self.get_logger().info(f'parameters set: {changes_text(old, new)}')

    def on_configure(self, state):
        """Load what the node needs (scene, solver, message types)."""
        try:
            self._setup_model()
        except (ValueError, FileNotFoundError, KeyError, ModuleNotFoundError) as exc:
            self.get_logger().error(f'configure failed: {exc}')
            return TransitionCallbackReturn.FAILURE
        self._configured = True
        self.get_logger().info('configured (inactive: no topics until activate)')
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state):
        """Create the topics, services and timers: the node runs."""
        before = {id(entity) for entity in _interfaces(self)}
        self._setup_interfaces()
        self._active_interfaces = [e for e in _interfaces(self) if id(e) not in before]
        self.get_logger().info('active')
        return TransitionCallbackReturn.SUCCESS

    def on_deactivate(self, state):
        """Vent the arm, then remove the topics, services and timers."""
        self._stop()
        return TransitionCallbackReturn.SUCCESS

    def on_cleanup(self, state):
        """Back to unconfigured."""
        self._configured = False
        self.get_logger().info('cleaned up (unconfigured)')
        return TransitionCallbackReturn.SUCCESS

    def on_shutdown(self, state):
        """From any state: vent the arm first when active."""
        if self.active:
            self._stop()
        self._configured = False
        self.get_logger().info('shut down')
        return TransitionCallbackReturn.SUCCESS

    def on_error(self, state):
        """Vent when active after an error in a transition (then unconfigured)."""
        if self.active:
            self._stop()
        self._configured = False
        return TransitionCallbackReturn.SUCCESS

    def _stop(self):
        publisher = self._vent()
        acknowledged = publisher.wait_for_all_acked(Duration(seconds=VENT_ACK_TIMEOUT))
        if acknowledged:
            self.get_logger().info('vented; inactive')
        else:
            self.get_logger().warn(f'vented, not acknowledged within {VENT_ACK_TIMEOUT:g} s; '
                                   'inactive')
        for entity in self._active_interfaces:
            _destroy(self, entity)
        self._active_interfaces = None


def run_managed(node_class, argv=None):
    """
    Run a managed node until SIGINT/SIGTERM; its transitions come from a lifecycle manager.

    Parameters
    ----------
    node_class : type
        A :class:`Managed` node class.
    argv : list of str, optional
        Command line (default ``sys.argv``).

    Returns
    -------
    int
        0 on a clean shutdown, 2 on invalid parameters.

    """
    return run_node(node_class, node_class.node_name, argv, params_class=node_class.params_class,
                    executable=node_class.executable)
