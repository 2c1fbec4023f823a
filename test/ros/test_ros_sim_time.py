"""
``use_sim_time`` in every node: timers and stamps follow ``/clock``; watchdogs stay steady.

The test publishes ``/clock`` itself (no player: the clock is exactly what the test says), 1000 s
plus 10 ms steps (half a period of the nodes) each after 30 ms of spinning, so sim time runs at
most a third as fast as wall time (a loaded machine only slows the wall side further). Then it
stops the clock: the trajectory and the plant (sim-time timers) stop, while the closed-loop
solver's staleness watchdog (steady clock) sees the feedback go stale, turns to ``hold`` and keeps
commanding, flags the target stale, and diagnostics keep coming with the frozen sim stamp.
"""

import time

from cbha_inverse.ros.common.qos import COMMAND_QOS, DIAGNOSTICS_QOS, MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.ros.nodes.trajectory import TrajectoryNode
from cbha_inverse.scene import load_scene
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from ros_helpers import spin_for, spin_until
from rosgraph_msgs.msg import Clock
from std_msgs.msg import Float64MultiArray

SCENE = 'tendon_6f_8c'
CENTER = (0.117, 0.0, -0.005)
RATE = 50.0
START = 1000.0
STEP = 0.01


def _stamp(message):
    return message.header.stamp.sec + 1e-9 * message.header.stamp.nanosec


def _overrides(**values):
    return [Parameter(k, value=v) for k, v in {'use_sim_time': True, **values}.items()]


def test_nodes_follow_clock_and_watchdog_stays_steady(rclpy_context):
    """Targets, tips and timers on /clock; stale detection and diagnostics on wall time."""
    names = list(load_scene(SCENE).actuator_names)
    trajectory = TrajectoryNode(context=rclpy_context, namespace='/simtime',
                                parameter_overrides=_overrides(
                                    center=list(CENTER), radius=0.01, speed=0.02,
                                    rate_hz=RATE))
    solver = InverseSolverNode(context=rclpy_context, namespace='/simtime',
                               parameter_overrides=_overrides(
                                   scene=SCENE, valve_names=names, rate_hz=RATE, mode='closed',
                                   target_timeout=0.3, feedback_timeout=0.3,
                                   diagnostics_period=0.1))
    sim = CbhaSimNode(context=rclpy_context, namespace='/simtime', parameter_overrides=_overrides(
        scene=SCENE, valve_names=names, rate_hz=RATE, max_pressure=10.0))
    probe = Node('probe', context=rclpy_context, namespace='/simtime')
    clock = probe.create_publisher(Clock, '/clock', 10)
    targets, tips, commands, diagnostics = [], [], [], []
    probe.create_subscription(PointStamped, 'target', targets.append, TARGET_QOS)
    probe.create_subscription(PointStamped, 'tip/true', tips.append, MEASURED_QOS)
    probe.create_subscription(Float64MultiArray, 'pressure_command', lambda m: commands.append(
        time.monotonic()), COMMAND_QOS)
    probe.create_subscription(DiagnosticArray, '/diagnostics', lambda m: diagnostics.append(
        (time.monotonic(), _stamp(m), [s.name for s in m.status])), DIAGNOSTICS_QOS)
    executor = SingleThreadedExecutor(context=rclpy_context)
    nodes = (trajectory, solver, sim, probe)
    for node in nodes:
        executor.add_node(node)
    try:
        assert spin_until(executor, lambda: clock.get_subscription_count() >= 3
                          and trajectory.publisher.get_subscription_count() >= 2, 10.0)
        steps = 100
        wall = time.monotonic()
        for k in range(steps + 1):
            message = Clock()
            message.clock.sec, message.clock.nanosec = divmod(
                int(round((START + k * STEP) * 1e9)), 1_000_000_000)
            clock.publish(message)
            spin_for(executor, 0.03)
        wall = time.monotonic() - wall
        spin_for(executor, 0.1)  # the last /clock messages and what they trigger
        spin_until(executor, lambda: len(targets) >= trajectory.published, 2.0)
        end = START + steps * STEP
        stamps = np.array([_stamp(m) for m in targets])
        print(f'{steps * STEP:.2f} s of /clock in {wall:.2f} s of wall time: '
              f'{len(targets)} targets, {len(tips)} tips, {len(commands)} commands')
        # timers follow /clock: one target per 20 ms of sim time, whatever the wall time was
        # (an rcl timer skips a period when the clock jumps past two before it is checked)
        assert abs(len(targets) - steps * STEP * RATE) <= 0.05 * steps * STEP * RATE
        assert wall >= 3.0 * steps * STEP  # a wall-clock timer would have published 3x more
        assert np.all((stamps >= START) & (stamps <= end + 1e-9))
        assert np.all(np.diff(stamps) > 0)
        # the path is sampled at the sim time of each tick (first tick = elapsed 0)
        expected = trajectory.trajectory.sample(stamps - stamps[0])
        measured = np.array([(m.point.x, m.point.y, m.point.z) for m in targets])
        np.testing.assert_allclose(measured, expected.reshape(-1, 3), atol=1e-12)
        tip_stamps = np.array([_stamp(m) for m in tips])
        assert tips and np.all((tip_stamps >= START) & (tip_stamps <= end + 1e-9))
        assert commands and solver.decision == 'run'
        # /clock stops: no more targets or tips, but the watchdog (steady clock) holds
        published, measured = trajectory.published, len(tips)
        frozen = time.monotonic()
        assert spin_until(executor, lambda: solver.decision == 'hold', 3.0)
        held = time.monotonic()
        spin_for(executor, 0.3)
        assert trajectory.published == published and len(tips) == measured
        assert solver.target_stale
        assert sum(1 for t in commands if t > held) >= 5
        late = [d for d in diagnostics if d[0] > frozen and any(
            name.startswith('inverse_solver:') for name in d[2])]
        assert len(late) >= 3
        assert all(d[1] == pytest.approx(end, abs=1e-9) for d in late)
    finally:
        executor.shutdown()
        for node in nodes:
            node.destroy_node()
