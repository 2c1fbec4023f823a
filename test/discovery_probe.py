"""
How long a new process takes to discover a running publisher over DDS (not a test).

``python test/discovery_probe.py [runs]`` starts a publisher process (std_msgs/Float64 at 100 Hz)
and then, ``runs`` times (default 10) one after the other, a subscriber process that prints the
seconds from its node's creation to the publisher's discovery (``count_publishers``) and to the
first message. The environment is that of the test processes (``test/conftest.py``: localhost
discovery, UDPv4, the Fast DDS profile ``test/data/fastdds_discovery.xml`` unless
``FASTRTPS_DEFAULT_PROFILES_FILE`` names another); ``ROS_DOMAIN_ID`` defaults to 93. Results:
``docs/design.md``, "Tests".
"""

import os
from pathlib import Path
import statistics
import subprocess
import sys
import time

PROFILE = Path(__file__).resolve().parent / 'data' / 'fastdds_discovery.xml'


def environment():
    """Return the environment of a probe process (that of the test processes)."""
    env = dict(os.environ)
    env.setdefault('ROS_DOMAIN_ID', '93')
    env['ROS_AUTOMATIC_DISCOVERY_RANGE'] = 'LOCALHOST'
    env['FASTDDS_BUILTIN_TRANSPORTS'] = 'UDPv4'
    env.setdefault('FASTRTPS_DEFAULT_PROFILES_FILE', str(PROFILE))
    return env


def publish():
    """Publish ``x`` (std_msgs/Float64) at 100 Hz until killed."""
    import rclpy
    from std_msgs.msg import Float64
    rclpy.init()
    node = rclpy.create_node('discovery_publisher')
    publisher = node.create_publisher(Float64, 'x', 10)
    node.create_timer(0.01, lambda: publisher.publish(Float64(data=1.0)))
    rclpy.spin(node)


def subscribe():
    """Print ``<seconds to discovery> <seconds to the first message>`` of one new node."""
    import rclpy
    from std_msgs.msg import Float64
    rclpy.init()
    node = rclpy.create_node('discovery_subscriber')
    start = time.monotonic()
    received = []
    node.create_subscription(Float64, 'x', lambda message: received.append(time.monotonic()),
                             10)
    discovered = None
    while not received and time.monotonic() - start < 30.0:
        rclpy.spin_once(node, timeout_sec=0.01)
        if discovered is None and node.count_publishers('x'):
            discovered = time.monotonic()
    print(f'{(discovered or time.monotonic()) - start:.3f} '
          f'{(received[0] if received else time.monotonic()) - start:.3f}', flush=True)
    node.destroy_node()
    rclpy.shutdown()


def main(runs):
    """Run the publisher and ``runs`` subscribers; print each run, the mean, median and maximum."""
    env = environment()
    publisher = subprocess.Popen([sys.executable, __file__, 'publish'], env=env)
    try:
        time.sleep(2.0)
        firsts = []
        for _ in range(runs):
            out = subprocess.run([sys.executable, __file__, 'subscribe'], env=env,
                                 capture_output=True, text=True, timeout=60).stdout
            discovered, first = map(float, out.split()[-2:])
            firsts.append(first)
            print(f'discovered after {discovered:.3f} s, first message after {first:.3f} s')
        print(f'first message: mean {statistics.mean(firsts):.3f} s, '
              f'median {statistics.median(firsts):.3f} s, max {max(firsts):.3f} s '
              f'({env["FASTRTPS_DEFAULT_PROFILES_FILE"]})')
    finally:
        publisher.kill()
        publisher.wait()


if __name__ == '__main__':
    if sys.argv[1:2] == ['publish']:
        publish()
    elif sys.argv[1:2] == ['subscribe']:
        subscribe()
    else:
        main(int(sys.argv[1]) if len(sys.argv) > 1 else 10)
