"""The nodes' spin loop (events executor): callbacks run; a stop, ``done`` or shutdown ends it."""

import os
import signal
import threading
import time

from cbha_inverse.ros.common.conversions import command_array, command_message
from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.common.runner import spin_until_stopped, StopRequest
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
        spin_until_stopped(node, StopRequest(), done)
    finally:
        guard.cancel()
        node.destroy_node()
    assert done.done() and rclpy_context.ok()
    assert len(received) == 20
    assert all(np.array_equal(r, values) for r in received)


def test_spin_without_done_returns_when_the_context_shuts_down(rclpy_context):
    """A shutdown of the context from another thread ends the loop."""
    node = Node('spin_until_shutdown', context=rclpy_context)
    ticks = []

    def tick():
        ticks.append(None)
        if len(ticks) == 10:
            threading.Thread(target=rclpy_context.try_shutdown).start()

    node.create_timer(0.01, tick)
    guard = _guard(rclpy_context)
    try:
        spin_until_stopped(node, StopRequest())
    finally:
        guard.cancel()
        node.destroy_node()
    assert 10 <= len(ticks) <= 12


def test_a_stop_signal_during_a_callback_lets_it_finish_then_ends_the_spin(rclpy_context):
    """
    SIGINT while a callback runs: the callback completes, the loop ends at its next poll.

    rclpy's own handlers raise ``KeyboardInterrupt`` at whatever line runs (here: inside the
    callback, which would then never finish) and shut the context down from another thread.
    """
    node = Node('stop_request_probe', context=rclpy_context)
    finished = []

    def busy_callback():
        if not finished:
            # the signal arrives while this Python loop runs
            threading.Timer(0.05, os.kill, (os.getpid(), signal.SIGINT)).start()
            deadline = time.monotonic() + 0.3
            while time.monotonic() < deadline:
                pass
        finished.append(time.monotonic())

    node.create_timer(0.01, busy_callback)
    guard = _guard(rclpy_context)
    try:
        with StopRequest() as stop:
            spin_until_stopped(node, stop)
        assert stop.signal_name == 'SIGINT'
        assert finished, 'the callback the signal landed in did not finish'
        assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
        assert rclpy_context.ok(), 'the loop must leave the shutdown to its caller'
    finally:
        guard.cancel()
        node.destroy_node()


def test_a_stop_signal_ends_the_spin_of_a_node_whose_callbacks_cannot_keep_up(rclpy_context):
    """
    A timer callback longer than its period: a timer event is always queued.

    The events executor ends a spin slice at its timeout only when its queue is empty, so the
    loop's poll of the stop flag between slices would never come: the stop must end the slice.
    """
    node = Node('overloaded_probe', context=rclpy_context)
    ticks = []

    def overloaded_callback():
        ticks.append(time.monotonic())
        if len(ticks) == 100:
            # after 100 back-to-back callbacks (0.5 s, five spin slices); Python runs the
            # handler in this thread before this callback's next line
            os.kill(os.getpid(), signal.SIGINT)
        deadline = time.monotonic() + 0.005
        while time.monotonic() < deadline:
            pass

    node.create_timer(0.002, overloaded_callback)
    guard = _guard(rclpy_context, seconds=10.0)
    try:
        with StopRequest() as stop:
            spin_until_stopped(node, stop)
        assert stop.signal_name == 'SIGINT'
        assert rclpy_context.ok(), 'the stop, not the guard, must end the spin'
        # the slice ends with the callback the signal landed in (a slice's worth is 20)
        assert len(ticks) == 100, len(ticks)
    finally:
        guard.cancel()
        node.destroy_node()
