"""
``robotino_bridge`` over real DDS with the driver's messages built here (robotino_msgs, colcon).

The session fixture ``robotino_msgs`` builds the shipped interface package once. A driver
stand-in (``robotino_helpers.DriverStandIn``) takes ``/set_bha_pressures`` and publishes
``/bha_readings`` as ``robotino_node`` does. Expected set-points are written out by hand from the
driver's channel table (0-2 inner section over/right/left, 3-5 outer section, 6-7 wrist), not
computed with the mapping under test.
"""

import subprocess
import sys
import time

from cbha_inverse.robot.robotino import PASCAL_PER_BAR
from cbha_inverse.ros.common.params import ParameterError
from cbha_inverse.ros.common.qos import COMMAND_QOS, MEASURED_QOS
from cbha_inverse.ros.nodes.cbha_sim import CbhaSimNode
from cbha_inverse.ros.nodes.inverse_solver import InverseSolverNode
from cbha_inverse.ros.nodes.robotino_bridge import RobotinoBridgeNode, RobotinoBridgeParams
from cbha_inverse.ros.nodes.trajectory import TrajectoryNode
from cbha_inverse.scene import load_scene
from diagnostic_msgs.msg import DiagnosticArray
import numpy as np
import pytest
from rclpy.node import Node
from rclpy.parameter import Parameter
from robotino_helpers import DriverStandIn, robotino_child_env
from ros_helpers import (
    child_env, hiding_env, loop_lag_error, make_node, record_tracking, REPO_ROOT, spin_for,
    spin_until, spinning)
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
import yaml

PERMUTED = ('outer_left', 'inner_over', 'outer_over', 'inner_left', 'inner_right', 'outer_right')
"""A valve order other than the vendor's: channels 5, 0, 3, 2, 1, 4."""

MAX_PRESSURE = RobotinoBridgeParams.max_pressure
"""The bridge's default ceiling of a forwarded command [Pa] (1.5 bar)."""

SHIPPED = yaml.safe_load((REPO_ROOT / 'config' / 'robotino_bridge.yaml').read_text())['/**'][
    'ros__parameters']
"""The parameters of the shipped params file."""

LOOP_RATE = 50.0
"""Rate of trajectory, solver and plant in the closed-loop comparison [Hz]."""

BRIDGE_RMS_MARGIN = 0.35e-3
"""How much more RMS tip error [m] the bridged loop may show than the direct one (run noise)."""


def _bridge(context, namespace='/cbha', **overrides):
    overrides.setdefault('command_timeout', 30.0)
    return make_node(RobotinoBridgeNode, context, namespace, **overrides)


def _client(context):
    client = Node('client', context=context, namespace='/cbha')
    return client, client.create_publisher(Float64MultiArray, 'pressure_command', COMMAND_QOS)


def _command(values):
    return Float64MultiArray(data=[float(v) for v in values])


def _commanded(driver):
    """Return the set-points the driver received (nothing comes before the first command)."""
    return [values for _, values in driver.received]


def test_commands_reach_all_eight_channels_in_bar_with_wrist_and_cap(rclpy_context,
                                                                     robotino_msgs):
    bridge = _bridge(rclpy_context, valve_names=list(PERMUTED), wrist_bar=[0.25, 0.75],
                     max_bar=1.2)
    driver = DriverStandIn(rclpy_context)
    client, command_pub = _client(rclpy_context)
    with spinning(rclpy_context, bridge, driver, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and bridge.driver_publisher.get_subscription_count() > 0, 10.0)
        # outer_left, inner_over, outer_over, inner_left, inner_right, outer_right [Pa]
        command_pub.publish(_command([6e4, 1e4, 4e4, 3e4, 2e4, 1.5e5]))
        assert spin_until(executor, lambda: len(_commanded(driver)) == 1, 5.0)
        spin_for(executor, 0.1)
    # channels: inner over/right/left, outer over/right/left, wrist horizontal/vertical [bar];
    # outer_right asks 1.5 bar and is capped at max_bar = 1.2
    expected = [0.1, 0.2, 0.3, 0.4, 1.2, 0.6, 0.25, 0.75]
    assert len(_commanded(driver)) == 1
    np.testing.assert_allclose(_commanded(driver)[0], expected, rtol=1e-6)
    assert driver.ignored == 0 and bridge.forwarded == 1


