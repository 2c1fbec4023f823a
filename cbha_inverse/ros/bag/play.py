"""
``cbha_bag play``: publish a bag's raw CDR bytes with the recorded timing.

Publishers use the bag's offered QoS as rosbag2's player adapts it
(:func:`cbha_inverse.bag.qos.adapt_offered`), or the profile of ``--qos-profile-overrides-path``.
Message ``k`` with bag time ``t_k`` is published at wall time ``T_0 + (t_k - t_0) / rate`` on the
steady clock (a sleeping wait: a busy wait only loses the CPU sooner on a loaded machine).
``--clock HZ`` publishes ``/clock`` (rosgraph_msgs/Clock) at ``HZ`` Hz of wall time with the bag
time of that instant, for ``use_sim_time`` nodes. The player exits when done, after every
reliable subscriber acknowledged the last messages (bounded wait).
"""

from dataclasses import dataclass
import itertools
import signal
import sys
import time

from cbha_inverse.bag.qos import adapt_offered, load_qos_overrides
from cbha_inverse.bag.storage import absolute_topic, BagError, open_bag
from cbha_inverse.errors import ConfigError, report_config_error
from cbha_inverse.ros.bag.qos import message_class, qos_to_rclpy
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import ReliabilityPolicy
from rosgraph_msgs.msg import Clock

ACK_TIMEOUT = 5.0
"""Longest wait for reliable subscribers to acknowledge the last messages [s]."""


@dataclass(frozen=True)
class PlayOptions:
    """
    How to play a bag (the flags of ``ros2 bag play``).

    Attributes
    ----------
    rate : float
        Playback speed factor (> 0).
    loop : bool
        Start again at the end, until interrupted.
    topics : tuple of str
        Only these topics (empty: all).
    remaps : dict of str to str
        Topic renames ``old -> new``.
    clock_hz : float  [Hz]
        Rate of ``/clock`` publication (0: none).
    start_offset : float  [s]
        Start this far into the bag.
    delay : float  [s]
        Wait this long after creating the publishers.
    qos_overrides : str or None
        Path of a rosbag2 QoS override file.
    wait_for_subscribers : float  [s]
        Wait up to this long until every publisher has a subscriber (0: do not wait).

    """

    rate: float = 1.0
    loop: bool = False
    topics: tuple = ()
    remaps: dict = None
    clock_hz: float = 0.0
    start_offset: float = 0.0
    delay: float = 0.0
    qos_overrides: str = None
    wait_for_subscribers: float = 0.0


def parse_remaps(pairs):
    """
    Parse ``old:=new`` topic remaps.

    Parameters
    ----------
    pairs : sequence of str
        The ``--remap`` arguments.

    Returns
    -------
    dict of str to str
        Absolute old name -> absolute new name.

    Raises
    ------
    ValueError
        If an argument is not ``old:=new``.

    """
    remaps = {}
    for pair in pairs:
        old, separator, new = pair.partition(':=')
        if not separator or not old or not new:
            raise ValueError(f'remap {pair!r} is not old:=new')
        remaps[absolute_topic(old)] = absolute_topic(new)
    return remaps


def _wait_until(due_ns, stopped):
    """Return at steady time ``due_ns`` (sleeping), or within 0.1 s once ``stopped()``."""
    while not stopped():
        remaining = due_ns - time.monotonic_ns()
        if remaining <= 0:
            return
        time.sleep(min(remaining * 1e-9, 0.1))


