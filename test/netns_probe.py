"""
A probe run inside a test host: prints what it receives, one line per message.

``python test/netns_probe.py <namespace>`` subscribes ``target`` (``T``), ``tip/true``
(``P``) and ``pressure_command`` (``C``) in ``<namespace>`` and prints ``<kind> <receive time>
<stamp> <values...>`` (times in seconds; a command has no stamp: ``nan``) until SIGINT/SIGTERM.
"""

import sys
import time


def main(namespace):
    """Spin the probe in ``namespace`` until SIGINT/SIGTERM."""
    import rclpy
    from rclpy.executors import ExternalShutdownException
    from rclpy.node import Node
    from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS, TARGET_QOS
    from geometry_msgs.msg import PointStamped
    from std_msgs.msg import Float64MultiArray

    rclpy.init()
    node = Node('probe', namespace=namespace)

    def point(kind):
        def callback(message):
            stamp = message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec
            p = message.point
            print(f'{kind} {time.time():.6f} {stamp:.9f} {p.x!r} {p.y!r} {p.z!r}', flush=True)
        return callback

    def command(message):
        print(f'C {time.time():.6f} nan ' + ' '.join(repr(v) for v in message.data), flush=True)

    node.create_subscription(PointStamped, 'target', point('T'), TARGET_QOS)
    node.create_subscription(PointStamped, 'tip/true', point('P'), MEASURED_QOS)
    node.create_subscription(Float64MultiArray, 'pressure_command', command, COMMAND_QOS)
    print('probe ready', flush=True)
    try:
        rclpy.spin(node)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    node.destroy_node()
    rclpy.try_shutdown()


if __name__ == '__main__':
    main(sys.argv[1])
