"""
The controller and the simulated robot over real DDS (in one process, one executor).

The closed loop runs the CBHA scene (6 cavities, ~1.5 ms per tick); the fuzz and staleness tests
use the paper's tendon trunk (``tendon_6f_8c``, ~1 ms per tick) where the CBHA is not essential.
The plant is the scene 10 % softer (``stiffness_scale`` 0.9), with valve lag (10 ms), transport
latency (3 ms) and 0.2 mm measurement noise.
"""

import time

from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS, TARGET_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode, CbhaSimParams
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.ros.nodes.trajectory import TrajectoryNode
from cbha_inverse.scene import load_scene
from geometry_msgs.msg import PointStamped
import numpy as np
import pytest
from rclpy.node import Node
from ros_helpers import (
    loop_lag_error, make_node, record_tracking, spin_for, spin_until, spinning, target_point)
from std_msgs.msg import Float64MultiArray

SCENE = 'tendon_6f_8c'
MAX_TENSION = 10.0
"""The tendon trunk's cable tension ceiling [N] (its scene's upper bounds), as max_pressure."""
CENTER = (0.117, 0.0, -0.005)
"""A tip position well in the tendon trunk's reach (near its workspace centre) [m]."""
RATE = 50.0
"""Rate of trajectory, solver and plant in the closed loop [Hz]."""


def _names():
    return list(load_scene(SCENE).actuator_names)


def _solver(context, namespace='/cbha', **overrides):
    params = {'scene': SCENE, 'valve_names': _names(), 'rate_hz': RATE, **overrides}
    return make_node(InverseSolverNode, context, namespace, **params)


def _sim(context, namespace='/cbha', **overrides):
    params = {'scene': SCENE, 'valve_names': _names(), 'rate_hz': RATE,
              'max_pressure': MAX_TENSION, **overrides}
    return make_node(CbhaSimNode, context, namespace, **params)


def _command_client(context):
    """Return a client node, its target publisher and the (time, command) list it records."""
    client = Node('client', context=context, namespace='/cbha')
    target_pub = client.create_publisher(PointStamped, 'target', TARGET_QOS)
    commands = []
    client.create_subscription(Float64MultiArray, 'pressure_command', lambda m: commands.append(
        (time.monotonic(), np.array(m.data))), COMMAND_QOS)
    return client, target_pub, commands


def _tracking_rms(context, mode, duration, hold=1.5, settle=1.0):
    """
    Run trajectory + solver + sim on the CBHA scene (paper circle, 50 Hz).

    Returns the RMS and max tip error [m] from ``hold + settle`` seconds after the start.
    """
    scene = load_scene('cbha')
    center = scene.workspace_center[-1]
    names = list(scene.actuator_names)
    trajectory = make_node(TrajectoryNode, context, center=[float(v) for v in center],
                           rate_hz=RATE, start_hold=hold, wait_for_subscribers=2)
    solver = _solver(context, scene='cbha', valve_names=names, mode=mode, loop_gain=0.1)
    sim = _sim(context, scene='cbha', valve_names=names, max_pressure=CbhaSimParams.max_pressure)
    errors = record_tracking(context, [trajectory, solver, sim], duration, hold, settle, RATE)
    return errors.rms, errors.maximum


def test_closed_loop_tracks_circle_segment_below_bound(rclpy_context):
    """
    CBHA, paper circle (r 60 mm, 2.5 cm/s), 10 % softer plant: closed loop beats the lag bound.

    Segment: 1.5 s at the start point, then 6 s (15 cm) of the circle, scored after 1.5 s of
    motion. The integral correction removes the model error (the open loop here is ~6 mm off
    and must be at least 3x worse; it has no integral to settle and its error, the softer
    plant's sag, is about the same along the whole circle, so its run holds the start point
    0.5 s, settles 0.5 s and is scored for 2 s: 5 cm of the circle). What no feedback of this
    structure can remove is the loop lag: valve 10 ms + latency 3 ms + one plant tick and one
    control tick (20 ms each at 50 Hz) = 53 ms, i.e. ``speed * lag`` = 1.3 mm of error along the
    path. The bound is that lag error: the loop must compensate the model error completely and
    not add to the lag (measured here 0.45-0.6 mm, open loop 7.8 mm; the demo at 100 Hz in
    separate processes gives ~0.5 mm).
    """
    bound = loop_lag_error(RATE)
    closed_rms, closed_max = _tracking_rms(rclpy_context, 'closed', 7.5, settle=1.5)
    open_rms, _ = _tracking_rms(rclpy_context, 'open', 3.0, hold=0.5, settle=0.5)
    print(f'closed loop RMS {closed_rms * 1e3:.3f} mm (max {closed_max * 1e3:.3f}), '
          f'open loop RMS {open_rms * 1e3:.3f} mm, bound {bound * 1e3:.3f} mm')
    assert closed_rms < bound
    assert open_rms > 3.0 * closed_rms


