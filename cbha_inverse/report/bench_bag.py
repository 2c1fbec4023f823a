"""
``cbha_bench_bag``: timing of ``cbha_bag play`` into a real subscriber (goal: p99 <= 2 ms).

Writes a bag with rosbags' ``Writer`` (``--messages`` PointStamped at irregular 2-12 ms intervals,
seeded), plays it with the ``cbha_bag play`` command at each ``--rates`` value into a raw
subscriber in this process, and prints per rate the timing error of the messages: the
middleware's receive time minus the recorded schedule ``(t_k - t_0) / rate``, after removing the
median offset (the constant delivery delay), as median, p99 and max, and the played duration.

``--priority N`` (default 10) runs the player and this process's DDS threads with SCHED_RR
priority N where the OS allows it, as ``chrt -r N`` would; ``--priority 0`` runs them with the
normal policy (on a loaded machine other processes then delay the player's wake-ups).
"""

import argparse
import contextlib
import os
from pathlib import Path
import subprocess
import sys
import tempfile
import time

import numpy as np

GOAL_P99_MS = 2.0


def parse_args(argv):
    """Parse the command line."""
    parser = argparse.ArgumentParser(prog='cbha_bench_bag', description=__doc__.split('\n\n')[0])
    parser.add_argument('--messages', type=int, default=300, help='messages in the bag')
    parser.add_argument('--rates', default='1,2', help='comma-separated playback rates')
    parser.add_argument('--priority', type=int, default=10,
                        help='SCHED_RR priority of the player and the receive threads (0: none)')
    return parser.parse_args(argv)


def write_bag(path, count, seed=3):
    """
    Write the benchmark bag with rosbags' ``Writer``.

    Parameters
    ----------
    path : pathlib.Path
        New bag folder.
    count : int
        Messages on ``/bench``.
    seed : int
        Seed of the intervals.

    Returns
    -------
    list of (int, bytes)
        Bag time [ns] and CDR bytes of each message.

    """
    from geometry_msgs.msg import PointStamped
    from rclpy.serialization import serialize_message
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import get_typestore, Stores

    rng = np.random.default_rng(seed)
    stamp = 1_700_000_000 * 10**9
    content = []
    for k in range(count):
        message = PointStamped()
        message.point.x = float(k)
        content.append((stamp, bytes(serialize_message(message))))
        stamp += int(rng.uniform(2e6, 12e6))
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connection = writer.add_connection(
            '/bench', 'geometry_msgs/msg/PointStamped',
            typestore=get_typestore(Stores.ROS2_JAZZY))
        for stamp, data in content:
            writer.write(connection, stamp, data)
    return content


def set_priority(priority):
    """Switch the calling thread to SCHED_RR ``priority`` if allowed; return whether it did."""
    if priority <= 0:
        return False
    try:
        os.sched_setscheduler(0, os.SCHED_RR, os.sched_param(priority))
    except (OSError, AttributeError):
        return False
    return True


@contextlib.contextmanager
def priority_for_new_threads(priority):
    """Create threads (DDS receive threads inherit the policy) at ``priority``, then restore."""
    previous = os.sched_getscheduler(0), os.sched_getparam(0)
    changed = set_priority(priority)
    try:
        yield changed
    finally:
        if changed:
            os.sched_setscheduler(0, previous[0], previous[1])


def timing_errors(arrivals, schedule, rate):
    """
    Return receive times minus the recorded schedule, median offset removed.

    Parameters
    ----------
    arrivals : (N,) array_like of int  [ns]
        Receive times.
    schedule : (N,) array_like of int  [ns]
        Recorded bag times.
    rate : float
        Playback rate.

    Returns
    -------
    (N,) ndarray  [s]
        Signed timing errors.

    """
    arrival = np.asarray(arrivals, dtype=float)
    recorded = np.asarray(schedule, dtype=float)
    offset = (arrival - arrival[0]) - (recorded - recorded[0]) / rate
    return (offset - np.median(offset)) * 1e-9


