"""
``fault_relay`` over DDS: serialized messages of any type relayed with the link's faults.

The relay's output must be exactly what a :class:`FaultyLink` of the same faults and seed
delivers for the same input sequence (drops and duplicates fall on the same messages), each
message no earlier than ``delay`` after it was sent, for two message types and both QoS kinds.
"""

import time

from cbha_inverse.ros.common.params import ParameterError
from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS
from cbha_inverse.ros.nodes.fault_relay import FaultRelayNode
from cbha_inverse.sim.link import FaultyLink, LinkFaults
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.node import Node
from ros_helpers import make_node, spin_for, spin_until, spinning
from std_msgs.msg import Float64MultiArray


def test_the_relay_delivers_what_its_seeded_link_would(rclpy_context):
    n, seed, delay = 60, 7, 0.02
    faults = LinkFaults(drop=0.2, delay=delay, jitter=0.005, duplicate=0.2)
    relay = make_node(FaultRelayNode, rclpy_context, inputs=['a/wire', 'b/wire'],
                      outputs=['a', 'b'], qos=['sensor', 'reliable'],
                      types=['geometry_msgs/msg/PointStamped', 'std_msgs/msg/Float64MultiArray'],
                      drop=faults.drop, delay=delay, jitter=faults.jitter,
                      duplicate=faults.duplicate, seed=seed)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    # the sender publishes reliable so that every message reaches the relay
    point_pub = client.create_publisher(PointStamped, 'a/wire', COMMAND_QOS)
    array_pub = client.create_publisher(Float64MultiArray, 'b/wire', COMMAND_QOS)
    points, arrays, sent = [], [], {}
    client.create_subscription(PointStamped, 'a', lambda m: points.append(
        (int(m.point.x), time.monotonic())), MEASURED_QOS)
    client.create_subscription(Float64MultiArray, 'b', lambda m: arrays.append(
        (int(m.data[0]), time.monotonic())), COMMAND_QOS)
    with spinning(rclpy_context, relay, client) as executor:
        assert spin_until(executor, lambda: all(
            p.get_subscription_count() > 0 for p in (point_pub, array_pub)) and all(
            relay.count_subscribers(t) > 0 for t in ('/cbha/a', '/cbha/b')), 10.0)
        for i in range(n):
            message = PointStamped()
            message.point.x = float(i)
            sent[i] = time.monotonic()
            point_pub.publish(message)
            array_pub.publish(Float64MultiArray(data=[float(i), 0.5]))
            spin_for(executor, 0.005)
        assert spin_until(executor, lambda: relay.links[1][0].counts['sent'] == n
                          and not len(relay.links[1][0]) and not len(relay.links[0][0]), 5.0)
        spin_for(executor, 0.1)
    for index, received in ((0, points), (1, arrays)):
        reference = FaultyLink(faults, seed + index)
        for i in range(n):
            reference.send(i, 0.0)
        expected = reference.receive(np.inf)
        assert [i for i, _ in received] == expected
        assert relay.links[index][0].counts == reference.counts
        assert min(t - sent[i] for i, t in received) >= delay - faults.jitter
    assert 0 < len({i for i, _ in points}) < n          # the faults did act
    assert len(points) > len({i for i, _ in points})


@pytest.mark.untimed
@pytest.mark.parametrize('bad, match', [
    ({'inputs': ['a'], 'outputs': ['b', 'c'], 'types': ['std_msgs/msg/Empty']}, 'same length'),
    ({'inputs': ['a'], 'outputs': ['b'], 'types': ['no_msgs/msg/Nothing']}, 'not installed'),
    ({'inputs': ['a'], 'outputs': ['b'], 'types': ['std_msgs/msg/Empty'], 'qos': ['fast']},
     'qos'),
])
def test_bad_tables_are_refused(rclpy_context, bad, match):
    with pytest.raises(ParameterError, match=match):
        make_node(FaultRelayNode, rclpy_context, **bad)
