"""
``cbha_bag record``: subscribe raw (no deserialisation) and write a rosbag2 bag (v9 + MCAP).

A topic is subscribed as soon as the graph shows it with a publisher (polled every 0.1 s on the
steady clock), with the profile that reaches every publisher (reliable only if all are, see
:func:`cbha_inverse.bag.qos.adapt_offered`) and a deep history; the publishers' offered profiles
go into the metadata. Each message is written in its callback with the receive time of the node
clock (``--use-sim-time``: ``/clock``), so SIGINT or SIGTERM loses nothing that was received: the
spin loop ends and the bag is closed (``metadata.yaml`` written). A requested topic without a
publisher after :data:`NO_PUBLISHER_WARNING` seconds is warned about once (with the nearest topic
of the graph); a bag of 0 messages is an error (exit 1) unless ``--allow-empty``.
"""

import sys
import time

from cbha_inverse.bag.qos import adapt_offered
from cbha_inverse.bag.storage import absolute_topic, BagError, BagWriter, knows_type
from cbha_inverse.config_files import nearest
from cbha_inverse.errors import report_config_error, report_error
from cbha_inverse.ros.bag.qos import message_class, qos_from_rclpy, qos_to_rclpy
from cbha_inverse.ros.common.runner import SPIN_POLL_S, StopRequest
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.parameter import Parameter

RECORD_DEPTH = 1000
"""History depth of the recorder's subscriptions (a slow disk must not drop reliable samples)."""

NO_PUBLISHER_WARNING = 3.0
"""Seconds after the start when a requested topic without a publisher is warned about."""


class BagRecorder:
    """
    One rclpy node that records topics into a :class:`cbha_inverse.bag.storage.BagWriter`.

    Parameters
    ----------
    context : rclpy.Context
        Initialised context.
    writer : cbha_inverse.bag.storage.BagWriter
        The open bag.
    topics : sequence of str
        Topics to record (ignored with ``all_topics``).
    all_topics : bool
        Record every topic that appears (hidden topics excluded).
    use_sim_time : bool
        Time stamps from ``/clock`` instead of the system clock.
    progress : file-like, optional
        Where the progress line goes once a second (default stderr).

    """

    def __init__(self, context, writer, topics=(), all_topics=False, use_sim_time=False,
                 progress=None):
        self.node = Node('cbha_bag_record', context=context, start_parameter_services=False,
                         parameter_overrides=[Parameter('use_sim_time', value=use_sim_time)])
        self.writer = writer
        self.wanted = {absolute_topic(t) for t in topics}
        self.all_topics = all_topics
        self.progress = sys.stderr if progress is None else progress
        self.subscriptions = {}
        self.skipped = set()
        self.started = time.monotonic()
        self.warned = set()
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.node.create_timer(0.1, self.discover, clock=steady)
        self.node.create_timer(1.0, self.report, clock=steady)
        self.discover()

    def discover(self):
        """Subscribe to every wanted topic that now has a publisher."""
        for name, types in self.node.get_topic_names_and_types():
            if name in self.subscriptions or name in self.skipped:
                continue
            if not (name in self.wanted or (self.all_topics and '/_' not in name)):
                continue
            publishers = self.node.get_publishers_info_by_topic(name)
            if not publishers:
                continue
            msgtype = types[0]
            try:
                if len(types) > 1 or not knows_type(msgtype):
                    raise ValueError(f'type {", ".join(types)} is not recordable')
                message_type = message_class(msgtype)
            except ValueError as exc:
                self.skipped.add(name)
                self._say(f'not recording {name}: {exc}')
                continue
            offered = [qos_from_rclpy(info.qos_profile) for info in publishers]
            subscribe_qos = qos_to_rclpy(adapt_offered(offered)._replace(depth=RECORD_DEPTH))
            self.writer.add_topic(name, msgtype, offered)
            self.subscriptions[name] = self.node.create_subscription(
                message_type, name, self._writer_for(name), subscribe_qos, raw=True)
            self._say(f"Subscribed to topic '{name}'")

    def _writer_for(self, name):
        def callback(data):
            self.writer.write(name, self.node.get_clock().now().nanoseconds, data)
        return callback

    def _say(self, text):
        print(text, file=self.progress, flush=True)

    def missing(self):
        """Return the requested topics that have no subscription yet (sorted)."""
        return sorted(self.wanted - set(self.subscriptions) - self.skipped)

    def warn_missing(self, now):
        """Warn once about each requested topic still without publisher after the delay."""
        if now - self.started < NO_PUBLISHER_WARNING:
            return
        graph = [name for name, _ in self.node.get_topic_names_and_types()]
        for name in self.missing():
            if name not in self.warned:
                self.warned.add(name)
                near = nearest(name, set(graph) - {name})
                hint = f' (did you mean {near}?)' if near else ''
                self._say(f'warning: no publisher of {name} after {NO_PUBLISHER_WARNING:g} s'
                          f'{hint}; still waiting')

    def report(self):
        """Print the progress line: messages recorded per topic."""
        self.warn_missing(time.monotonic())
        counts = ', '.join(f'{name} {count}' for name, count in self.writer.counts.items())
        self._say(f'recording {sum(self.writer.counts.values())} messages: {counts or "-"}')

    def destroy(self):
        """Destroy the node."""
        self.node.destroy_node()


def record(args):
    """
    Run ``cbha_bag record`` until ``--duration``, SIGINT or SIGTERM; return the exit code.

    Parameters
    ----------
    args : argparse.Namespace
        ``output``, ``topics``, ``all``, ``duration``, ``max_bag_size``, ``max_bag_duration``,
        ``use_sim_time``.

    Returns
    -------
    int
        0 once the bag is closed, 1 if it holds no message (unless ``allow_empty``), 2 on bad
        arguments.

    """
    import rclpy
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.signals import SignalHandlerOptions

    if not args.topics and not args.all:
        return report_config_error('cbha_bag record', 'give topics or -a')
    output = args.output or time.strftime('rosbag2_%Y_%m_%d-%H_%M_%S')
    try:
        writer = BagWriter(output, max_bag_size=args.max_bag_size,
                           max_bag_duration=int(args.max_bag_duration * 1e9))
    except (BagError, OSError) as exc:
        return report_config_error('cbha_bag record', exc)
    # SIGINT/SIGTERM only set a flag: a signal never interrupts a write half-way, the loop
    # notices it within SPIN_POLL_S and the bag is closed below
    with StopRequest() as stop:
        rclpy.init(signal_handler_options=SignalHandlerOptions.NO)
        recorder = executor = None
        try:
            recorder = BagRecorder(rclpy.get_default_context(), writer, args.topics, args.all,
                                   args.use_sim_time)
            executor = SingleThreadedExecutor()
            executor.add_node(recorder.node)
            deadline = time.monotonic() + args.duration if args.duration > 0 else float('inf')
            while not stop.requested and time.monotonic() < deadline:
                executor.spin_once(
                    timeout_sec=min(SPIN_POLL_S, max(deadline - time.monotonic(), 0.0)))
        finally:
            path = writer.close()
            if recorder is not None:
                recorder.report()
                recorder.destroy()
            if executor is not None:
                executor.shutdown()
            rclpy.try_shutdown()
    total = sum(writer.counts.values())
    print(f'wrote {path} ({total} messages)', file=sys.stderr)
    if total == 0 and not getattr(args, 'allow_empty', False):
        missing = recorder.missing() if recorder is not None else []
        why = f' (no publisher of {", ".join(missing)})' if missing else ''
        return report_error('cbha_bag record', f'0 messages recorded{why}; --allow-empty '
                            'accepts an empty bag', 1)
    return 0
