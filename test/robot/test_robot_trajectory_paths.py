"""
The target paths' geometry, laps and arguments (:mod:`cbha_inverse.robot.trajectory`).

Where each shape starts and which way it runs, how a finite number of laps ends and holds,
repeated waypoints, the argument checks that name the argument, and the defaults (the paper's
circle and square, Bosman et al. 2015, section V).
"""

import math

from cbha_inverse.robot.trajectory import (
    circle_points, circle_trajectory, make_trajectory, polyline_points, square_trajectory,
    square_vertices, waypoint_trajectory)
import numpy as np
import pytest


def test_square_starts_mid_side_and_runs_counter_clockwise():
    center = np.array([0.1, 0.2, 0.3])
    path = square_trajectory(center, 0.08, 'YZ', speed=0.04)
    assert path.shape == 'square' and path.plane == 'yz'
    np.testing.assert_array_equal(path.center, center)
    start, first_corner, second_corner = path.sample([0.0, 1.0, 3.0])
    np.testing.assert_allclose(start, center + [0.0, 0.04, 0.0], atol=1e-15)
    # half a side (0.04 m at 0.04 m/s) to the (+u, +v) corner, then one side to (-u, +v)
    np.testing.assert_allclose(first_corner, center + [0.0, 0.04, 0.04], atol=1e-15)
    np.testing.assert_allclose(second_corner, center + [0.0, -0.04, 0.04], atol=1e-15)


def test_circle_fields_and_start_point():
    path = circle_trajectory((0.0, 0.0, 0.0), 0.06, 'ZX', speed=0.025)
    assert path.shape == 'circle' and path.plane == 'zx' and path.radius == 0.06
    np.testing.assert_allclose(path.sample(0.0)[0], [0.0, 0.0, 0.06])
    # a quarter lap later the point is on the second axis (x): counter-clockwise about y
    np.testing.assert_allclose(path.sample(0.25 * path.lap_time)[0], [0.06, 0.0, 0.0],
                               atol=1e-15)


def test_one_lap_ends_on_the_start_point_and_holds_it():
    path = circle_trajectory((0.0, 0.0, 0.0), 0.06, 'yz', speed=0.05, laps=1, start_hold=0.5)
    assert path.duration == pytest.approx(0.5 + path.lap_time)
    half = path.sample(0.5 + 0.5 * path.lap_time)[0]
    np.testing.assert_allclose(half, [0.0, -0.06, 0.0], atol=1e-15)
    assert path.arc_length(path.duration)[0] == path.length
    assert path.arc_length(path.duration + 10.0)[0] == path.length
    np.testing.assert_allclose(path.sample(path.duration + 10.0)[0], [0.0, 0.06, 0.0],
                               atol=1e-15)
    assert path.finished(path.duration) and not path.finished(path.duration - 1e-9)


def test_repeated_waypoints_give_no_garbage():
    """A loop whose last waypoint already is the first: a zero-length closing piece."""
    square = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 1.0, 0.0), (0.0, 0.0, 0.0)]
    path = waypoint_trajectory(square, 1.0, loop=True)
    assert path.shape == 'waypoints' and path.closed
    assert path.length == pytest.approx(2.0 + math.sqrt(2.0))
    np.testing.assert_array_equal(polyline_points(path.vertices, [path.length, 1e9]),
                                  np.zeros((2, 3)))
    repeated = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (1.0, 0.0, 0.0)]
    np.testing.assert_array_equal(polyline_points(repeated, [1.0, 1.5, 5.0]),
                                  [[1.0, 0.0, 0.0]] * 3)


