"""The pure safety gate: point checks, driver-like command checks, bounded commands, staleness."""

import math

from cbha_inverse.robot.safety import (
    bounded_command, check_command, check_point, command_bounds, CommandGate, stale_action,
    StalenessWatch, valve_order, WorkspaceBox)
from cbha_inverse.scene import load_scene
import numpy as np
import pytest

BOX = WorkspaceBox((-0.1, -0.2, -0.3), (0.5, 0.2, 0.3))


@pytest.mark.parametrize('point, frame, reason', [
    ((0.2, 0.0, 0.0), 'cbha_base', 'ok'),
    ((0.5, 0.2, 0.3), 'cbha_base', 'ok'),
    ((math.nan, 0.0, 0.0), 'cbha_base', 'non_finite'),
    ((0.2, math.inf, 0.0), 'cbha_base', 'non_finite'),
    ((0.2, 0.0, -math.inf), 'wrong', 'non_finite'),
    ((0.2, 0.0, 0.0), 'world', 'wrong_frame'),
    ((0.2, 0.0, 0.0), '', 'wrong_frame'),
    ((1e300, 0.0, 0.0), 'cbha_base', 'outside_workspace'),
    ((0.2, -0.21, 0.0), 'cbha_base', 'outside_workspace'),
])
def test_check_point(point, frame, reason):
    check = check_point(point, frame, 'cbha_base', BOX)
    assert check.reason == reason and check.ok == (reason == 'ok')
    assert check.ok or check.detail


@pytest.mark.parametrize('values, reason', [
    ([0.0, 1e5, 1.5e5], 'ok'),
    ([0.0, 1e5], 'wrong_length'),
    ([0.0, 1e5, 1e5, 0.0], 'wrong_length'),
    ([], 'wrong_length'),
    ([0.0, math.nan, 0.0], 'non_finite'),
    ([0.0, -math.inf, 0.0], 'non_finite'),
    ([0.0, -1.0, 0.0], 'out_of_range'),
    ([0.0, 1.5e5 + 1.0, 0.0], 'out_of_range'),
    ([1e308, 0.0, 0.0], 'out_of_range'),
])
def test_check_command(values, reason):
    assert check_command(values, 3, 1.5e5).reason == reason


def test_command_gate_refuses_bounds_it_cannot_keep():
    for lower, upper in (([0.0, 0.0], [1.0]), ([0.0, math.nan], [1.0, 1.0]),
                         ([0.0, 0.0], [1.0, math.inf]), ([0.0, 2.0], [1.0, 1.0])):
        with pytest.raises(ValueError, match='command bounds'):
            CommandGate(lower, upper)
    gate = CommandGate([0.0, 0.0], [1.0, 1.0])
    # not the gate's float path: an int array, a (1, 2) row, strings
    np.testing.assert_array_equal(gate(np.array([3, -1])), [1.0, 0.0])
    np.testing.assert_array_equal(gate(np.array([[0.5, 2.0]])), [0.5, 1.0])
    with pytest.raises(ValueError, match='not numbers'):
        gate(['a', 'b'])
    with pytest.raises(ValueError, match='3 values, expected 2'):
        gate(np.zeros(3))


def test_bounded_command_clips_and_refuses_nan():
    lower, upper = np.zeros(3), np.full(3, 1.5e5)
    np.testing.assert_array_equal(bounded_command([-5.0, 2e5, 7.0], lower, upper),
                                  [0.0, 1.5e5, 7.0])
    for bad in ([math.nan, 0.0, 0.0], [math.inf, 0.0, 0.0], [0.0, 0.0]):
        with pytest.raises(ValueError):
            bounded_command(bad, lower, upper)
    rng = np.random.default_rng(0)
    values = rng.normal(0.0, 1e6, (1000, 3))
    for row in values:
        out = bounded_command(row, lower, upper)
        assert np.all((out >= 0.0) & (out <= 1.5e5))


def test_staleness_on_a_given_steady_clock():
    watch = StalenessWatch(0.5)
    assert watch.stale(100.0) and watch.age(100.0) == math.inf
    watch.mark(100.0)
    assert not watch.stale(100.5) and watch.stale(100.5001)
    with pytest.raises(ValueError):
        StalenessWatch(0.0)


@pytest.mark.parametrize('feedback, closed, action, expected', [
    (False, False, 'hold', 'run'),
    (True, False, 'vent', 'run'),
    (True, True, 'vent', 'vent'),
    (True, True, 'hold', 'hold'),
    (False, True, 'vent', 'run'),
])
def test_stale_action(feedback, closed, action, expected):
    assert stale_action(feedback, closed, action) == expected


def test_workspace_box_validation():
    with pytest.raises(ValueError, match='below'):
        WorkspaceBox((0.0, 0.0, 0.0), (1.0, 0.0, 1.0))
    with pytest.raises(ValueError, match='finite'):
        WorkspaceBox((0.0, 0.0, -math.inf), (1.0, 1.0, 1.0))
    with pytest.raises(ValueError, match='3 components'):
        WorkspaceBox((0.0, 0.0), (1.0, 1.0))


def test_valve_order_maps_each_command_entry_to_its_scene_actuator():
    names = ('inner_over', 'inner_right', 'outer_over')
    assert valve_order(names) == (names, pytest.approx([0, 1, 2]))
    valves, order = valve_order(names, ['outer_over', 'inner_over', 'inner_right'])
    assert valves == ('outer_over', 'inner_over', 'inner_right')
    scene_vector = np.array([10.0, 20.0, 30.0])
    np.testing.assert_array_equal(scene_vector[order], [30.0, 10.0, 20.0])
    for wrong in (['inner_over', 'inner_right'], ['inner_over', 'inner_over', 'outer_over'],
                  ['a', 'b', 'c']):
        with pytest.raises(ValueError, match='must be a permutation of the scene actuators'):
            valve_order(names, wrong)


def test_command_bounds_are_the_scene_bounds_within_zero_and_max_pressure():
    cbha = load_scene('cbha')
    lower, upper = command_bounds(cbha.lower_bounds, cbha.upper_bounds, 120e3)
    np.testing.assert_array_equal(lower, np.zeros(6))
    np.testing.assert_array_equal(upper, np.full(6, 120e3))
    np.testing.assert_array_equal(command_bounds(cbha.lower_bounds, cbha.upper_bounds)[1],
                                  np.full(6, 150000.0))
    # a negative lower bound is raised to 0 (no suction), an upper bound below the cap stays
    lower, upper = command_bounds([-5.0, 1.0], [4.0, 8.0], 6.0)
    np.testing.assert_array_equal(lower, [0.0, 1.0])
    np.testing.assert_array_equal(upper, [4.0, 6.0])
    with pytest.raises(ValueError, match='below a lower actuator bound'):
        command_bounds(load_scene('tendon_6f_8c').lower_bounds,
                       load_scene('tendon_6f_8c').upper_bounds, -1.0)
    # without a cap, bounds that cross are refused with their own reason
    with pytest.raises(ValueError, match='upper actuator bound lies below its lower bound'):
        command_bounds([0.0, 2.0], [1.0, 1.0])
