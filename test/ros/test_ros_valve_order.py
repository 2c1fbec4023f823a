"""
``valve_names`` over real DDS: each command entry and each plant pressure goes to the named valve.

``inverse_solver`` and ``cbha_sim`` run with a permuted ``valve_names`` (a cyclic shift, not its
own inverse, so that a permutation applied the wrong way round fails): the command is the
independent core solver's actuation in that order, and the plant's tip is the scene's static
equilibrium of the named tubes' pressures.
"""

import time

from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode, InverseSolverParams
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped
import numpy as np
from rclpy.node import Node
from ros_helpers import make_node, sim_plant_scene, spin_for, spin_until, spinning, target_point
from std_msgs.msg import Float64MultiArray

CBHA = 'cbha'
MAX_PRESSURE = InverseSolverParams.max_pressure
"""The solver node's command ceiling [Pa] (its default, 1.5 bar)."""


def _shifted(names):
    """Return the names cyclically shifted by one (a permutation that is not an involution)."""
    names = list(names)
    return names[1:] + names[:1]


def test_solver_commands_follow_a_permuted_valve_order(rclpy_context):
    """
    The first command after a target = the core solver's first tick, entry i = valve_names[i].

    ``rate_hz`` 1 keeps the timer from ticking the solver during the test, so exactly one tick
    (the one the target triggers) is compared with an independent solver of the same scene.
    """
    scene = load_scene(CBHA)
    names = list(scene.actuator_names)
    valve_names = _shifted(names)
    target = scene.workspace_center[-1] + np.array([0.0, 0.02, 0.01])
    reference = scene.make_inverse_solver()
    reference.warm_up()
    actuation = reference.step(target[None]).actuation
    expected = np.clip(actuation, 0.0, MAX_PRESSURE)[[names.index(n) for n in valve_names]]
    # the permutation matters for this target: scene order differs from valve order by > 1 kPa
    assert np.abs(expected - np.clip(actuation, 0.0, MAX_PRESSURE)).max() > 1e3

    solver = make_node(InverseSolverNode, rclpy_context, scene=CBHA, valve_names=valve_names,
                       rate_hz=1.0)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    commands = []
    client.create_subscription(Float64MultiArray, 'pressure_command', commands.append,
                               COMMAND_QOS)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and client.count_publishers('/cbha/pressure_command') > 0, 10.0)
        spin_for(executor, 0.1)
        before = len(commands)
        target_pub.publish(target_point(target))
        assert spin_until(executor, lambda: solver.ticks >= 1 and len(commands) > before, 10.0)
        spin_until(executor, lambda: any(np.any(np.asarray(c.data) > 0.0)
                                         for c in commands[before:]), 2.0)
    assert solver.ticks == 1
    solved = [c for c in commands[before:] if np.any(np.asarray(c.data) > 0.0)]
    assert solved, 'no solved command received'
    assert solved[0].layout.dim[0].label == ','.join(valve_names)
    np.testing.assert_allclose(solved[0].data, expected, rtol=1e-9, atol=1e-6)


def test_simulator_applies_each_pressure_to_the_named_tube(rclpy_context):
    """cbha_sim with permuted valve_names: the tip is the equilibrium of the named tubes' load."""
    plant_scene = sim_plant_scene(CBHA)
    names = list(plant_scene.actuator_names)
    valve_names = _shifted(names)
    command = np.zeros(len(names))
    command[valve_names.index('outer_left')] = 1.2e5
    command[valve_names.index('inner_over')] = 0.4e5
    in_scene_order = np.zeros(len(names))
    in_scene_order[names.index('outer_left')] = 1.2e5
    in_scene_order[names.index('inner_over')] = 0.4e5
    expected = plant_scene.forward(in_scene_order).effector_positions[-1]
    unpermuted = plant_scene.forward(command).effector_positions[-1]
    assert np.linalg.norm(expected - unpermuted) > 5e-3  # the order decides the tip by > 5 mm

    sim = make_node(CbhaSimNode, rclpy_context, scene=CBHA, valve_names=valve_names,
                    noise_std=0.0, tolerance=1e-9)
    client = Node('client', context=rclpy_context, namespace='/cbha')
    command_pub = client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)
    tips = []
    client.create_subscription(PointStamped, 'tip/true', lambda m: tips.append(
        (time.monotonic(), [m.point.x, m.point.y, m.point.z])), MEASURED_QOS)
    with spinning(rclpy_context, sim, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and len(tips) > 0, 10.0)
        command_pub.publish(Float64MultiArray(data=[float(v) for v in command]))
        sent = time.monotonic()
        # 10 ms valves: after 0.4 s the pressures are within exp(-37) of the set-points
        assert spin_until(executor, lambda: tips[-1][0] > sent + 0.4, 10.0)
    assert sim.accepted == 1
    np.testing.assert_allclose(tips[-1][1], expected, atol=1e-6)