@pytest.mark.parametrize('arguments, match', [
    ({'shape': 'circle', 'radius': 0.0}, '^radius must be a finite number > 0'),
    ({'shape': 'circle', 'center': (0.0, math.nan, 0.0)}, '^center must be finite'),
    ({'shape': 'square', 'side': -1.0}, '^side must be a finite number > 0'),
    ({'shape': 'square', 'center': (0.0, 0.0)}, '^center must have 3 components'),
    ({'shape': 'circle', 'speed': 0.0}, '^speed must be a finite number > 0'),
    ({'shape': 'circle', 'laps': -1}, r'^laps must be an integer >= 0'),
    ({'shape': 'circle', 'start_hold': -1.0}, '^start_hold must be a finite number >= 0'),
    ({'shape': 'waypoints', 'waypoints': [[0.0, 0.0], [1.0, 1.0], [2.0, 2.0]]},
     r'^waypoints must be \(V, 3\) with V >= 2'),
    ({'shape': 'waypoints', 'waypoints': [0.0, 0.0, 0.0, 1.0]},
     '^a flat waypoint list needs 3 numbers per point'),
    ({'shape': 'waypoints', 'waypoints': [0.0, 0.0, 0.0, 1.0, math.inf, 0.0]},
     '^waypoints must be finite$'),
    ({'shape': 'waypoints', 'waypoints': [1.0, 1.0, 1.0, 1.0, 1.0, 1.0]},
     '^waypoints span a path of zero length$'),
    ({'shape': 'triangle'}, '^shape must be one of'),
])
def test_bad_trajectory_arguments_name_the_argument(arguments, match):
    with pytest.raises(ValueError, match=match):
        make_trajectory(**arguments)


@pytest.mark.parametrize('call, match', [
    (lambda: circle_points((0.0, math.inf, 0.0), 0.06, 'yz', [0.0]), '^center must be finite'),
    (lambda: circle_points((0.0, 0.0, 0.0), -0.06, 'yz', [0.0]),
     '^radius must be a finite number > 0'),
    (lambda: square_vertices((0.0, 0.0), 0.08, 'yz'), '^center must have 3 components'),
    (lambda: square_vertices((0.0, 0.0, 0.0), 0.0, 'yz'), '^side must be a finite number > 0'),
])
def test_path_point_functions_validate_their_own_inputs(call, match):
    with pytest.raises(ValueError, match=match):
        call()


def test_last_lap_ends_exactly_at_the_path_length():
    # exact binary numbers: side 0.25 m (length 1 m) at 0.5 m/s, the lap ends at t = 2 s
    path = square_trajectory((0.0, 0.0, 0.0), 0.25, 'yz', speed=0.5, laps=1)
    assert path.duration == 2.0
    assert path.arc_length([1.0, 2.0, 3.0]).tolist() == [0.5, 1.0, 1.0]
    endless = square_trajectory((0.0, 0.0, 0.0), 0.25, 'yz', speed=0.5)
    assert endless.arc_length([1.0, 2.0, 3.0]).tolist() == [0.5, 0.0, 0.5]


def test_path_constructor_defaults_are_the_papers():
    """Bosman et al. 2015, section V: circle at 2.5 cm/s, square at 3.1 cm/s, in the y-z plane."""
    circle = circle_trajectory((0.0, 0.0, 0.0), 0.06)
    assert (circle.plane, circle.speed, circle.laps, circle.start_hold) == ('yz', 0.025, 0, 0.0)
    square = square_trajectory((0.0, 0.0, 0.0), 0.08)
    assert (square.plane, square.speed, square.laps, square.start_hold) == ('yz', 0.031, 0, 0.0)
    line = waypoint_trajectory([(0.0, 0.0, 0.0), (0.0, 0.0, 0.5)], 0.1)
    assert (line.closed, line.laps, line.start_hold) == (False, 0, 0.0)
    assert make_trajectory('square').length == pytest.approx(4 * 0.08)


def test_make_trajectory_defaults_are_the_papers_and_pass_every_argument():
    circle = make_trajectory('circle')
    assert (circle.speed, circle.radius, circle.plane, circle.laps, circle.start_hold) == (
        0.025, 0.06, 'yz', 0, 0.0)
    square = make_trajectory('square', center=(1.0, 2.0, 3.0), side=0.1, plane='xy',
                             speed=0.031, laps=2, start_hold=1.5)
    assert (square.length, square.plane, square.speed, square.laps, square.start_hold) == (
        pytest.approx(0.4), 'xy', 0.031, 2, 1.5)
    np.testing.assert_array_equal(square.center, [1.0, 2.0, 3.0])
    line = make_trajectory('waypoints', waypoints=(0.0, 0.0, 0.0, 0.0, 0.0, 0.5), speed=0.1,
                           laps=3, start_hold=2.0)
    assert not line.closed and line.length == 0.5 and line.duration == pytest.approx(7.0)
    loop = make_trajectory('waypoints', waypoints=(0.0, 0.0, 0.0, 0.0, 0.0, 0.5), loop=True,
                           laps=3)
    assert loop.closed and loop.length == 1.0 and loop.duration == pytest.approx(3.0 / 0.025)