def _bad_points(rng, count):
    """Yield NaN/inf/huge/wrong-frame points."""
    bad = [np.nan, np.inf, -np.inf, 1e300, -1e6, 5.0]
    for i in range(count):
        point = list(CENTER)
        kind = i % 4
        if kind == 3:
            yield target_point(point, frame_id=['', 'world', 'cbha_base ', 'map'][rng.integers(4)])
            continue
        point[rng.integers(3)] = bad[rng.integers(len(bad))]
        if kind == 2:
            point = [bad[rng.integers(len(bad))] for _ in range(3)]
        yield target_point(point)


def _bad_commands(rng, count, n_valves):
    """Yield wrong-length, non-finite, negative and too-high commands."""
    for i in range(count):
        kind = i % 4
        if kind == 0:
            length = int(rng.choice([0, 1, n_valves - 1, n_valves + 1, 8 * n_valves]))
            data = rng.uniform(0.0, 1.0, length)
        else:
            data = rng.uniform(0.0, MAX_TENSION, n_valves)
            data[rng.integers(n_valves)] = [np.nan, np.inf, -np.inf, -1.0, 1e308,
                                            MAX_TENSION * 1.01][rng.integers(6)]
        yield Float64MultiArray(data=[float(v) for v in data])


def _count(node, prefix):
    return sum(v for k, v in node.rejected.items() if k.startswith(prefix))


def test_fuzzed_inputs_never_produce_bad_commands(rclpy_context):
    """
    2,600 bad messages on each subscribed topic of both nodes; commands stay finite and bounded.

    The solver runs in /cbha (target, tip/measured), the fuzzed simulator in /fuzz
    (pressure_command) so that the monitor of /cbha/pressure_command sees only the solver.
    """
    count = 2600
    rng = np.random.default_rng(7)
    solver = _solver(rclpy_context, max_pressure=MAX_TENSION)
    sim = _sim(rclpy_context, namespace='/fuzz')
    fuzzer = Node('fuzzer', context=rclpy_context)
    target_pub = fuzzer.create_publisher(PointStamped, '/cbha/target', TARGET_QOS)
    measured_pub = fuzzer.create_publisher(PointStamped, '/cbha/tip/measured', MEASURED_QOS)
    command_pub = fuzzer.create_publisher(Float64MultiArray, '/fuzz/pressure_command',
                                          COMMAND_QOS)
    commands, tips = [], []
    fuzzer.create_subscription(Float64MultiArray, '/cbha/pressure_command',
                               lambda m: commands.append(np.array(m.data)), COMMAND_QOS)
    fuzzer.create_subscription(PointStamped, '/fuzz/tip/measured', lambda m: tips.append(
        (m.point.x, m.point.y, m.point.z)), MEASURED_QOS)
    with spinning(rclpy_context, solver, sim, fuzzer) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and command_pub.get_subscription_count() > 0
                          and measured_pub.get_subscription_count() > 0, 10.0)
        streams = zip(_bad_points(rng, count), _bad_points(rng, count),
                      _bad_commands(rng, count, len(_names())))
        for i, (target, measured, command) in enumerate(streams):
            target_pub.publish(target)
            measured_pub.publish(measured)
            command_pub.publish(command)
            if i % 20 == 0:
                target_pub.publish(target_point((CENTER[0], 0.005 * np.cos(i), 0.005 * np.sin(i))))
            if i % 5 == 4:  # pace: reliable KEEP_LAST(10) would drop a burst
                spin_until(executor, lambda: _count(solver, 'target.') > i
                           and sum(sim.rejected.values()) > i, 2.0)
        spin_until(executor, lambda: sum(sim.rejected.values()) >= count, 20.0)
        spin_for(executor, 0.3)
        published_during_fuzz = len(commands)
        target_pub.publish(target_point(CENTER))
        assert spin_until(executor, lambda: len(commands) > published_during_fuzz + 2, 5.0)
    rejected_targets = _count(solver, 'target.')
    rejected_measured = _count(solver, 'tip/measured.')
    print(f'rejected: solver {solver.rejected}, sim {sim.rejected}; {len(commands)} commands')
    assert rejected_targets == count
    assert rejected_measured >= 2000  # best effort (sensor QoS): a burst may drop a few
    assert sum(sim.rejected.values()) == count
    assert len(commands) > count // 20
    data = np.array(commands)
    assert np.all(np.isfinite(data)) and np.all(data >= 0.0) and np.all(data <= MAX_TENSION)
    assert np.all(np.isfinite(tips)) and len(tips) > 0
    assert np.all(sim.pressures <= MAX_TENSION) and np.all(sim.pressures >= 0.0)


