"""Tests of the obstacle primitives' signed distance: closed forms, finite differences."""

from cbha_inverse.core.obstacles import Obstacle, obstacle_from_rpy, sphere_gaps
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

_TURN = Rotation.from_euler('xyz', [0.3, -0.5, 1.1]).as_matrix()
_AT = np.array([0.1, -0.2, 0.05])


def _posed(local):
    """Return local obstacle-frame points in the base frame of the posed obstacles below."""
    return np.atleast_2d(local) @ _TURN.T + _AT


def _obstacles():
    """One obstacle of each shape, all at the same rotated, shifted pose."""
    return {'plane': Obstacle('floor', 'plane', _AT, _TURN),
            'sphere': Obstacle('ball', 'sphere', _AT, _TURN, radius=0.03),
            'box': Obstacle('crate', 'box', _AT, _TURN, size=(0.04, 0.06, 0.1)),
            'capsule': Obstacle('pill', 'capsule', _AT, _TURN, radius=0.02, length=0.08),
            'cylinder': Obstacle('post', 'cylinder', _AT, _TURN, radius=0.02, length=0.08)}


# (shape, local point, distance, local outward normal)
_CLOSED_FORMS = [
    ('plane', [0.3, -0.2, 0.07], 0.07, [0, 0, 1]),
    ('plane', [0.3, -0.2, -0.01], -0.01, [0, 0, 1]),
    ('sphere', [0.0, 0.05, 0.0], 0.02, [0, 1, 0]),
    ('sphere', [-0.01, 0.0, 0.0], -0.02, [-1, 0, 0]),
    # box, half edges (0.02, 0.03, 0.05): face, edge, corner, inside
    ('box', [0.025, 0.01, -0.02], 0.005, [1, 0, 0]),
    ('box', [0.023, -0.034, 0.0], 0.005, [0.6, -0.8, 0]),
    ('box', [-0.022, 0.032, -0.051], 3e-3, [-2 / 3, 2 / 3, -1 / 3]),
    ('box', [0.0, 0.025, 0.01], -0.005, [0, 1, 0]),
    ('box', [0.01, 0.0, -0.048], -0.002, [0, 0, -1]),
    # capsule radius 0.02, segment z in [-0.04, 0.04]: beside, beyond an end, inside
    ('capsule', [0.0, -0.05, 0.03], 0.03, [0, -1, 0]),
    ('capsule', [0.03, 0.0, 0.08], 0.03, [0.6, 0, 0.8]),
    ('capsule', [0.0, 0.005, -0.01], -0.015, [0, 1, 0]),
    # cylinder radius 0.02, caps at z = +-0.04: side, cap, rim, inside near side / cap
    ('cylinder', [0.03, 0.04, 0.0], 0.03, [0.6, 0.8, 0]),
    ('cylinder', [0.005, 0.0, -0.05], 0.01, [0, 0, -1]),
    ('cylinder', [0.0, 0.023, 0.044], 0.005, [0, 0.6, 0.8]),
    ('cylinder', [0.0, -0.015, 0.0], -0.005, [0, -1, 0]),
    ('cylinder', [0.002, 0.0, 0.037], -0.003, [0, 0, 1]),
]


@pytest.mark.parametrize('shape, local, distance, normal', _CLOSED_FORMS)
def test_distance_normal_and_closest_point_match_closed_forms(shape, local, distance, normal):
    """Distance, normal and closest point of each primitive at faces, edges, corners, inside."""
    obstacle = _obstacles()[shape]
    point = _posed(local)
    query = obstacle.signed_distance(point)
    assert query.distance[0] == pytest.approx(distance, abs=1e-12)
    np.testing.assert_allclose(query.normal[0], _TURN @ np.array(normal, dtype=float),
                               atol=1e-12)
    np.testing.assert_allclose(query.closest[0], point[0] - distance * query.normal[0],
                               atol=1e-12)
    # the closest point lies on the surface
    assert obstacle.signed_distance(query.closest).distance[0] == pytest.approx(0.0, abs=1e-12)


def _random_points(rng, count=200):
    """Points around the obstacles, outside and inside."""
    return _posed(rng.uniform(-0.09, 0.09, size=(count, 3)))


