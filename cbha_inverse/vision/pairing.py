"""
Left/right image pairs by header stamp, in bounded queues (no ROS, no OpenCV).

A hardware-triggered stereo pair carries (nearly) one stamp in both images; the two streams
arrive independently. :class:`StereoPairer` holds the images still waiting for a partner, pairs
an arriving image with the closest-stamped one of the other side when within ``max_dt``, and
drops what can no longer pair: the oldest of a full queue, and every image older than a pair
just completed. ``stereo_tracker`` feeds it the image streams; :class:`DropMonitor` tells the
drops of normal running from a tracker that falls behind.
"""

import collections

SIDES = ('left', 'right')


class StereoPairer:
    """
    Pair left and right images whose stamps differ by at most ``max_dt``.

    Parameters
    ----------
    max_dt : float  [s]
        Largest stamp difference of a pair (>= 0).
    queue_size : int
        Images kept per side while waiting for a partner (>= 1).

    """

    def __init__(self, max_dt, queue_size):
        self.max_dt = float(max_dt)
        self.queue_size = int(queue_size)
        self.queues = {side: collections.deque() for side in SIDES}

    def add(self, side, stamp, item):
        """
        Add an image; return the pair it completes and the images dropped meanwhile.

        Parameters
        ----------
        side : {'left', 'right'}
            The camera.
        stamp : float  [s]
            The image's header stamp.
        item : object
            What the caller pairs (e.g. the pixels and the message stamp).

        Returns
        -------
        pair : (left item, right item) or None
            The pair completed by this image (the closest-stamped image of the other side),
            or None: the image waits in its queue.
        dropped : tuple of str
            One reason per dropped image: ``'no_partner'`` (this side's queue was full: its
            oldest image went) or ``'superseded'`` (older than the completed pair).

        """
        other = SIDES[1 - SIDES.index(side)]
        partner = min(self.queues[other], key=lambda entry: abs(entry[0] - stamp), default=None)
        if partner is None or abs(partner[0] - stamp) > self.max_dt:
            queue = self.queues[side]
            dropped = ()
            if len(queue) >= self.queue_size:
                queue.popleft()
                dropped = ('no_partner',)
            queue.append((stamp, item))
            return None, dropped
        dropped = []
        for queue, keep_after in ((self.queues[other], partner[0]), (self.queues[side], stamp)):
            while queue and queue[0][0] < keep_after:
                queue.popleft()
                dropped.append('superseded')
        self.queues[other].popleft()
        pair = (item, partner[1]) if side == 'left' else (partner[1], item)
        return pair, tuple(dropped)


class DropMonitor:
    """
    Whether a tracker falls behind: the share of dropped images over the last ones.

    A few images dropped now and then are normal (two free-running streams, a pair that one
    delayed image misses); a tracker that drops a large share of them cannot keep up.

    Parameters
    ----------
    window : int
        Number of arriving images the share is taken over (>= 1).
    share : float
        Share of dropped images, in (0, 1], from which the tracker falls behind.

    """

    def __init__(self, window=60, share=0.25):
        if window < 1 or not 0.0 < share <= 1.0:
            raise ValueError(f'need window >= 1 and share in (0, 1], got {window}, {share}')
        self.share = float(share)
        self.events = collections.deque(maxlen=int(window))

    def add(self, dropped):
        """
        Record one arriving image and the images dropped on its arrival.

        Parameters
        ----------
        dropped : int
            Images dropped when it arrived (>= 0).

        Returns
        -------
        bool
            Whether the tracker falls behind: a full window whose dropped images reach
            ``share`` of its arrivals.

        """
        self.events.append(int(dropped))
        return (len(self.events) == self.events.maxlen
                and sum(self.events) >= self.share * len(self.events))