def play_and_receive(context, bag, rate, priority, topic='/bench', extra=()):
    """
    Play ``bag`` with ``cbha_bag play`` into a raw subscriber; return the received messages.

    Parameters
    ----------
    context : rclpy.Context
        Initialised context.
    bag : pathlib.Path
        The bag.
    rate : float
        ``--rate``.
    priority : int
        SCHED_RR priority of the player and the receive threads (0: normal policy).
    topic : str
        Topic to receive.
    extra : sequence of str
        More ``cbha_bag play`` arguments.

    Returns
    -------
    list of (int, bytes)
        Middleware receive time [ns] and bytes of each message.

    """
    from geometry_msgs.msg import PointStamped
    from rclpy.executors import SingleThreadedExecutor
    from rclpy.node import Node
    from rclpy.qos import QoSProfile, ReliabilityPolicy

    received = []
    with priority_for_new_threads(priority):
        node = Node('bench_listener', context=context)
    node.create_subscription(
        PointStamped, topic, lambda data, info: received.append(
            (info['received_timestamp'], bytes(data))),
        QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE), raw=True)
    executor = SingleThreadedExecutor(context=context)
    executor.add_node(node)
    env = dict(os.environ)
    env.pop('_ROS_WHEELS_BOOTSTRAP_COMPLETE', None)
    try:
        player = subprocess.Popen(
            [sys.executable, '-m', 'cbha_inverse.ros.bag.cli', 'play', str(bag), '--rate',
             str(rate), '--wait-for-subscribers', '30', *extra], env=env,
            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
            preexec_fn=lambda: set_priority(priority))
        deadline = time.monotonic() + 120.0
        while player.poll() is None and time.monotonic() < deadline:
            executor.spin_once(timeout_sec=0.005)
        drain = time.monotonic() + 0.3
        while time.monotonic() < drain:
            executor.spin_once(timeout_sec=0.005)
        if player.poll() is None:
            player.kill()
        player.wait()
    finally:
        executor.shutdown()
        node.destroy_node()
    return received


def main(argv=None):
    """
    Run the benchmark and print one line per rate.

    Parameters
    ----------
    argv : list of str, optional
        Command line without the program name.

    Returns
    -------
    int
        0 (the numbers are the result), 2 if messages were lost.

    """
    args = parse_args(sys.argv[1:] if argv is None else argv)
    import rclpy
    from rclpy.signals import SignalHandlerOptions

    context = rclpy.Context()
    rclpy.init(context=context, signal_handler_options=SignalHandlerOptions.NO)
    code = 0
    try:
        with tempfile.TemporaryDirectory(prefix='cbha_bench_bag_') as folder:
            bag = Path(folder) / 'bench'
            content = write_bag(bag, args.messages)
            for rate in (float(r) for r in args.rates.split(',')):
                received = play_and_receive(context, bag, rate, args.priority)
                if [d for _, d in received] != [d for _, d in content]:
                    print(f'rate {rate:g}: {len(received)} of {len(content)} messages arrived '
                          'in order')
                    code = 2
                    continue
                errors = np.abs(timing_errors([t for t, _ in received],
                                              [t for t, _ in content], rate)) * 1e3
                played = (received[-1][0] - received[0][0]) * 1e-9
                recorded = (content[-1][0] - content[0][0]) * 1e-9
                p99 = np.percentile(errors, 99)
                verdict = 'met' if p99 <= GOAL_P99_MS else 'MISSED'
                print(f'rate {rate:g}: {len(errors)} messages, timing error median '
                      f'{np.median(errors):.3f} ms, p99 {p99:.3f} ms, max {errors.max():.3f} ms;'
                      f' played {played:.4f} s for {recorded:.4f} s recorded (goal p99 <= '
                      f'{GOAL_P99_MS:g} ms: {verdict}, priority {args.priority})', flush=True)
    finally:
        rclpy.try_shutdown(context=context)
    return code


if __name__ == '__main__':
    sys.exit(main())