class BagPlayer:
    """
    Publish the messages of one bag with their recorded timing.

    Parameters
    ----------
    context : rclpy.Context
        Initialised context.
    path : str or os.PathLike
        The bag folder.
    options : PlayOptions
        How to play.

    Raises
    ------
    BagError
        If the bag is missing or damaged or a requested topic is not in it.
    ConfigError
        If the QoS override file is wrong.
    ValueError
        If an option is out of range or a message type is not installed.

    """

    def __init__(self, context, path, options):
        if not options.rate > 0.0:
            raise ValueError(f'--rate must be > 0, got {options.rate}')
        if options.clock_hz < 0.0 or options.start_offset < 0.0 or options.delay < 0.0:
            raise ValueError('--clock, --start-offset and --delay must be >= 0')
        self.path = path
        self.options = options
        with open_bag(path) as bag:
            self.summary = bag.summary
        recorded = {t.name: t for t in self.summary.topics}
        wanted = [absolute_topic(t) for t in options.topics] or list(recorded)
        missing = [t for t in wanted if t not in recorded]
        if missing:
            raise BagError(f'{path}: topics {missing} are not in the bag '
                           f'(it has {sorted(recorded)})')
        self.topics = wanted
        remaps = options.remaps or {}
        defaults = {name: adapt_offered(recorded[name].offered_qos) for name in wanted}
        overrides = (load_qos_overrides(options.qos_overrides, defaults)
                     if options.qos_overrides else {})
        self.node = Node('cbha_bag_play', context=context, start_parameter_services=False)
        self.publishers = {}
        for name in wanted:
            output = remaps.get(name, name)
            qos = overrides.get(name, overrides.get(output, defaults[name]))
            self.publishers[name] = self.node.create_publisher(
                message_class(recorded[name].msgtype), output, qos_to_rclpy(qos))
        self.clock_publisher = (self.node.create_publisher(Clock, '/clock', 1)
                                if options.clock_hz > 0.0 else None)
        self.published = 0
        self.lateness_ns = []
        self.stopped = False

    def _is_stopped(self):
        return self.stopped

    def _all_publishers(self):
        return list(self.publishers.values()) + (
            [self.clock_publisher] if self.clock_publisher is not None else [])

    def wait_for_subscribers(self, timeout):
        """Wait until every publisher has a subscriber, at most ``timeout`` s; return whether."""
        deadline = time.monotonic() + timeout
        while time.monotonic() < deadline and not self.stopped:
            if all(p.get_subscription_count() > 0 for p in self._all_publishers()):
                return True
            time.sleep(0.01)
        return all(p.get_subscription_count() > 0 for p in self._all_publishers())

    def _publish_clock(self, bag_ns):
        message = Clock()
        message.clock.sec, message.clock.nanosec = divmod(int(bag_ns), 1_000_000_000)
        self.clock_publisher.publish(message)

    def play_once(self):
        """Play the bag once from ``start_offset``; return the number of messages published."""
        options = self.options
        begin = self.summary.start_ns + int(options.start_offset * 1e9)
        clock_step = 1e9 / options.clock_hz if options.clock_hz > 0.0 else None
        ticks = 0
        published = 0
        with open_bag(self.path) as bag:
            messages = bag.messages(self.topics, begin)
            first = next(messages, None)
            # the clock starts once the file is open and the first message read
            wall_start = time.monotonic_ns()
            for topic, stamp, data in itertools.chain([first] if first else [], messages):
                due = wall_start + int((stamp - begin) / options.rate)
                while clock_step is not None and wall_start + ticks * clock_step <= due:
                    _wait_until(wall_start + int(ticks * clock_step), self._is_stopped)
                    self._publish_clock(begin + round(ticks * clock_step * options.rate))
                    ticks += 1
                    if self.stopped:
                        return published
                _wait_until(due, self._is_stopped)
                if self.stopped:
                    return published
                self.publishers[topic].publish(data)
                self.lateness_ns.append(time.monotonic_ns() - due)
                published += 1
                self.published += 1
        if clock_step is not None and first is not None:
            self._publish_clock(begin + round((time.monotonic_ns() - wall_start) * options.rate))
        return published

    def play(self):
        """Wait for subscribers, play once or in a loop, wait for acknowledgements."""
        options = self.options
        if options.wait_for_subscribers > 0.0:
            self.wait_for_subscribers(options.wait_for_subscribers)
        delay_end = time.monotonic() + options.delay
        while not self.stopped and time.monotonic() < delay_end:
            time.sleep(min(0.05, max(delay_end - time.monotonic(), 0.0)))
        while not self.stopped:
            self.play_once()
            if not options.loop or self.summary.message_count == 0:
                break
        for publisher in self._all_publishers():
            if publisher.qos_profile.reliability == ReliabilityPolicy.RELIABLE:
                publisher.wait_for_all_acked(Duration(seconds=ACK_TIMEOUT))
        return self.published

    def destroy(self):
        """Destroy the node."""
        self.node.destroy_node()


def play(args):
    """
    Run ``cbha_bag play``; return the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        ``bag``, ``rate``, ``loop``, ``topics``, ``remap``, ``clock``, ``start_offset``,
        ``delay``, ``qos_profile_overrides_path``, ``wait_for_subscribers``.

    Returns
    -------
    int
        0 when played (or interrupted by SIGINT/SIGTERM), 2 for a bad bag or bad options.

    """
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    try:
        options = PlayOptions(
            rate=args.rate, loop=args.loop, topics=tuple(args.topics or ()),
            remaps=parse_remaps(args.remap or ()), clock_hz=args.clock or 0.0,
            start_offset=args.start_offset, delay=args.delay,
            qos_overrides=args.qos_profile_overrides_path,
            wait_for_subscribers=args.wait_for_subscribers)
    except ValueError as exc:
        return report_config_error('cbha_bag play', exc)
    rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
    player = None
    try:
        player = BagPlayer(rclpy.get_default_context(), args.bag, options)

        def stop(*_):
            player.stopped = True
        for number in (signal.SIGINT, signal.SIGTERM):
            signal.signal(number, stop)
        count = player.play()
    except (BagError, ConfigError, ValueError) as exc:
        return report_config_error('cbha_bag play', exc)
    finally:
        if player is not None:
            player.destroy()
        rclpy.try_shutdown()
    lateness = sorted(player.lateness_ns) or [0]
    print(f'played {count} messages from {args.bag}; publish time after schedule median '
          f'{lateness[len(lateness) // 2] * 1e-6:.3f} ms, p99 '
          f'{lateness[int(0.99 * (len(lateness) - 1))] * 1e-6:.3f} ms', file=sys.stderr)
    return 0
