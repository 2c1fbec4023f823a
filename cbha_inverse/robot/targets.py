"""
The closed loop's target history: which target was current at a measurement's time (no ROS).

A measurement is compared with the target of its own stamp, so that delivery delays and bursts
of measurements stay out of the integral correction
(:class:`cbha_inverse.core.inverse.solver.TargetCorrector`).
"""

import bisect
import collections


class TargetHistory:
    """
    The latest stamped targets.

    Parameters
    ----------
    capacity : int
        Targets kept at most (the oldest are dropped).

    """

    def __init__(self, capacity=256):
        self._entries = collections.deque(maxlen=int(capacity))

    def __len__(self):
        """Return the number of targets kept."""
        return len(self._entries)

    def add(self, stamp_ns, target):
        """Record a target that became current at ``stamp_ns`` [ns] (in stamp order)."""
        self._entries.append((int(stamp_ns), target))

    def at(self, stamp_ns, default):
        """
        Return the target that was current at a stamp.

        Parameters
        ----------
        stamp_ns : int  [ns]
            The measurement's stamp, on the targets' clock.
        default : object
            Returned when the history does not cover the stamp (none yet, a stamp before the
            oldest or after the newest target: unstamped or differently clocked measurements).

        Returns
        -------
        object
            The latest target stamped at or before ``stamp_ns``, or ``default``.

        """
        entries = self._entries
        if not entries or stamp_ns < entries[0][0] or stamp_ns > entries[-1][0]:
            return default
        index = bisect.bisect_right([stamp for stamp, _ in entries], stamp_ns) - 1
        return entries[max(index, 0)][1]
