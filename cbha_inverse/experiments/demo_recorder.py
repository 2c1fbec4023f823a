"""
The demo's in-process subscriber (``cbha_demo``): what a run's nodes publish, and the run's gates.

It keeps the targets and the true, measured and estimated tips with their stamps, and the last
``/diagnostics`` status of every node (which tells that a node is up: it spins).
"""

import time


class Recorder:
    """
    Subscribe to tip/true, tip/measured, tip/estimated, /diagnostics (one node in this process).

    Its subscriptions to ``target`` and ``pressure_command`` are the gates of a run
    (:meth:`open_gate`): the trajectory and ``cbha_excite`` wait for one subscriber more than
    they have, this recorder, which subscribes once the nodes are up (``cbha_excite`` starts with
    the plant).
    """

    def __init__(self, context, namespace):
        from cbha_inverse.ros.common.qos import DIAGNOSTICS_QOS, MEASURED_QOS
        from diagnostic_msgs.msg import DiagnosticArray
        from geometry_msgs.msg import PointStamped
        from rclpy.executors import SingleThreadedExecutor
        from rclpy.node import Node

        self.node = Node('cbha_demo_recorder', context=context, namespace=namespace)
        self.targets, self.tips, self.measured, self.diagnostics = [], [], [], {}
        self.estimated = []
        self._gate = None
        self.node.create_subscription(PointStamped, 'tip/estimated', self._point(self.estimated),
                                      MEASURED_QOS)
        self.node.create_subscription(PointStamped, 'tip/true', self._point(self.tips),
                                      MEASURED_QOS)
        self.node.create_subscription(PointStamped, 'tip/measured', self._point(self.measured),
                                      MEASURED_QOS)
        self.node.create_subscription(DiagnosticArray, '/diagnostics', self._on_diagnostics,
                                      DIAGNOSTICS_QOS)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)

    @staticmethod
    def _point(store):
        def callback(message):
            stamp = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
            store.append((stamp, message.point.x, message.point.y, message.point.z))
        return callback

    def _on_diagnostics(self, message):
        for status in message.status:
            self.diagnostics[status.name] = ({v.key: v.value for v in status.values},
                                             time.monotonic())

    def open_gate(self, topic):
        """
        Subscribe to ``target`` (record it) or ``pressure_command`` (only counted).

        A trajectory or ``cbha_excite`` started with ``wait_for_subscribers`` one more than its
        other subscribers publishes nothing until then.
        """
        from cbha_inverse.ros.common.qos import COMMAND_QOS, TARGET_QOS
        from geometry_msgs.msg import PointStamped
        from std_msgs.msg import Float64MultiArray
        if topic == 'target':
            self._gate = self.node.create_subscription(
                PointStamped, 'target', self._point(self.targets), TARGET_QOS)
        else:
            self._gate = self.node.create_subscription(
                Float64MultiArray, topic, lambda message: None, COMMAND_QOS)

    def subscribed(self, node, topic):
        """Return whether the node named ``node`` subscribes to ``topic`` (as discovered here)."""
        return any(info.node_name == node
                   for info in self.node.get_subscriptions_info_by_topic(topic))

    def close_gate(self):
        """Destroy the gate's subscription (the next run's nodes wait for a new one)."""
        if self._gate is not None:
            self.node.destroy_subscription(self._gate)
            self._gate = None

    def spin_until(self, predicate, timeout):
        """Spin until ``predicate()`` or ``timeout`` seconds; return the predicate."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not predicate():
            self.executor.spin_once(timeout_sec=0.05)
        return predicate()

    def clear(self):
        """Forget what was recorded."""
        self.targets.clear()
        self.tips.clear()
        self.measured.clear()
        self.estimated.clear()
        self.diagnostics.clear()

    def close(self):
        """Destroy the node."""
        self.executor.shutdown()
        self.node.destroy_node()