def test_bad_commands_are_never_forwarded_and_are_counted(rclpy_context, robotino_msgs):
    bridge = _bridge(rclpy_context)
    driver = DriverStandIn(rclpy_context)
    client, command_pub = _client(rclpy_context)
    good = [[1e4, 2e4, 3e4, 4e4, 5e4, 6e4], [6e4, 5e4, 4e4, 3e4, 2e4, 1e4]]
    bad = {'non_finite': [[np.nan, 0, 0, 0, 0, 0], [0, 0, np.inf, 0, 0, 0],
                          [0, 0, 0, 0, 0, -np.inf]],
           'wrong_length': [[], [1e4] * 5, [1e4] * 7, [1e4] * 8],
           'out_of_range': [[-1.0, 0, 0, 0, 0, 0], [0, 0, 0, MAX_PRESSURE + 1.0, 0, 0],
                            [1e308] * 6]}
    with spinning(rclpy_context, bridge, driver, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and bridge.driver_publisher.get_subscription_count() > 0, 10.0)
        command_pub.publish(_command(good[0]))
        assert spin_until(executor, lambda: len(_commanded(driver)) == 1, 5.0)
        count = 0
        for values in (v for group in bad.values() for v in group):
            command_pub.publish(_command(values))
            count += 1
            assert spin_until(executor, lambda: sum(bridge.rejected.values()) == count, 5.0)
        command_pub.publish(_command(good[1]))
        assert spin_until(executor, lambda: len(_commanded(driver)) == 2, 5.0)
        spin_for(executor, 0.1)
    assert bridge.rejected == {reason: len(group) for reason, group in bad.items()}
    sent = np.array(_commanded(driver))
    assert sent.shape == (2, 8)
    np.testing.assert_allclose(sent[:, :6], np.array(good) / PASCAL_PER_BAR, rtol=1e-6)
    assert np.all(sent[:, 6:] == 0.0) and driver.ignored == 0


@pytest.mark.parametrize('action', ['vent', 'hold'])
def test_stale_command_stream_vents_or_holds_within_the_timeout(rclpy_context, robotino_msgs,
                                                                action):
    timeout = 0.2
    bridge = _bridge(rclpy_context, command_timeout=timeout, stale_action=action,
                     vent_pressure=2e4, wrist_bar=[0.5, 0.5], rate_hz=100.0)
    driver = DriverStandIn(rclpy_context)
    client, command_pub = _client(rclpy_context)
    command = [1e4, 3e4, 5e4, 7e4, 9e4, 1.1e5]
    with spinning(rclpy_context, bridge, driver, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and bridge.driver_publisher.get_subscription_count() > 0, 10.0)
        end = time.monotonic() + 0.4
        while time.monotonic() < end:
            command_pub.publish(_command(command))
            spin_for(executor, 0.02)
        last_command = time.monotonic()
        spin_for(executor, timeout + 0.3)
    assert bridge.decision == action
    running = [values for t, values in driver.received if t < last_command]
    assert running
    np.testing.assert_allclose(running[-1], [0.1, 0.3, 0.5, 0.7, 0.9, 1.1, 0.5, 0.5], rtol=1e-6)
    stale = [(t, values) for t, values in driver.received if t > last_command + timeout + 0.1]
    assert len(stale) >= 5, 'no set-points republished while stale'
    # vent: arm channels at vent_pressure (0.2 bar), wrist at 0; hold: the last set-points
    expected = [0.2] * 6 + [0.0] * 2 if action == 'vent' else running[-1]
    for _, values in stale:
        np.testing.assert_allclose(values, expected, rtol=1e-6)
    if action == 'vent':
        first = next(t for t, values in driver.received
                     if t > last_command and np.allclose(values, expected))
        assert first - last_command < timeout + 0.1


