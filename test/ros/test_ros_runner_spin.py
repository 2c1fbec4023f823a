"""The nodes' spin loop (events executor): callbacks run; a stop, ``done`` or shutdown ends it."""

import os
import signal
import sys
import threading
import time

from cbha_inverse.ros.common.conversions import command_array, command_message
from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.common.runner import (SignalSafeEvent, spin_until_stopped, StopRequest,
                                            tear_down)
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


def _spin_with_a_signal_at_line(context, line_number, seconds=3.0):
    """
    Spin a node and send SIGINT when the main thread reaches a Python line of the loop.

    Lines are counted in the spin loop's own module and in ``rclpy.task`` (the futures the
    events executor calls at every slice); ``line_number`` 0 counts them without a signal until
    a timer callback sends it. A spin the signal did not end gets a second SIGINT after
    ``seconds`` (its ``KeyboardInterrupt`` ends the test's wait).

    Returns
    -------
    tuple
        (lines counted, ``(function, line)`` the signal was sent at or None, whether the spin
        needed the second signal).

    """
    node = Node('signal_at_a_line', context=context)
    counted, sent_at = [0], []

    def send_stop():
        os.kill(os.getpid(), signal.SIGINT)

    def tracer(frame, event, arg):
        if event == 'line' and not sent_at and frame.f_code.co_filename.endswith(
                (os.path.join('common', 'runner.py'), os.path.join('rclpy', 'task.py'))):
            counted[0] += 1
            if counted[0] == line_number:
                sent_at.append((frame.f_code.co_name, frame.f_lineno))
                send_stop()
        return tracer

    def on_timer():
        if line_number == 0 and not sent_at and time.monotonic() - start > 0.15:
            sent_at.append(None)
            send_stop()

    node.create_timer(0.01, on_timer)
    rescue = threading.Timer(seconds, send_stop)
    hung = False
    start = time.monotonic()
    measuring = sys.gettrace()   # coverage's tracer: given back after the spin
    try:
        with StopRequest() as stop:
            rescue.start()
            sys.settrace(tracer)
            try:
                spin_until_stopped(node, stop)
            except KeyboardInterrupt:
                hung = True
            finally:
                sys.settrace(measuring)
    finally:
        rescue.cancel()
        node.destroy_node()
    return counted[0], (sent_at or [None])[0], hung


def test_a_stop_signal_at_any_line_of_the_spin_loop_ends_it(rclpy_context):
    """
    SIGINT at each Python line the loop runs: its setup and the first slices.

    Python runs the handler between two bytecodes of the interrupted line. rclpy's ``Future``
    takes a non-reentrant lock in ``add_done_callback`` and ``remove_done_callback``, which the
    events executor calls at every slice: a handler that completed such a future there would
    wait for that lock for ever (a node that ignores Ctrl-C and is killed).
    """
    lines, _, hung = _spin_with_a_signal_at_line(rclpy_context, 0)
    assert not hung and lines >= 20, lines   # the setup and at least one whole slice
    stuck = []
    for line_number in range(1, lines + 1):
        _, sent_at, hung = _spin_with_a_signal_at_line(rclpy_context, line_number)
        assert sent_at is not None, f'line {line_number} of {lines} was never reached'
        if hung:
            stuck.append(sent_at)
    assert not stuck, f'a stop signal at these lines did not end the spin: {stuck}'


def test_signal_safe_event_runs_each_callback_once_as_a_future_does():
    event, calls = SignalSafeEvent(), []
    first, removed = (lambda e: calls.append(('first', e))), (lambda e: calls.append('removed'))
    event.add_done_callback(first)
    event.add_done_callback(removed)
    assert event.remove_done_callback(removed) and not event.remove_done_callback(removed)
    assert not event.done() and calls == []
    event.trigger()
    event.trigger()
    assert event.done() and calls == [('first', event)]
    event.add_done_callback(lambda e: calls.append('late'))   # runs at once, as a done Future's
    assert calls == [('first', event), 'late']


def test_a_teardown_that_does_not_return_ends_within_its_bound(rclpy_context, capfd):
    """A ``destroy_node`` that blocks (as rclpy's now and then does) costs the bound, no more."""
    node = Node('teardown_probe', context=rclpy_context)
    release = threading.Event()
    destroy = node.destroy_node
    node.destroy_node = lambda: release.wait(10.0)
    started = time.monotonic()
    tear_down(node, 0.3)
    waited = time.monotonic() - started
    assert 0.3 <= waited < 2.0
    assert 'did not return within 0.3 s' in capfd.readouterr().err
    release.set()
    node.destroy_node = destroy
    started = time.monotonic()
    tear_down(node, 5.0)
    assert time.monotonic() - started < 2.0
    assert capfd.readouterr().err == ''
