"""
The rejected inputs of a node: counted by reason, logged (throttled per reason), in diagnostics.

Every node that refuses a message (a malformed command, a point outside the workspace, a stale
reading) counts it in its :class:`Rejections` under a short key (``'target.non_finite'``), logs
one line ``<what> (total <count>)`` at most once per ``log_throttle`` seconds per key (a flood
of one reason does not hide another), and reports the counts on ``/diagnostics``
(:meth:`Rejections.key_values`). Its other repeated warnings and errors go through the same
:class:`ThrottledLog`. The throttle is read at every line, so that a node's live
``log_throttle`` parameter applies at once (rclpy's own ``throttle_duration_sec`` refuses a
duration that changed since the first call: ``ValueError``).
"""

import math
import time


class ThrottledLog:
    """
    A node's log lines, each kind at most once per throttle.

    Parameters
    ----------
    logger : rclpy.impl.rcutils_logger.RcutilsLogger
        The node's logger (``node.get_logger()``).
    throttle : callable
        Returns the least time between two lines of one kind [s] (the node's ``log_throttle``).
    clock : callable
        Steady clock [s] (default ``time.monotonic``).

    """

    def __init__(self, logger, throttle, clock=time.monotonic):
        """Start with nothing logged."""
        self._logger, self._throttle, self._clock = logger, throttle, clock
        self._logged = {}

    def _due(self, kind):
        now = self._clock()
        if now - self._logged.get(kind, -math.inf) < self._throttle():
            return False
        self._logged[kind] = now
        return True

    def warning(self, kind, text):
        """Log ``text`` at WARN unless a line of ``kind`` was logged less than throttle ago."""
        if not self._due(kind):
            return False
        self._logger.warning(text)
        return True

    def error(self, kind, text):
        """Log ``text`` at ERROR unless a line of ``kind`` was logged less than throttle ago."""
        if not self._due(kind):
            return False
        self._logger.error(text)
        return True


class Rejections(dict):
    """
    Rejection counts by key (a dict ``key -> count``), with the throttled log.

    Parameters
    ----------
    log : ThrottledLog
        The node's throttled log.

    """

    def __init__(self, log):
        """Start with no rejection."""
        super().__init__()
        self.log = log

    def count(self, key, what, number=1, error=False):
        """
        Count a rejection; log it unless one of the same key was logged less than throttle ago.

        Parameters
        ----------
        key : str
            The counter (diagnostics key ``rejected.<key>``).
        what : str or None
            The line to log (``'rejected target: non-finite point'``); None: counted only.
        number : int
            How many rejections.
        error : bool
            Log at ERROR (a fault of the node itself) instead of WARN.

        Returns
        -------
        bool
            Whether a line was logged.

        """
        self[key] = self.get(key, 0) + number
        if what is None:
            return False
        text = f'{what} (total {self[key]})'
        return self.log.error(key, text) if error else self.log.warning(key, text)

    @property
    def total(self):
        """Return the number of rejections of every key."""
        return sum(self.values())

    def key_values(self):
        """Return the diagnostics key-values: ``rejected_total`` and ``rejected.<key>``, sorted."""
        return {'rejected_total': self.total,
                **{f'rejected.{key}': count for key, count in sorted(self.items())}}