@pytest.mark.parametrize('publish_idle', [False, True])
def test_before_the_first_command_nothing_or_the_vent_set_points(rclpy_context, robotino_msgs,
                                                                 publish_idle):
    bridge = _bridge(rclpy_context, command_timeout=0.05, rate_hz=100.0, vent_pressure=1e4,
                     publish_idle=publish_idle)
    driver = DriverStandIn(rclpy_context)
    with spinning(rclpy_context, bridge, driver) as executor:
        assert spin_until(executor, lambda: bridge.driver_publisher.get_subscription_count() > 0,
                          10.0)
        spin_for(executor, 0.3)
    assert bridge.decision == 'waiting'
    if publish_idle:
        assert len(driver.received) >= 5
        for _, values in driver.received:
            np.testing.assert_allclose(values, [0.1] * 6 + [0.0] * 2, rtol=1e-6)
    else:
        assert driver.received == []


def test_readings_become_pressure_measured_in_pascal_and_string_pots(rclpy_context,
                                                                     robotino_msgs):
    bridge = _bridge(rclpy_context, valve_names=list(PERMUTED), diagnostics_period=0.1)
    driver = DriverStandIn(rclpy_context)
    client, command_pub = _client(rclpy_context)
    measured, pots, diagnostics = [], [], []
    client.create_subscription(Float64MultiArray, 'pressure_measured', measured.append,
                               MEASURED_QOS)
    client.create_subscription(JointState, 'string_pots', pots.append, MEASURED_QOS)
    client.create_subscription(DiagnosticArray, '/diagnostics', diagnostics.append, 10)
    channel_bar = [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7, 0.8]
    cablepull = [101.0, 102.0, 103.0, 195.0, 196.0, 197.0]
    with spinning(rclpy_context, bridge, driver, client) as executor:
        assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0
                          and driver.readings_publisher.get_subscription_count() > 0, 10.0)
        command_pub.publish(_command([5e4, 1e4, 4e4, 3e4, 2e4, 6e4]))
        assert spin_until(executor, lambda: len(_commanded(driver)) == 1, 5.0)
        driver.publish_readings([0.1, 0.2], cablepull)  # too few channels: rejected
        driver.publish_readings([np.nan] + channel_bar[1:], cablepull)  # rejected
        assert spin_until(executor, lambda: sum(bridge.rejected.values()) == 2, 5.0)
        sent = driver.publish_readings(channel_bar, cablepull)
        assert spin_until(executor, lambda: measured and pots, 5.0)
        assert spin_until(executor, lambda: any(
            v.key == 'measured_minus_commanded_pa.outer_left'
            for d in diagnostics for s in d.status for v in s.values), 5.0)
    assert len(measured) == 1 and len(pots) == 1
    # PERMUTED reads channels 5, 0, 3, 2, 1, 4 [bar] -> Pa
    np.testing.assert_allclose(measured[0].data, [6e4, 1e4, 4e4, 3e4, 2e4, 5e4], rtol=1e-6)
    assert measured[0].layout.dim[0].label == ','.join(PERMUTED)
    assert pots[0].header.stamp == sent.stamp and pots[0].header.frame_id == 'cbha_base'
    np.testing.assert_allclose(pots[0].position, cablepull, rtol=1e-6)
    assert pots[0].name[0] == 'string_pot_inner_over' and len(pots[0].name) == 6
    assert bridge.rejected == {'readings.wrong_length': 1, 'readings.non_finite': 1}
    values = {v.key: v.value for d in diagnostics for s in d.status for v in s.values}
    # commanded outer_left 0.5 bar, measured channel 5 = 0.6 bar -> +1e4 Pa
    assert float(values['measured_minus_commanded_pa.outer_left']) == pytest.approx(1e4, rel=1e-5)
    assert float(values['measured_minus_commanded_pa.inner_over']) == pytest.approx(0.0, abs=1.0)
    assert {'command_rate_hz', 'reading_rate_hz', 'reading_age_s', 'rejected_total'} <= set(values)


