"""
``cbha_bag play`` (a separate process, as a user runs it) into real subscribers over DDS.

The bag is written here with rosbags' ``Writer`` directly (not by ``cbha_bag``): ``/a``
(PointStamped, 80 messages at irregular 5-40 ms intervals), ``/b`` (Float64MultiArray, 10
messages). The tests check behaviour: every message, its bytes, its order, and that the recorded
schedule ``(t_k - t_0) / rate`` is followed: the playback speed, estimated robustly (the median of
the receive-time / bag-time slopes over half the bag, so a late start on a loaded machine followed
by a catch-up burst does not count), is ``rate`` within 5 %. The timing goal (error p99 <= 2 ms at
``--rate 1``) is measured by the ``cbha_bench_bag`` command, which prints the numbers; these tests
print theirs too (receive time = the middleware's ``received_timestamp``).
"""

import signal
import subprocess
import sys
import time

from cbha_inverse.bag.storage import open_bag
from cbha_inverse.report.bench_bag import timing_errors
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from rclpy.serialization import deserialize_message, serialize_message
from ros_helpers import child_env, REPO_ROOT, spin_until
from rosbags.interfaces import Qos, QosDurability, QosHistory, QosLiveliness, QosReliability
from rosbags.interfaces import QosTime
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import get_typestore, Stores
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

START_NS = 1_700_000_000_000_000_000
RELIABLE = Qos(QosHistory.KEEP_LAST, 10, QosReliability.RELIABLE, QosDurability.VOLATILE,
               QosTime(0, 0), QosTime(0, 0), QosLiveliness.AUTOMATIC, QosTime(0, 0), False)


@pytest.fixture(scope='module')
def bag(tmp_path_factory):
    """Write the test bag with rosbags' Writer; return (path, {topic: [(t_ns, bytes)]})."""
    path = tmp_path_factory.mktemp('play') / 'source'
    rng = np.random.default_rng(3)
    typestore = get_typestore(Stores.ROS2_JAZZY)
    content = {'/a': [], '/b': []}
    stamp = START_NS
    for k in range(80):
        message = PointStamped()
        message.header.stamp.sec = k
        message.point.x = float(k)
        content['/a'].append((stamp, bytes(serialize_message(message))))
        stamp += int(rng.uniform(5e6, 40e6))
    for k in range(10):
        message = Float64MultiArray(data=[float(k), 2.0 * k])
        content['/b'].append((START_NS + k * 150_000_000 + 1_000_000,
                              bytes(serialize_message(message))))
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        connections = {
            '/a': writer.add_connection('/a', 'geometry_msgs/msg/PointStamped',
                                        typestore=typestore, offered_qos_profiles=[RELIABLE]),
            '/b': writer.add_connection('/b', 'std_msgs/msg/Float64MultiArray',
                                        typestore=typestore, offered_qos_profiles=[RELIABLE])}
        for topic, t_ns, data in sorted((topic, t, d) for topic, items in content.items()
                                        for t, d in items):
            writer.write(connections[topic], t_ns, data)
    return path, content


class Listener:
    """Raw subscribers on the given topics, recording (middleware receive time [ns], bytes)."""

    def __init__(self, context, topics):
        self.node = Node('listener', context=context)
        self.received = {topic: [] for topic in topics}
        types = {'/clock': Clock, '/b': Float64MultiArray}
        for topic in topics:
            qos = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE)
            self.node.create_subscription(types.get(topic, PointStamped), topic,
                                          self._store(topic), qos, raw=True)
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(self.node)

    def _store(self, topic):
        def callback(data, info):
            # the middleware's receive time (system clock), not the executor's dispatch time
            self.received[topic].append((info['received_timestamp'], bytes(data)))
        return callback

    def spin_while_running(self, process, timeout=60.0):
        """Spin until the player exits, then 0.3 s more; return its exit code."""
        deadline = time.monotonic() + timeout
        while process.poll() is None and time.monotonic() < deadline:
            self.executor.spin_once(timeout_sec=0.005)
        drain = time.monotonic() + 0.3
        while time.monotonic() < drain:
            self.executor.spin_once(timeout_sec=0.005)
        return process.wait(timeout=10)

    def close(self):
        """Destroy the node."""
        self.executor.shutdown()
        self.node.destroy_node()


def _play(*args):
    return subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.bag.cli', 'play', *map(str, args)],
        cwd=REPO_ROOT, env=child_env(), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        text=True)


def _schedule(received, recorded, rate):
    """Return (|timing errors| [ms], playback speed [-]: bag time per received time)."""
    arrival = np.array([t for t, _ in received], dtype=float)
    schedule = np.array([t for t, _ in recorded], dtype=float)
    errors = timing_errors(arrival, schedule, rate)
    half = len(arrival) // 2
    speed = np.median((schedule[half:2 * half] - schedule[:half])
                      / (arrival[half:2 * half] - arrival[:half]))
    return np.abs(errors) * 1e3, float(speed)


