"""
Order of a measurement stream: duplicated and reordered (older) samples are dropped (no ROS).

A network that duplicates or reorders packets (DDS best effort over a lossy link, a relay, a
second publisher) can deliver a ``tip/measured`` sample whose stamp is not newer than the one
the closed loop integrated last. Integrating it again would count one error twice, integrating
an older one would step the correction backwards in time, so :class:`StampOrder` drops both.

A zero stamp is "unstamped" (ROS convention): it cannot be ordered and is admitted as it is.
After a gap of fresh samples (the stream was stale: a restarted publisher, a bag replayed from
its start) the next sample is admitted whatever its stamp and restarts the order.
"""

ADMITTED = 'admitted'
UNSTAMPED = 'unstamped'
RESTARTED = 'restarted'
DUPLICATE = 'duplicate'
OLDER = 'older'
DROPPED = (DUPLICATE, OLDER)
"""The verdicts of :meth:`StampOrder.admit` that drop the sample."""


class StampOrder:
    """
    The stamp of the last admitted sample of one stream, and the samples dropped against it.

    Attributes
    ----------
    last : int or None  [ns]
        Stamp of the last admitted stamped sample (None before the first).
    dropped : dict
        Verdict (``duplicate``: same stamp, ``older``: an earlier stamp) -> samples dropped.

    """

    def __init__(self):
        self.last = None
        self.dropped = {verdict: 0 for verdict in DROPPED}

    def admit(self, stamp_ns, stale=False):
        """
        Decide whether a sample stamped ``stamp_ns`` is integrated; count it if dropped.

        Parameters
        ----------
        stamp_ns : int  [ns]
            The sample's ``header.stamp`` (0: unstamped).
        stale : bool
            Whether the stream was stale when the sample arrived: the sample then restarts the
            order whatever its stamp.

        Returns
        -------
        str
            ``admitted`` (newer than the last), ``unstamped``, ``restarted`` (first, or after a
            stale gap), or a dropped verdict (:data:`DROPPED`: ``duplicate``, ``older``).

        """
        stamp_ns = int(stamp_ns)
        if stamp_ns == 0:
            return UNSTAMPED
        if self.last is None or stale:
            self.last = stamp_ns
            return RESTARTED
        if stamp_ns > self.last:
            self.last = stamp_ns
            return ADMITTED
        verdict = DUPLICATE if stamp_ns == self.last else OLDER
        self.dropped[verdict] += 1
        return verdict