def test_bridge_process_from_the_params_file_with_the_built_messages(rclpy_context,
                                                                     robotino_msgs):
    """The user's path: ``install/setup.sh`` environment, ``config/robotino_bridge.yaml``."""
    process = subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.nodes.robotino_bridge', '--ros-args',
         '--params-file', str(REPO_ROOT / 'config' / 'robotino_bridge.yaml'),
         '-r', '__ns:=/cbha'], cwd=REPO_ROOT, env=robotino_child_env(robotino_msgs),
        stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    driver = DriverStandIn(rclpy_context)
    client, command_pub = _client(rclpy_context)
    try:
        with spinning(rclpy_context, driver, client) as executor:
            assert spin_until(executor, lambda: command_pub.get_subscription_count() > 0, 20.0)
            command_pub.publish(_command([1e4, 2e4, 3e4, 4e4, 5e4, 6e4]))
            assert spin_until(executor, lambda: driver.received, 5.0)
            # the shipped file: stale after command_timeout -> vent, republished at rate_hz
            assert spin_until(executor, lambda: len(driver.received) > 5, 5.0)
    finally:
        process.terminate()
        output = process.communicate(timeout=20)[0]
    assert process.returncode == 0, output
    np.testing.assert_allclose(driver.received[0][1], [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.0, 0.0],
                               rtol=1e-6)
    # the first vent set-point: not before the timeout, less 50 ms of delivery jitter
    assert driver.received[1][0] - driver.received[0][0] > SHIPPED['command_timeout'] - 0.05, (
        'vented before the timeout')
    for _, values in driver.received[1:]:
        np.testing.assert_array_equal(values, np.zeros(8))


@pytest.mark.untimed
def test_missing_robotino_msgs_stops_with_one_line_and_exit_2(tmp_path):
    # make install puts robotino_msgs into the venv: hidden here
    process = subprocess.Popen(
        [sys.executable, '-m', 'cbha_inverse.ros.nodes.robotino_bridge'], cwd=REPO_ROOT,
        env=hiding_env(tmp_path, 'robotino_msgs'), stdout=subprocess.PIPE,
        stderr=subprocess.STDOUT, text=True)
    output = process.communicate(timeout=60)[0]
    assert process.returncode == 2, output
    assert 'Traceback' not in output
    lines = [line for line in output.splitlines() if 'robotino_msgs is not importable' in line]
    assert len(lines) == 1 and 'make install' in lines[0], output
    assert 'robotino_msgs' not in child_env().get('PYTHONPATH', '')


def _tracking_rms(context, through_bridge, duration=7.5, hold=1.5, settle=1.5):
    """
    Run the closed loop on the CBHA scene (paper circle), direct or through bridge and driver.

    Direct: trajectory -> inverse_solver -> cbha_sim. Bridged: the solver's pressure_command goes
    to robotino_bridge, whose /set_bha_pressures reaches the driver stand-in, which forwards the
    arm channels in Pa to cbha_sim (remapped to /robot/pressure_command) and publishes the
    plant's valve pressures on /bha_readings at 20 Hz. Returns the RMS and max tip error [m] and
    the number of set-points the driver received.
    """
    scene = load_scene('cbha')
    names = list(scene.actuator_names)
    trajectory = make_node(TrajectoryNode, context,
                           center=[float(v) for v in scene.workspace_center[-1]],
                           rate_hz=LOOP_RATE, start_hold=hold, wait_for_subscribers=2)
    solver = make_node(InverseSolverNode, context, scene='cbha', valve_names=names,
                       rate_hz=LOOP_RATE, mode='closed', loop_gain=0.1)
    sim_args = ['--ros-args', '-r', 'pressure_command:=/robot/pressure_command']
    sim = CbhaSimNode(context=context, namespace='/cbha', parameter_overrides=[
        Parameter(k, value=v) for k, v in {'scene': 'cbha', 'valve_names': names,
                                           'rate_hz': LOOP_RATE}.items()],
        cli_args=sim_args if through_bridge else None)
    nodes = [trajectory, solver, sim]
    driver = None
    if through_bridge:
        driver = DriverStandIn(context, plant_topic='/robot/pressure_command',
                               read_bar=lambda: np.append(sim.pressures[sim.order]
                                                          / PASCAL_PER_BAR, [0.0, 0.0]),
                               reading_rate=20.0)
        nodes += [_bridge(context, valve_names=names, command_timeout=0.5), driver]
    errors = record_tracking(context, nodes, duration, hold, settle, LOOP_RATE)
    return errors.rms, errors.maximum, (len(driver.received) if driver else 0)


