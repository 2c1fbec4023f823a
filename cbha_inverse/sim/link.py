"""
A faulty network link: drop, fixed delay + jitter, duplicate and reorder messages (no ROS).

What ``tc netem`` would do to a link, done to a message stream in user space, with a seeded
random generator so that a test run is repeatable. The ``fault_relay`` node
(``cbha_inverse/ros/nodes/fault_relay.py``) puts one :class:`FaultyLink` on each relayed topic.

Each sent message is, in this order: dropped with probability ``drop``; otherwise due after
``delay`` plus a uniform jitter in ``[-jitter, +jitter]`` (never before it was sent), in the
order sent (jitter alone keeps the order, as on one network path); with probability ``reorder``
it is held back a further ``reorder_delay`` so that the messages sent after it overtake it; with
probability ``duplicate`` a second copy is due right after it.
"""

from dataclasses import dataclass
import heapq
import math

import numpy as np


@dataclass(frozen=True)
class LinkFaults:
    """
    The faults of one link.

    Attributes
    ----------
    drop, duplicate, reorder : float  [-]
        Probabilities per message, in [0, 1].
    delay, jitter, reorder_delay : float  [s]
        Fixed delay, half-width of the uniform jitter, extra delay of a reordered message (>= 0).

    Raises
    ------
    ValueError
        On a probability outside [0, 1] or a negative or non-finite time.

    """

    drop: float = 0.0
    delay: float = 0.0
    jitter: float = 0.0
    duplicate: float = 0.0
    reorder: float = 0.0
    reorder_delay: float = 0.02

    def __post_init__(self):
        """Check the ranges."""
        for name in ('drop', 'duplicate', 'reorder'):
            value = getattr(self, name)
            if not 0.0 <= value <= 1.0:
                raise ValueError(f'{name} must be a probability in [0, 1], got {value}')
        for name in ('delay', 'jitter', 'reorder_delay'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0.0):
                raise ValueError(f'{name} must be a finite time >= 0 s, got {value}')


class FaultyLink:
    """
    Messages in, the same messages out later, some dropped, duplicated or reordered.

    Parameters
    ----------
    faults : LinkFaults
        What the link does.
    seed : int
        Seed of the link's random generator.

    Attributes
    ----------
    counts : dict
        ``sent``, ``dropped``, ``duplicated``, ``reordered``, ``delivered`` message counts.

    """

    def __init__(self, faults, seed=0):
        self.faults = faults
        self._rng = np.random.default_rng(seed)
        self._queue = []            # heap of (due [s], sequence, message)
        self._sequence = 0
        self._last_due = -math.inf  # due time of the last in-order message
        self.counts = {k: 0 for k in ('sent', 'dropped', 'duplicated', 'reordered', 'delivered')}

    def __len__(self):
        """Return the number of messages in flight."""
        return len(self._queue)

    def _push(self, due, message):
        heapq.heappush(self._queue, (due, self._sequence, message))
        self._sequence += 1

    def send(self, message, now):
        """
        Put ``message`` on the link at time ``now`` [s].

        Returns
        -------
        int
            Copies queued (0: dropped, 1, or 2: duplicated).

        """
        faults, rng = self.faults, self._rng
        self.counts['sent'] += 1
        # one draw per fault and message, so that the faults of one message do not shift the
        # random stream of the others
        drop, jitter, reorder, duplicate = rng.random(4)
        if drop < faults.drop:
            self.counts['dropped'] += 1
            return 0
        due = now + max(0.0, faults.delay + (2.0 * jitter - 1.0) * faults.jitter)
        due = max(due, self._last_due)
        if reorder < faults.reorder:
            self.counts['reordered'] += 1
            due += faults.reorder_delay
        else:
            self._last_due = due
        self._push(due, message)
        if duplicate < faults.duplicate:
            self.counts['duplicated'] += 1
            self._push(due, message)
            return 2
        return 1

    def next_due(self):
        """Return the due time [s] of the next message (``inf`` when none is in flight)."""
        return self._queue[0][0] if self._queue else math.inf

    def receive(self, now):
        """
        Return the messages due at ``now`` [s], in delivery order, and take them off the link.

        Returns
        -------
        list
            The messages (copies of a duplicated one appear twice).

        """
        out = []
        while self._queue and self._queue[0][0] <= now:
            out.append(heapq.heappop(self._queue)[2])
        self.counts['delivered'] += len(out)
        return out
