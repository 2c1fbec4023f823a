"""
``cbha_sim`` and a controller on another scene: one line and exit 2, not a flood of rejections.

A controller built for another scene publishes commands of another length at its tick rate,
every one of them wrong; a fuzzer's or a glitch's wrong lengths come one at a time among others.
"""

import time

from cbha_inverse.ros.common.qos import COMMAND_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from rclpy.node import Node
from ros_helpers import make_node, reaped, spin_for, spin_until, spinning, start_node
from std_msgs.msg import Float64MultiArray

TENDON_COMMAND = [1.0] * 8
"""A command of the tendon trunk's controller (8 tendons) [N]: the CBHA has 6 valves."""


def test_a_controller_on_another_scene_stops_the_sim_with_one_line(rclpy_context):
    process = start_node('cbha_inverse.ros.nodes.cbha_sim', '-p', 'scene:=cbha',
                         '-r', '__ns:=/cbha')
    client = Node('controller', context=rclpy_context, namespace='/cbha')
    publisher = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    with reaped(process), spinning(rclpy_context, client) as executor:
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 30.0)
        deadline = time.monotonic() + 20.0
        while process.poll() is None and time.monotonic() < deadline:
            publisher.publish(Float64MultiArray(data=TENDON_COMMAND))     # at 100 Hz
            spin_for(executor, 0.01)
        output = process.communicate(timeout=10.0)[0]
    lines = [line for line in output.splitlines() if 'pressure_command' in line]
    print('\n'.join(lines))
    assert process.returncode == 2, output
    assert len(lines) == 1, output
    assert 'have 8 values, expected 6' in lines[0] and 'different scenes' in lines[0]


def test_wrong_lengths_among_other_commands_are_rejected_one_by_one(rclpy_context):
    """Runs shorter than stop_after_wrong_length, or of mixed lengths, never stop the sim."""
    sim = make_node(CbhaSimNode, rclpy_context, scene='cbha', stop_after_wrong_length=5)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    publisher = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    sequence = ([[0.0] * 8] * 4 + [[0.0] * 6]            # four in a row, then a valid one
                + [[0.0] * 8, [0.0] * 7] * 3              # wrong, but of changing lengths
                + [[0.0] * 5, [float('nan')] * 6] * 3)    # wrong length, wrong values
    with spinning(rclpy_context, sim, client) as executor:
        assert spin_until(executor, lambda: publisher.get_subscription_count() > 0, 10.0)
        for k, data in enumerate(sequence):
            publisher.publish(Float64MultiArray(data=data))
            assert spin_until(executor, lambda: sim.accepted + sim.rejected.total > k, 5.0)
    assert sim.stopped is None
    assert sim.rejected == {'wrong_length': 4 + 6 + 3, 'non_finite': 3}
    assert sim.accepted == 1