def test_closed_loop_through_bridge_and_driver_tracks_like_the_direct_loop(rclpy_context,
                                                                           robotino_msgs):
    """
    Run trajectory -> inverse_solver -> robotino_bridge -> driver -> cbha_sim end to end.

    The bridge adds two in-process hops (~1 ms) to a loop lag of ~53 ms, so the tracking RMS
    must match the direct loop's within the run-to-run noise. Measured on the loaded 2-core
    machine, three pairs: direct 0.30-0.55 mm, bridged 0.31-0.57 mm (spread of repeated runs of
    one kind up to 0.26 mm), hence the margin of 0.35 mm; one extra control tick of delay (20 ms
    at 2.5 cm/s, +0.5 mm of lag error) would exceed it. The loop-lag bound of test_ros_loop
    (1.3 mm) holds as well. Both loops run in this one process on one executor: like
    test_ros_loop, the test needs the machine not to be overloaded (at a load average of 13 on
    2 cores both tests saw stalls of the executor, tip errors up to 9 mm, and failed). Running
    both loops at the same time on the executor, to share the load, starves them instead.
    """
    direct_rms, _, _ = _tracking_rms(rclpy_context, through_bridge=False)
    bridged_rms, bridged_max, set_points = _tracking_rms(rclpy_context, through_bridge=True)
    print(f'closed-loop RMS direct {direct_rms * 1e3:.3f} mm, through the bridge '
          f'{bridged_rms * 1e3:.3f} mm (max {bridged_max * 1e3:.3f} mm), '
          f'{set_points} set-points to the driver')
    # the solver's 50 Hz commands over 7.5 s are 375: most of them reach the driver
    assert set_points > 200
    assert bridged_rms < loop_lag_error(LOOP_RATE)
    assert bridged_rms < direct_rms + BRIDGE_RMS_MARGIN


@pytest.mark.untimed
@pytest.mark.parametrize('overrides, match', [
    ({'valve_names': ['inner_over', 'elbow']}, 'unknown valve names'),
    ({'valve_names': ['inner_over', 'inner_over']}, 'duplicate'),
    ({'wrist_bar': [0.1]}, 'wrist_bar'),
    ({'wrist_bar': [0.1, 1.4], 'max_bar': 1.0}, 'wrist_bar'),
    ({'vent_pressure': 1e5, 'max_pressure': 5e4}, 'vent_pressure'),
    ({'max_bar': 2.0}, 'max_bar'),
    ({'stale_action': 'coast'}, 'stale_action'),
])
def test_invalid_parameters_are_refused_at_start(rclpy_context, overrides, match):
    with pytest.raises(ParameterError, match=match):
        _bridge(rclpy_context, **overrides)


def test_no_driver_readings_warns_once_then_every_period(rclpy_context, robotino_msgs, capfd):
    driver = DriverStandIn(rclpy_context)                    # silent until asked
    start = time.monotonic()
    bridge = _bridge(rclpy_context, reading_timeout=0.2, silence_warn_period=0.5)
    warning = 'no bha_readings from the driver on /bha_readings for 0.2 s or more'
    with spinning(rclpy_context, bridge, driver) as executor:
        if time.monotonic() - start < 0.15:
            spin_for(executor, 0.15 - (time.monotonic() - start))
            assert warning not in capfd.readouterr().err     # not before its timeout
        spin_for(executor, 1.1)
        elapsed = time.monotonic() - start
        log = capfd.readouterr().err
        assert 1 <= log.count(warning) <= 1 + (elapsed - 0.2) / 0.5, log
        # readings end the silence: no warning while they arrive
        assert spin_until(executor, lambda: driver.publish_readings() and bridge.readings, 10.0)
        capfd.readouterr()
        for _ in range(20):
            driver.publish_readings()
            spin_for(executor, 0.025)
        assert warning not in capfd.readouterr().err