@pytest.mark.parametrize('publish_idle', [False, True])
def test_no_command_before_the_first_target(rclpy_context, publish_idle):
    """Without a target nothing is published (publish_idle: the vent command at rate_hz)."""
    vent = 1.0
    solver = _solver(rclpy_context, max_pressure=MAX_TENSION, publish_idle=publish_idle,
                     vent_pressure=vent, rate_hz=100.0)
    client, target_pub, commands = _command_client(rclpy_context)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and solver.command_publisher.get_subscription_count() > 0, 10.0)
        spin_for(executor, 0.5)
        before_target = list(commands)
        target_pub.publish(target_point(CENTER))
        assert spin_until(executor, lambda: solver.ticks > 0
                          and len(commands) > len(before_target), 5.0)
    assert solver.decision == 'run'
    if publish_idle:
        assert len(before_target) >= 10
        assert all(np.allclose(c, vent) for _, c in before_target)
    else:
        assert before_target == []
        assert solver.ticks > 0


def test_target_sent_once_is_solved_until_the_model_reaches_it(rclpy_context):
    """One target, sent once: it stays the set-point past target_timeout; the model reaches it."""
    timeout = 0.2
    solver = _solver(rclpy_context, max_pressure=MAX_TENSION, target_timeout=timeout,
                     rate_hz=100.0)
    client, target_pub, commands = _command_client(rclpy_context)
    target = np.array([CENTER[0], 0.004, -0.008])

    def model_error():
        return float(np.linalg.norm(solver.solver.effector_positions()[0] - target))

    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0, 10.0)
        target_pub.publish(target_point(target))
        sent = time.monotonic()
        assert spin_until(executor, lambda: time.monotonic() > sent + 2.0 * timeout
                          and model_error() <= 1e-4, 10.0), f'model error {model_error()} m'
        ticks = solver.ticks
        spin_for(executor, 0.3)
    print(f'model {model_error() * 1e3:.4f} mm from the target after {ticks} ticks')
    assert solver.decision == 'run' and solver.target_stale
    assert solver.ticks > ticks, 'the solver stopped ticking at a stale target'
    late = [c for t, c in commands if t > sent + 2.0 * timeout]
    assert len(late) >= 5, 'commands stopped at a stale target'
    assert np.all(np.isfinite(late)) and np.all(np.asarray(late) <= MAX_TENSION)


def test_stale_feedback_in_closed_loop_vents_within_timeout(rclpy_context):
    timeout = 0.2
    vent = 1.0
    solver = _solver(rclpy_context, max_pressure=MAX_TENSION, mode='closed',
                     feedback_timeout=timeout, stale_action='vent', vent_pressure=vent,
                     rate_hz=100.0)
    client, target_pub, commands = _command_client(rclpy_context)
    measured_pub = client.create_publisher(PointStamped, 'tip/measured', MEASURED_QOS)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0
                          and measured_pub.get_subscription_count() > 0, 10.0)
        last_measured = None
        start = time.monotonic()
        while time.monotonic() < start + 1.0:
            target_pub.publish(target_point((CENTER[0], 0.005, 0.0)))
            if time.monotonic() < start + 0.5:
                measured_pub.publish(target_point(CENTER))
                last_measured = time.monotonic()
            spin_for(executor, 0.01)
    assert solver.decision == 'vent'
    running = [c for t, c in commands if t < last_measured]
    assert running and not np.allclose(running[-1], vent)
    first_vent = next(t for t, c in commands if t > last_measured and np.allclose(c, vent))
    assert first_vent - last_measured < timeout + 0.1
    assert all(np.allclose(c, vent) for t, c in commands if t > first_vent)


def test_solver_publishes_backbone_markers_and_diagnostics(rclpy_context):
    from diagnostic_msgs.msg import DiagnosticArray
    from visualization_msgs.msg import Marker, MarkerArray

    solver = _solver(rclpy_context, max_pressure=MAX_TENSION, diagnostics_period=0.2)
    client, target_pub, _ = _command_client(rclpy_context)
    markers, diagnostics = [], []
    client.create_subscription(MarkerArray, 'backbone', markers.append, 1)
    client.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    with spinning(rclpy_context, solver, client) as executor:
        assert spin_until(executor, lambda: target_pub.get_subscription_count() > 0, 10.0)
        target_pub.publish(target_point(CENTER))
        target_pub.publish(target_point((float('nan'), 0.0, 0.0)))
        assert spin_until(executor, lambda: solver.ticks > 0 and markers and any(
            s.name == 'inverse_solver: inputs' and any(
                v.key == 'rejected.target.non_finite' for v in s.values)
            for d in diagnostics for s in d.status), 10.0)
    line = markers[-1].markers[0]
    assert line.type == Marker.LINE_STRIP and line.header.frame_id == 'cbha_base'
    assert len(line.points) == solver.scene.model.n_frames and line.color.a == 1.0
    control = next(s for d in diagnostics for s in d.status
                   if s.name == 'inverse_solver: control')
    keys = {v.key for v in control.values}
    assert {'tick_median_ms', 'tick_p99_ms', 'latency_p99_ms', 'residual_norm', 'qp_status',
            'saturated', 'last_status'} <= keys
