"""The pure reference paths: radius, side, closure and constant speed (to 1e-9)."""

import math

from cbha_inverse.robot.trajectory import (
    circle_trajectory, make_trajectory, plane_axes, square_trajectory, waypoint_trajectory)
import numpy as np
import pytest

CENTER = np.array([0.2, 0.01, -0.02])


def _speeds(trajectory, times):
    """Finite-difference speed between consecutive samples (exact for straight pieces)."""
    points = trajectory.sample(times)
    return np.linalg.norm(np.diff(points, axis=0), axis=1) / np.diff(times)


def test_circle_lies_on_radius_in_its_plane_and_closes():
    circle = circle_trajectory(CENTER, 0.06, 'yz', 0.025)
    times = np.linspace(0.0, circle.lap_time, 2001)
    points = circle.sample(times)
    assert np.max(np.abs(np.linalg.norm(points - CENTER, axis=1) - 0.06)) < 1e-12
    assert np.max(np.abs(points[:, 0] - CENTER[0])) < 1e-15
    assert np.linalg.norm(points[-1] - points[0]) < 1e-9
    assert circle.length == pytest.approx(2.0 * math.pi * 0.06, abs=1e-15)
    np.testing.assert_allclose(points[0], CENTER + [0.0, 0.06, 0.0], atol=1e-15)


def test_circle_constant_speed_along_the_path():
    circle = circle_trajectory(CENTER, 0.06, 'yz', 0.025)
    arc = circle.arc_length(np.linspace(0.0, circle.lap_time * 0.999, 997))
    np.testing.assert_allclose(np.diff(arc), np.diff(arc)[0], rtol=0, atol=1e-12)
    # angular rate = speed / radius exactly: the arc between two samples is speed * dt
    times = np.linspace(0.0, 3.0, 301)
    points = circle.sample(times)
    angles = np.unwrap(np.arctan2(points[:, 2] - CENTER[2], points[:, 1] - CENTER[1]))
    np.testing.assert_allclose(np.diff(angles) * 0.06, 0.025 * np.diff(times), atol=1e-9)


def test_square_side_closure_and_speed():
    square = square_trajectory(CENTER, 0.08, 'yz', 0.031)
    assert square.length == pytest.approx(0.32, abs=1e-15)
    corners = square.vertices[1:5]
    sides = np.linalg.norm(np.diff(np.vstack([corners, corners[:1]]), axis=0), axis=1)
    np.testing.assert_allclose(sides, 0.08, atol=1e-15)
    times = np.linspace(0.0, square.lap_time, 3201)
    points = square.sample(times)
    assert np.linalg.norm(points[-1] - points[0]) < 1e-9
    in_plane = np.abs(points[:, 1:] - CENTER[1:])
    assert np.all(np.max(in_plane, axis=1) == pytest.approx(0.04, abs=1e-12))
    # speed is exact on every sample interval that does not straddle a corner
    speeds = _speeds(square, times)
    corner_arcs = np.array([0.04, 0.12, 0.2, 0.28])
    arcs = square.arc_length(times)
    straight = ~np.any((arcs[:-1, None] < corner_arcs) & (arcs[1:, None] > corner_arcs), axis=1)
    np.testing.assert_allclose(speeds[straight], 0.031, atol=1e-9)


def test_waypoints_constant_speed_and_end_hold():
    path = waypoint_trajectory([0.0, 0.0, 0.0, 0.0, 0.03, 0.0, 0.0, 0.03, 0.04], 0.01)
    assert path.length == pytest.approx(0.07)
    times = np.linspace(0.0, 2.9, 291)
    np.testing.assert_allclose(_speeds(path, times), 0.01, atol=1e-9)
    np.testing.assert_allclose(path.sample(100.0)[0], [0.0, 0.03, 0.04], atol=1e-15)
    assert path.finished(7.001) and not path.finished(6.999)


def test_looped_waypoints_close_and_laps_end_at_start():
    path = waypoint_trajectory([[0, 0, 0], [0.1, 0, 0], [0.1, 0.1, 0]], 0.05, loop=True, laps=2,
                               start_hold=1.0)
    assert path.length == pytest.approx(0.2 + math.sqrt(0.02))
    np.testing.assert_allclose(path.sample([0.0, 0.5, 1.0]), 0.0, atol=1e-15)
    np.testing.assert_allclose(path.sample(1.0 + path.lap_time), [[0.0, 0.0, 0.0]], atol=1e-9)
    assert path.duration == pytest.approx(1.0 + 2 * path.lap_time)
    np.testing.assert_allclose(path.sample(path.duration + 5.0), [[0.0, 0.0, 0.0]], atol=1e-9)


def test_plane_axes_orientation():
    u_axis, v_axis = plane_axes('yz')
    np.testing.assert_array_equal(np.cross(u_axis, v_axis), [1.0, 0.0, 0.0])
    u_axis, v_axis = plane_axes('XY')
    np.testing.assert_array_equal(np.cross(u_axis, v_axis), [0.0, 0.0, 1.0])


@pytest.mark.parametrize('kwargs, match', [
    ({'shape': 'circle', 'radius': -0.06}, 'radius'),
    ({'shape': 'circle', 'radius': 0.0}, 'radius'),
    ({'shape': 'circle', 'speed': 0.0}, 'speed'),
    ({'shape': 'square', 'speed': -1.0}, 'speed'),
    ({'shape': 'square', 'side': math.nan}, 'side'),
    ({'shape': 'circle', 'center': (0.0, math.inf, 0.0)}, 'center'),
    ({'shape': 'circle', 'center': (0.0, 0.0)}, 'center'),
    ({'shape': 'circle', 'plane': 'yy'}, 'plane'),
    ({'shape': 'triangle'}, 'shape'),
    ({'shape': 'circle', 'laps': -1}, 'laps'),
    ({'shape': 'circle', 'start_hold': -1.0}, 'start_hold'),
    ({'shape': 'waypoints', 'waypoints': [0.0, 0.0, 0.0, 1.0]}, '3 numbers'),
    ({'shape': 'waypoints', 'waypoints': [0.0, 0.0, 0.0]}, 'V >= 2'),
    ({'shape': 'waypoints', 'waypoints': [0.0, 0.0, 0.0] * 2}, 'zero length'),
    ({'shape': 'waypoints', 'waypoints': [0.0, 0.0, math.nan, 0.0, 1.0, 0.0]}, 'finite'),
])
def test_invalid_arguments_raise_clear_errors(kwargs, match):
    with pytest.raises(ValueError, match=match):
        make_trajectory(**kwargs)
