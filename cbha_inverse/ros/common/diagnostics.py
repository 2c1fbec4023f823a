"""
A small ``/diagnostics`` publisher (diagnostic_updater is not on PyPI).

Each node registers one callback that returns its statuses; they are published about once per
second as a ``diagnostic_msgs/DiagnosticArray`` with names ``"<node>: <task>"``. The period runs on
the steady clock (health is reported even while a bag's ``/clock`` pauses); the stamp is the node
clock's (``use_sim_time`` follows ``/clock``).
"""

import collections
import math

from cbha_inverse.ros.common.qos import DIAGNOSTICS_QOS
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
import numpy as np
from rclpy.clock import Clock, ClockType

OK = DiagnosticStatus.OK
WARN = DiagnosticStatus.WARN
ERROR = DiagnosticStatus.ERROR
STALE = DiagnosticStatus.STALE


def make_status(node_name, task, level, message, values=None, hardware_id=''):
    """
    Build one ``DiagnosticStatus``.

    Parameters
    ----------
    node_name : str
        Node name (first part of the status name).
    task : str
        What is reported (second part of the status name).
    level : bytes
        ``OK``, ``WARN``, ``ERROR`` or ``STALE`` (1-byte values in rclpy).
    message : str
        Short human-readable summary.
    values : mapping, optional
        Key/value pairs; values are formatted with ``str`` (floats with 6 significant digits).
    hardware_id : str
        Hardware identifier.

    Returns
    -------
    diagnostic_msgs.msg.DiagnosticStatus
        The status.

    """
    status = DiagnosticStatus(level=level, name=f'{node_name}: {task}', message=message,
                              hardware_id=hardware_id)
    for key, value in (values or {}).items():
        text = f'{value:.6g}' if isinstance(value, float) else str(value)
        status.values.append(KeyValue(key=str(key), value=text))
    return status


class DiagnosticsPublisher:
    """
    Publish a node's statuses on ``/diagnostics`` at a fixed period.

    Parameters
    ----------
    node : rclpy.node.Node
        The node that owns the publisher and the timer.
    collect : callable
        ``collect() -> list of DiagnosticStatus``, called at each period.
    period : float  [s]
        Publication period (about 1 s by convention).

    """

    def __init__(self, node, collect, period=1.0):
        self._node = node
        self._collect = collect
        self.publisher = node.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.timer = node.create_timer(period, self.publish,
                                       clock=Clock(clock_type=ClockType.STEADY_TIME))

    def publish(self):
        """Collect the statuses and publish them once."""
        message = DiagnosticArray()
        message.header.stamp = self._node.get_clock().now().to_msg()
        message.status = list(self._collect())
        self.publisher.publish(message)


class TimingStats:
    """
    Bounded record of durations with median / p99 summaries (for diagnostics).

    Parameters
    ----------
    capacity : int
        Most recent samples kept.

    """

    def __init__(self, capacity=20000):
        self._samples = collections.deque(maxlen=int(capacity))
        self.count = 0

    def add(self, seconds):
        """Record one duration [s]."""
        self._samples.append(float(seconds))
        self.count += 1

    def summary(self, prefix):
        """
        Return ``{prefix_median_ms, prefix_p99_ms, prefix_max_ms}`` over the kept samples.

        Parameters
        ----------
        prefix : str
            Key prefix.

        Returns
        -------
        dict
            Milliseconds (NaN when no sample was recorded).

        """
        if not self._samples:
            values = (math.nan, math.nan, math.nan)
        else:
            samples = np.fromiter(self._samples, dtype=float) * 1e3
            values = (float(np.median(samples)), float(np.percentile(samples, 99)),
                      float(np.max(samples)))
        return dict(zip((f'{prefix}_median_ms', f'{prefix}_p99_ms', f'{prefix}_max_ms'), values))


class RateMeter:
    """
    Messages per second between two diagnostics reports.

    Parameters
    ----------
    now : float  [s]
        Steady time of the start.

    """

    def __init__(self, now):
        self.count = 0
        self._since = now
        self._count_then = 0

    def add(self):
        """Count one message."""
        self.count += 1

    def rate(self, now):
        """Return the messages per second since the last call [Hz] and restart the window."""
        elapsed = now - self._since
        rate = (self.count - self._count_then) / elapsed if elapsed > 0.0 else math.nan
        self._since, self._count_then = now, self.count
        return rate
