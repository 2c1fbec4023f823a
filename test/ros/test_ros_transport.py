"""
The controller's DDS transport on one host: UDP on 127.0.0.1 alone, over real DDS.

A child process started with :func:`loopback_udp_environment` has no shared-memory transport
(Fast DDS names its receive threads by transport: ``dds.shm.*`` / ``dds.udp.*``) while one
started with the test environment has it, and this process (shared memory and UDP, the
``LOCALHOST`` range) still receives what the child publishes.
"""

import os
from pathlib import Path
import subprocess
import sys
import xml.etree.ElementTree as ElementTree

from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.common.transport import loopback_udp_environment, node_environment
from rclpy.node import Node
from ros_helpers import child_env, reaped, spin_until, spinning
from std_msgs.msg import Float64MultiArray

CHILD = """
import os, sys, time
import rclpy
from std_msgs.msg import Float64MultiArray
rclpy.init()
node = rclpy.create_node('transport_child')
publisher = node.create_publisher(Float64MultiArray, sys.argv[1], 10)
task = f'/proc/{os.getpid()}/task'
names = sorted({open(f'{task}/{t}/comm').read().strip() for t in os.listdir(task)})
print(' '.join(names), flush=True)
for _ in range(600):
    publisher.publish(Float64MultiArray(data=[1.0, 2.0]))
    time.sleep(0.01)
"""


def _thread_names(process):
    line = process.stdout.readline()
    assert line, 'the child printed nothing'
    return line.split()


def test_the_loopback_profile_is_udp_on_127_0_0_1_without_builtin_transports():
    env = loopback_udp_environment({'FASTDDS_BUILTIN_TRANSPORTS': 'UDPv4',
                                    'ROS_AUTOMATIC_DISCOVERY_RANGE': 'LOCALHOST'})
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SUBNET'
    assert 'FASTDDS_BUILTIN_TRANSPORTS' not in env
    namespace = {'d': 'http://www.eprosima.com/XMLSchemas/fastRTPS_Profiles'}
    root = ElementTree.parse(Path(env['FASTRTPS_DEFAULT_PROFILES_FILE'])).getroot()
    descriptor = root.find('.//d:transport_descriptor', namespace)
    assert descriptor.find('d:type', namespace).text == 'UDPv4'
    assert [a.text for a in descriptor.iterfind('.//d:address', namespace)] == ['127.0.0.1']
    assert root.find('.//d:useBuiltinTransports', namespace).text == 'false'


def test_node_environment_isolates_a_run_and_keeps_a_given_range():
    env = node_environment(7, {'_ROS_WHEELS_BOOTSTRAP_COMPLETE': '1', 'PATH': '/bin'})
    assert env['ROS_DOMAIN_ID'] == '7' and '_ROS_WHEELS_BOOTSTRAP_COMPLETE' not in env
    assert env['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'LOCALHOST' and env['PATH'] == '/bin'
    given = node_environment(None, {'ROS_AUTOMATIC_DISCOVERY_RANGE': 'SUBNET'})
    assert given['ROS_AUTOMATIC_DISCOVERY_RANGE'] == 'SUBNET' and 'ROS_DOMAIN_ID' not in given


def test_a_loopback_udp_process_has_no_shared_memory_and_is_heard(rclpy_context):
    topic = f'/transport_{os.getpid()}'
    udp = subprocess.Popen([sys.executable, '-c', CHILD, topic],
                           env=loopback_udp_environment(child_env()), stdout=subprocess.PIPE,
                           text=True)
    default = subprocess.Popen([sys.executable, '-c', CHILD, f'{topic}_default'],
                               env=child_env(), stdout=subprocess.PIPE, text=True)
    with reaped(udp, default):
        udp_threads, default_threads = _thread_names(udp), _thread_names(default)
        assert any(name.startswith('dds.udp') for name in udp_threads), udp_threads
        assert not any(name.startswith('dds.shm') for name in udp_threads), udp_threads
        # the test environment's range (LOCALHOST) gives shared memory whatever else is set
        assert any(name.startswith('dds.shm') for name in default_threads), default_threads
        probe = Node('transport_probe', context=rclpy_context)
        received = []
        probe.create_subscription(Float64MultiArray, topic, received.append, COMMAND_QOS)
        with spinning(rclpy_context, probe) as executor:
            assert spin_until(executor, lambda: len(received) >= 3, 20.0)
    assert list(received[-1].data) == [1.0, 2.0]