def test_play_timing_at_rate_1_with_clock(rclpy_context, bag):
    """Every message, same bytes, the recorded schedule; /clock at 100 Hz of bag time."""
    path, content = bag
    listener = Listener(rclpy_context, ['/a', '/b', '/clock'])
    try:
        player = _play(path, '--clock', 100, '--wait-for-subscribers', 20)
        assert listener.spin_while_running(player) == 0, player.stdout.read()
    finally:
        listener.close()
    received = listener.received
    assert [d for _, d in received['/a']] == [d for _, d in content['/a']]
    assert [d for _, d in received['/b']] == [d for _, d in content['/b']]
    errors, speed = _schedule(received['/a'], content['/a'], 1.0)
    print(f'rate 1: playback speed {speed:.4f}, timing error median {np.median(errors):.3f} ms, '
          f'p99 {np.percentile(errors, 99):.3f} ms')
    assert speed == pytest.approx(1.0, rel=0.05)
    clocks = []
    for _, data in received['/clock']:
        message = deserialize_message(data, Clock)
        clocks.append(message.clock.sec * 1_000_000_000 + message.clock.nanosec)
    clocks = np.array(clocks)
    last = content['/a'][-1][0]
    assert clocks[0] == START_NS and clocks[-1] >= last
    steps = np.diff(clocks[:-1])
    assert np.all(steps == 10_000_000)  # 100 Hz of wall time = 10 ms of bag time at rate 1
    assert abs(len(clocks) - (last - START_NS) / 10_000_000) <= 3


def test_play_rate_2_topics_and_remap(rclpy_context, bag):
    """--rate 2 halves the duration; --topics /a plays only /a; --remap /a:=/c renames it."""
    path, content = bag
    listener = Listener(rclpy_context, ['/a', '/b', '/c'])
    try:
        player = _play(path, '--rate', 2, '--topics', '/a', '--remap', '/a:=/c',
                       '--wait-for-subscribers', 20)
        assert listener.spin_while_running(player) == 0, player.stdout.read()
    finally:
        listener.close()
    received = listener.received
    assert received['/a'] == [] and received['/b'] == []
    assert [d for _, d in received['/c']] == [d for _, d in content['/a']]
    errors, speed = _schedule(received['/c'], content['/a'], 2.0)
    print(f'rate 2: playback speed {speed:.4f} (half the recorded duration), timing error '
          f'median {np.median(errors):.3f} ms, p99 {np.percentile(errors, 99):.3f} ms')
    assert speed == pytest.approx(2.0, rel=0.05)


def test_play_loop_start_offset_and_qos_override(rclpy_context, bag, tmp_path):
    """--loop repeats from --start-offset until SIGINT; the override file sets the QoS."""
    path, content = bag
    overrides = tmp_path / 'qos.yaml'
    overrides.write_text('/a:\n  durability: transient_local\n  depth: 7\n')
    offset_ns = 500_000_000
    expected = [d for t, d in content['/a'] if t >= START_NS + offset_ns]
    listener = Listener(rclpy_context, ['/a', '/b'])
    try:
        player = _play(path, '--loop', '--start-offset', offset_ns * 1e-9,
                       '--qos-profile-overrides-path', overrides, '--wait-for-subscribers', 20)
        assert spin_until(listener.executor, lambda: len(listener.received['/a'])
                          >= 2 * len(expected) + 5, 30.0)
        (publisher,) = listener.node.get_publishers_info_by_topic('/a')
        assert publisher.qos_profile.durability == DurabilityPolicy.TRANSIENT_LOCAL
        assert publisher.qos_profile.reliability == ReliabilityPolicy.RELIABLE
        player.send_signal(signal.SIGINT)
        assert player.wait(timeout=10) == 0, player.stdout.read()
    finally:
        if player.poll() is None:
            player.kill()
        listener.close()
    data = [d for _, d in listener.received['/a']]
    assert data[:2 * len(expected)] == expected + expected
    assert data[2 * len(expected):] == expected[:len(data) - 2 * len(expected)]


def test_play_errors_are_one_line(tmp_path, bag):
    """A missing bag, an unknown topic or a broken override file: exit 2, one line."""
    path, _ = bag
    broken = tmp_path / 'qos.yaml'
    broken.write_text('/a:\n  reliability: sometimes\n')
    for args, words in [((tmp_path / 'nothing',), 'does not exist'),
                        ((path, '--topics', '/zzz'), "['/zzz'] are not in the bag"),
                        ((path, '--qos-profile-overrides-path', broken), '/a.reliability'),
                        ((path, '--remap', 'a=b'), 'old:=new')]:
        result = subprocess.run(
            [sys.executable, '-m', 'cbha_inverse.ros.bag.cli', 'play', *map(str, args)],
            cwd=REPO_ROOT, env=child_env(), capture_output=True, text=True, timeout=60)
        assert result.returncode == 2, result.stderr
        assert result.stderr.count('\n') == 1 and words in result.stderr, result.stderr
    with open_bag(path) as source:
        assert source.summary.message_count == 90


def test_play_sqlite3_metadata_v8_bag(rclpy_context, tmp_path):
    """An older layout (sqlite3 storage, metadata version 8) plays like an MCAP v9 bag."""
    path = tmp_path / 'sqlite3_v8'
    content = []
    with Writer(path, version=8, storage_plugin=StoragePlugin.SQLITE3) as writer:
        connection = writer.add_connection('/a', 'geometry_msgs/msg/PointStamped',
                                           typestore=get_typestore(Stores.ROS2_JAZZY),
                                           offered_qos_profiles=[RELIABLE])
        for k in range(20):
            message = PointStamped()
            message.point.z = 0.01 * k
            content.append((START_NS + k * 10_000_000, bytes(serialize_message(message))))
            writer.write(connection, *content[-1])
    with open_bag(path) as source:
        assert (source.summary.version, source.summary.storage_identifier) == (8, 'sqlite3')
    listener = Listener(rclpy_context, ['/a'])
    try:
        player = _play(path, '--wait-for-subscribers', 20)
        assert listener.spin_while_running(player) == 0, player.stdout.read()
    finally:
        listener.close()
    assert [d for _, d in listener.received['/a']] == [d for _, d in content]