@pytest.mark.parametrize('shape', list(_obstacles()))
def test_normal_is_the_gradient_and_curvature_its_derivative(shape):
    """Central differences of the distance give the normal, of the normal the Hessian."""
    obstacle = _obstacles()[shape]
    points = _random_points(np.random.default_rng(3))
    query = obstacle.signed_distance(points)
    step = 1e-6
    gradient, hessian = np.empty_like(points), np.empty((points.shape[0], 3, 3))
    smooth = np.ones(points.shape[0], dtype=bool)
    for axis in range(3):
        shift = np.zeros(3)
        shift[axis] = step
        ahead, behind = obstacle.signed_distance(points + shift), obstacle.signed_distance(
            points - shift)
        gradient[:, axis] = (ahead.distance - behind.distance) / (2 * step)
        hessian[:, :, axis] = (ahead.normal - behind.normal) / (2 * step)
        # a stencil across an edge of the regions (where the Hessian jumps) is no reference
        for side in (ahead, behind):
            smooth &= np.all(np.isclose(side.curvature, query.curvature, rtol=1e-2,
                                        atol=1e-6), axis=(1, 2))
    assert smooth.mean() > 0.95
    np.testing.assert_allclose(query.normal[smooth], gradient[smooth], atol=1e-7)
    np.testing.assert_allclose(np.linalg.norm(query.normal, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(query.curvature[smooth], hessian[smooth], atol=1e-5, rtol=1e-4)
    # the normal points out: moving along it increases the distance
    moved = obstacle.signed_distance(points + 1e-4 * query.normal).distance
    assert np.all(moved > query.distance)
    # the closest point is the point moved back by its distance, on the surface
    np.testing.assert_allclose(query.closest, points - query.distance[:, None] * query.normal,
                               atol=1e-12)


def test_curved_and_flat_regions_of_the_curvature():
    """A face of a box or a plane is flat; a sphere's Hessian is the tangent projector / R."""
    obstacles = _obstacles()
    assert not np.any(obstacles['plane'].signed_distance(_posed([0.1, 0.2, 0.3])).curvature)
    assert not np.any(obstacles['box'].signed_distance(_posed([0.03, 0.0, 0.0])).curvature)
    query = obstacles['sphere'].signed_distance(_posed([0.0, 0.0, 0.05]))
    n = query.normal[0]
    np.testing.assert_allclose(query.curvature[0], (np.eye(3) - np.outer(n, n)) / 0.05,
                               atol=1e-12)


def test_rpy_pose_and_sphere_gaps():
    """A plane turned by rpy has the turned normal; a sphere's gap subtracts its radius."""
    table = obstacle_from_rpy('table', 'plane', [0, 0, -0.05], [np.pi / 2, 0.0, 0.0])
    # roll +90 deg about x turns +z onto -y
    query = table.signed_distance([[0.0, -0.02, 0.3]])
    np.testing.assert_allclose(query.normal[0], [0.0, -1.0, 0.0], atol=1e-15)
    assert query.distance[0] == pytest.approx(0.02)
    floor = Obstacle('floor', 'plane', [0, 0, -0.05], np.eye(3))
    gaps = sphere_gaps([floor, table], [[0.0, 0.0, 0.0], [0.0, 0.01, -0.052]], [0.01, 0.005])
    np.testing.assert_allclose(gaps, [[0.04, -0.01], [-0.007, -0.015]], atol=1e-15)


@pytest.mark.parametrize('kwargs, problem', [
    ({'shape': 'cone'}, 'unknown shape'),
    ({'shape': 'sphere'}, 'needs its radius'),
    ({'shape': 'sphere', 'radius': -0.1}, 'must be > 0'),
    ({'shape': 'sphere', 'radius': float('nan')}, 'finite'),
    ({'shape': 'plane', 'radius': 0.1}, 'takes no radius'),
    ({'shape': 'box', 'size': (0.1, 0.1)}, '3 finite numbers'),
    ({'shape': 'capsule', 'radius': 0.01, 'length': -0.1}, 'must be >= 0'),
    ({'shape': 'plane', 'position': (0.0, float('inf'), 0.0)}, 'position'),
    ({'shape': 'plane', 'rotation': np.diag([1.0, 1.0, -1.0])}, 'rotation'),
    ({'shape': 'plane', 'rotation': 2 * np.eye(3)}, 'rotation'),
])
def test_invalid_obstacles_are_refused(kwargs, problem):
    """Each wrong shape, size or pose raises a ValueError naming the obstacle and the fault."""
    args = {'name': 'thing', 'position': (0.0, 0.0, 0.0), 'rotation': np.eye(3), **kwargs}
    with pytest.raises(ValueError, match=problem) as error:
        Obstacle(**args)
    assert "'thing'" in str(error.value) or 'unknown' not in problem


def test_points_are_checked():
    """Non-finite or mis-shaped points are refused at the door."""
    ball = _obstacles()['sphere']
    with pytest.raises(ValueError, match='finite'):
        ball.signed_distance([[0.0, np.nan, 0.0]])
    with pytest.raises(ValueError, match=r'\(N, 3\)'):
        ball.signed_distance(np.zeros((2, 2)))
