"""The Pa -> Robotino 8-channel bar mapping (the vendor channel table of docs/own-robot.md)."""

import math

from cbha_inverse.robot.robotino import ARM_VALVES, robotino_bar_command, robotino_pressures
import numpy as np
import pytest


def test_channel_order_units_and_wrist():
    pressures = [1e4, 2e4, 3e4, 4e4, 5e4, 6e4]
    np.testing.assert_allclose(robotino_bar_command(pressures),
                               [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.0, 0.0])


def test_permuted_valve_names_land_on_their_channels():
    names = ('outer_left', 'inner_over', 'outer_over', 'inner_left', 'inner_right', 'outer_right')
    out = robotino_bar_command([6e4, 1e4, 4e4, 3e4, 2e4, 5e4], names)
    np.testing.assert_allclose(out, [0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.0, 0.0])


def test_cap_negative_and_nan_safe():
    out = robotino_bar_command([2e5, -1e4, math.nan, math.inf, -math.inf, 1.5e5])
    np.testing.assert_array_equal(out, [1.5, 0.0, 0.0, 0.0, 0.0, 1.5, 0.0, 0.0])
    assert np.all(np.isfinite(out)) and out.shape == (8,)
    np.testing.assert_array_equal(robotino_bar_command(np.full(6, 1e5), max_bar=0.5)[:6], 0.5)


@pytest.mark.parametrize('pressures, names, match', [
    ([0.0] * 5, ARM_VALVES, 'pressures for'),
    ([0.0] * 6, ARM_VALVES[:5] + ('elbow',), 'unknown'),
    ([0.0] * 6, ARM_VALVES[:5] + ('inner_over',), 'duplicate'),
])
def test_bad_mapping_raises(pressures, names, match):
    with pytest.raises(ValueError, match=match):
        robotino_bar_command(pressures, names)


def test_bar_ceiling_cannot_be_raised():
    with pytest.raises(ValueError, match='max_bar'):
        robotino_bar_command([0.0] * 6, max_bar=2.0)


def test_wrist_set_points_are_clipped_and_overridden_by_commanded_wrist_valves():
    out = robotino_bar_command(np.zeros(6), wrist_bar=(0.4, 9.0))
    np.testing.assert_array_equal(out[6:], [0.4, 1.5])
    out = robotino_bar_command([2e4, 5e4], ('wrist_vertical', 'inner_left'),
                               wrist_bar=(0.3, math.nan))
    np.testing.assert_allclose(out, [0.0, 0.0, 0.5, 0.0, 0.0, 0.0, 0.3, 0.2])
    with pytest.raises(ValueError, match='wrist_bar'):
        robotino_bar_command(np.zeros(6), wrist_bar=(0.1,))


def test_readings_map_back_to_pascal_in_valve_order_round_trip():
    names = ('outer_left', 'inner_over', 'outer_over', 'inner_left', 'inner_right', 'outer_right')
    pressures = np.array([6e4, 1e4, 4e4, 3e4, 2e4, 5e4])
    channel_bar = np.append(robotino_bar_command(pressures, names), [0.25])
    np.testing.assert_allclose(robotino_pressures(channel_bar, names), pressures, rtol=1e-15)
    with pytest.raises(ValueError, match='channels read'):
        robotino_pressures([0.1] * 5, ARM_VALVES)
    with pytest.raises(ValueError, match='unknown'):
        robotino_pressures([0.1] * 8, ('elbow',))
