"""The nodes' spin loop (rclpy's events executor): callbacks run, ``done`` and shutdown end it."""

import threading

from cbha_inverse.ros.common.conversions import command_array, command_message
from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.common.runner import spin
import numpy as np
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import Float64MultiArray


def _guard(context, seconds=30.0):
    """Shut ``context`` down after ``seconds`` (a hung spin ends, and the test fails)."""
    timer = threading.Timer(seconds, context.try_shutdown)
    timer.start()
    return timer


def test_spin_runs_timers_and_messages_until_done(rclpy_context):
    """A timer publishes, the same node receives; spin returns when ``done`` completes."""
    node = Node('spin_until_done', context=rclpy_context)
    publisher = node.create_publisher(Float64MultiArray, 'spin_test', COMMAND_QOS)
    received, done = [], Future()
    values = np.array([1.5, -2.0, 3.25e5])

    def on_message(message):
        received.append(command_array(message))
        if len(received) == 20:
            done.set_result(0)

    node.create_subscription(Float64MultiArray, 'spin_test', on_message, COMMAND_QOS)
    node.create_timer(0.01, lambda: publisher.publish(command_message(values, ['a', 'b', 'c'])))
    guard = _guard(rclpy_context)
    try:
        spin(node, done)
    finally:
        guard.cancel()
        node.destroy_node()
    assert done.done() and rclpy_context.ok()
    assert len(received) == 20
    assert all(np.array_equal(r, values) for r in received)


def test_spin_without_done_returns_when_the_context_shuts_down(rclpy_context):
    """What SIGINT does through rclpy's handler: the context shuts down, spin returns."""
    node = Node('spin_until_shutdown', context=rclpy_context)
    ticks = []

    def tick():
        ticks.append(None)
        if len(ticks) == 10:
            threading.Thread(target=rclpy_context.try_shutdown).start()

    node.create_timer(0.01, tick)
    guard = _guard(rclpy_context)
    try:
        spin(node)
    finally:
        guard.cancel()
        node.destroy_node()
    assert 10 <= len(ticks) <= 12
