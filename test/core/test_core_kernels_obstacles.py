"""
The compiled signed distance of the obstacle primitives against independent references.

Closed forms of each primitive (distance, normal, closest point and Hessian at faces, edges,
corners, inside, on the axes and at ties), a dense sampling of each surface (no surface point
nearer than the distance claimed), an inside test of each solid, central differences (the
normal is the distance's gradient, the Hessian the normal's derivative), the packed arrays'
round trip and a call from compiled code. The file runs with numba's JIT off too (``make
cover-kernels``).
"""

from cbha_inverse.core._kernels.obstacles import (BOX, CAPSULE, CYLINDER, PLANE,
                                                  signed_distance_at, signed_distances_into,
                                                  SPHERE)
from cbha_inverse.core.obstacles import (Obstacle, pack_obstacles, pairwise_signed_distance,
                                         SHAPES)
import numba
from numba.core.runtime import _nrt_python, rtsys
import numpy as np
import pytest
from scipy.spatial.transform import Rotation

_TURN = Rotation.from_euler('zyx', [-0.7, 0.4, 2.2]).as_matrix()
_AT = np.array([-0.03, 0.12, 0.2])
# (shape code, sizes) of the primitives of the closed forms: box half edges (0.02, 0.03, 0.05);
# capsule and cylinder radius 0.02, ends or caps at z = +-0.04; sphere radius 0.03
_PRIMITIVES = {'plane': (PLANE, (0.0, 0.0, 0.0)), 'sphere': (SPHERE, (0.03, 0.0, 0.0)),
               'box': (BOX, (0.04, 0.06, 0.1)), 'capsule': (CAPSULE, (0.02, 0.08, 0.0)),
               'cylinder': (CYLINDER, (0.02, 0.08, 0.0)),
               # dyadic sizes: the excesses of a tie are equal bit for bit
               'cube': (BOX, (0.5, 0.5, 1.0)), 'ball capsule': (CAPSULE, (0.02, 0.0, 0.0))}


def _query(name, local, rotation=_TURN, position=_AT):
    """Return the kernel's (distance, normal, closest, curvature) of a local point, base frame."""
    shape, sizes = _PRIMITIVES[name]
    point = rotation @ np.asarray(local, dtype=float) + position
    normal, closest, curvature = np.empty(3), np.empty(3), np.empty((3, 3))
    distance = signed_distance_at(shape, position, rotation, np.array(sizes, dtype=float), point,
                                  normal, closest, curvature)
    return distance, normal, closest, curvature


def _outer(u):
    u = np.asarray(u, dtype=float)
    return np.outer(u, u)


_EYE = np.eye(3)
_X, _Y, _Z = _EYE
# (primitive, local point, distance, normal, closest, Hessian), all local
_CLOSED_FORMS = [
    ('plane', [0.3, -0.2, 0.07], 0.07, _Z, [0.3, -0.2, 0.0], 0 * _EYE),
    ('plane', [0.0, 0.0, -0.02], -0.02, _Z, [0.0, 0.0, 0.0], 0 * _EYE),
    # sphere: the Hessian is the tangent projector over the distance from the centre
    ('sphere', [0.0, 0.04, 0.03], 0.02, [0, 0.8, 0.6], [0.0, 0.024, 0.018],
     (_EYE - _outer([0, 0.8, 0.6])) / 0.05),
    ('sphere', [-0.01, 0.0, 0.0], -0.02, -_X, [-0.03, 0.0, 0.0], np.diag([0.0, 100.0, 100.0])),
    # box: a face is flat; an edge curves across it; a corner like a sphere
    ('box', [0.025, 0.01, -0.02], 0.005, _X, [0.02, 0.01, -0.02], 0 * _EYE),
    ('box', [0.023, -0.034, 0.0], 0.005, [0.6, -0.8, 0], [0.02, -0.03, 0.0],
     _outer([0.8, 0.6, 0]) / 0.005),
    ('box', [-0.022, 0.032, -0.051], 0.003, [-2 / 3, 2 / 3, -1 / 3], [-0.02, 0.03, -0.05],
     (_EYE - _outer([-2 / 3, 2 / 3, -1 / 3])) / 0.003),
    ('box', [0.0, 0.025, 0.01], -0.005, _Y, [0.0, 0.03, 0.01], 0 * _EYE),
    ('box', [0.01, -0.005, -0.048], -0.002, -_Z, [0.01, -0.005, -0.05], 0 * _EYE),
    # capsule: beside its segment a cylinder, beyond an end a sphere
    ('capsule', [0.0, -0.05, 0.03], 0.03, -_Y, [0.0, -0.02, 0.03], _outer(_X) / 0.05),
    ('capsule', [0.03, 0.0, 0.08], 0.03, [0.6, 0, 0.8], [0.012, 0.0, 0.056],
     (_EYE - _outer([0.6, 0, 0.8])) / 0.05),
    ('capsule', [0.0, 0.005, -0.01], -0.015, _Y, [0.0, 0.02, -0.01], _outer(_X) / 0.005),
    ('ball capsule', [0.0, 0.03, 0.04], 0.03, [0, 0.6, 0.8], [0.0, 0.012, 0.016],
     (_EYE - _outer([0, 0.6, 0.8])) / 0.05),
    # cylinder: the side curves by 1 / s about the axis; a cap is flat; the rim curves both ways
    ('cylinder', [0.03, 0.04, 0.0], 0.03, [0.6, 0.8, 0], [0.012, 0.016, 0.0],
     _outer([-0.8, 0.6, 0]) / 0.05),
    ('cylinder', [0.005, 0.0, -0.05], 0.01, -_Z, [0.005, 0.0, -0.04], 0 * _EYE),
    ('cylinder', [0.0, 0.023, 0.044], 0.005, [0, 0.6, 0.8], [0.0, 0.02, 0.04],
     _outer([0, 0.8, -0.6]) / 0.005 + 0.6 / 0.023 * _outer(_X)),
    ('cylinder', [0.0, -0.015, 0.0], -0.005, -_Y, [0.0, -0.02, 0.0], _outer(_X) / 0.015),
    ('cylinder', [0.002, 0.0, 0.037], -0.003, _Z, [0.002, 0.0, 0.04], 0 * _EYE),
]


# where the normal is not unique, the kernel's fixed choice (unposed: a pose's rounding would
# break the tie)
_CHOICES = [
    ('sphere', [0.0, 0.0, 0.0], -0.03, _Z, [0.0, 0.0, 0.03], 0 * _EYE),           # the centre
    # ties inside: the first face of x, y, z; the + side of a mirror plane
    ('cube', [0.125, 0.125, 0.0], -0.125, _X, [0.25, 0.125, 0.0], 0 * _EYE),
    ('cube', [0.0, 0.0, 0.0], -0.25, _X, [0.25, 0.0, 0.0], 0 * _EYE),
    ('cube', [0.0, -0.125, 0.375], -0.125, -_Y, [0.0, -0.25, 0.375], 0 * _EYE),
    ('capsule', [0.0, 0.0, 0.01], -0.02, _X, [0.02, 0.0, 0.01], 0 * _EYE),       # on the axis
    ('cylinder', [0.0, 0.0, 0.0], -0.02, _X, [0.02, 0.0, 0.0], 0 * _EYE),        # on the axis
    ('cylinder', [0.0, 0.0, 0.05], 0.01, _Z, [0.0, 0.0, 0.04], 0 * _EYE),        # beyond a cap
]


@pytest.mark.parametrize('name, local, distance, normal, closest, hessian', _CHOICES)
def test_where_the_normal_is_not_unique_the_choice_is_fixed(name, local, distance, normal,
                                                            closest, hessian):
    """The centre of a sphere, ties of a box's faces, the axis of a capsule or cylinder."""
    got = _query(name, local, np.eye(3), np.zeros(3))
    assert got[0] == pytest.approx(distance, abs=1e-15)
    np.testing.assert_array_equal(got[1], normal)
    np.testing.assert_allclose(got[2], closest, atol=1e-15)
    np.testing.assert_array_equal(got[3], hessian)


@pytest.mark.parametrize('name, local, distance, normal, closest, hessian', _CLOSED_FORMS)
def test_each_primitive_matches_its_closed_form_at_a_rotated_pose(name, local, distance, normal,
                                                                  closest, hessian):
    """Distance, normal, closest point and Hessian at a rotated, shifted pose and unposed."""
    for rotation, position in ((_TURN, _AT), (np.eye(3), np.zeros(3))):
        got = _query(name, local, rotation, position)
        assert got[0] == pytest.approx(distance, abs=1e-15)
        np.testing.assert_allclose(got[1], rotation @ normal, atol=1e-15)
        np.testing.assert_allclose(got[2], rotation @ closest + position, atol=1e-15)
        np.testing.assert_allclose(got[3], rotation @ hessian @ rotation.T, atol=1e-10,
                                   rtol=1e-12)


def _surface_samples(name, count):
    """Return about ``count`` points of the primitive's surface, local frame (a dense net)."""
    shape, sizes = _PRIMITIVES[name]
    rng = np.random.default_rng(17)
    if shape == SPHERE:
        u = rng.standard_normal((count, 3))
        return sizes[0] * u / np.linalg.norm(u, axis=1, keepdims=True)
    if shape == BOX:
        half = 0.5 * np.array(sizes)
        points = rng.uniform(-half, half, size=(count, 3))
        axis = rng.integers(0, 3, count)
        points[np.arange(count), axis] = rng.choice([-1.0, 1.0], count) * half[axis]
        return points
    radius, half = sizes[0], 0.5 * sizes[1]
    angle = rng.uniform(0.0, 2.0 * np.pi, count)
    around = np.column_stack([np.cos(angle), np.sin(angle), np.zeros(count)])
    side = radius * around + np.outer(rng.uniform(-half, half, count), _Z)
    if shape == CAPSULE:
        u = rng.standard_normal((count, 3))
        ends = radius * u / np.linalg.norm(u, axis=1, keepdims=True)
        ends[:, 2] += np.where(ends[:, 2] < 0.0, -half, half)
        return np.concatenate([side, ends])
    caps = np.sqrt(rng.uniform(0.0, 1.0, count))[:, None] * radius * around
    caps[:, 2] = rng.choice([-half, half], count)
    return np.concatenate([side, caps])


def _inside(name, local):
    """Whether local points are in the solid (an independent membership test)."""
    shape, sizes = _PRIMITIVES[name]
    if shape == SPHERE:
        return np.linalg.norm(local, axis=1) < sizes[0]
    if shape == BOX:
        return np.all(np.abs(local) < 0.5 * np.array(sizes), axis=1)
    radius, half = sizes[0], 0.5 * sizes[1]
    if shape == CAPSULE:
        core = local - np.outer(np.clip(local[:, 2], -half, half), _Z)
        return np.linalg.norm(core, axis=1) < radius
    return (np.hypot(local[:, 0], local[:, 1]) < radius) & (np.abs(local[:, 2]) < half)


@pytest.mark.parametrize('name', ['sphere', 'box', 'capsule', 'cylinder'])
def test_no_surface_point_is_nearer_than_the_distance_and_the_sign_says_inside(name):
    """
    Against a dense net of each surface: the distance is the nearest surface point's.

    No sample of the surface lies nearer than ``|φ|`` (1e-12), the nearest is at most the net's
    spacing farther, the closest point lies on the surface and ``φ < 0`` exactly inside.
    """
    samples = _surface_samples(name, 60000)
    extent = np.max(np.abs(samples), axis=0)
    local = np.random.default_rng(5).uniform(-1.2 * extent, 1.2 * extent, size=(300, 3))
    queries = [_query(name, q, np.eye(3), np.zeros(3)) for q in local]
    distance = np.array([q[0] for q in queries])
    closest = np.array([q[2] for q in queries])
    nearest = np.array([np.min(np.linalg.norm(samples - q, axis=1)) for q in local])
    assert np.all(nearest >= np.abs(distance) - 1e-12)
    np.testing.assert_allclose(nearest, np.abs(distance), atol=1.5e-3)
    np.testing.assert_allclose(np.linalg.norm(closest - local, axis=1), np.abs(distance),
                               atol=1e-15)
    on_surface = [_query(name, c, np.eye(3), np.zeros(3))[0] for c in closest]
    np.testing.assert_allclose(on_surface, 0.0, atol=1e-15)
    assert np.array_equal(distance < 0.0, _inside(name, local))
    assert 0.1 < np.mean(distance < 0.0) < 0.9


@pytest.mark.parametrize('name', ['plane', 'sphere', 'box', 'capsule', 'cylinder'])
def test_normal_is_the_gradient_of_the_distance_and_the_hessian_its_derivative(name):
    """Central differences at a rotated pose, away from the seams where the Hessian jumps."""
    rng = np.random.default_rng(8)
    points = _AT + rng.uniform(-0.08, 0.08, size=(150, 3))
    shape, sizes = _PRIMITIVES[name]
    sizes = np.array(sizes)
    step = 1e-6

    def query(p):
        normal, closest, curvature = np.empty(3), np.empty(3), np.empty((3, 3))
        distance = signed_distance_at(shape, _AT, _TURN, sizes, p, normal, closest, curvature)
        return distance, normal, curvature

    smooth_count = 0
    for point in points:
        distance, normal, curvature = query(point)
        gradient, derivative, smooth = np.empty(3), np.empty((3, 3)), True
        for axis in range(3):
            ahead, behind = query(point + step * _EYE[axis]), query(point - step * _EYE[axis])
            gradient[axis] = (ahead[0] - behind[0]) / (2 * step)
            derivative[:, axis] = (ahead[1] - behind[1]) / (2 * step)
            smooth &= all(np.allclose(side[2], curvature, rtol=1e-2, atol=1e-6)
                          for side in (ahead, behind))
        assert np.linalg.norm(normal) == pytest.approx(1.0, abs=1e-15)
        np.testing.assert_allclose(curvature, curvature.T, atol=1e-12)
        if smooth:
            smooth_count += 1
            np.testing.assert_allclose(normal, gradient, atol=1e-7)
            np.testing.assert_allclose(curvature, derivative, atol=1e-5, rtol=1e-4)
    assert smooth_count > 0.95 * len(points)


def test_the_batched_entry_is_the_point_query_row_by_row():
    """``signed_distances_into`` writes what ``signed_distance_at`` gives each point."""
    rng = np.random.default_rng(2)
    points = _AT + rng.uniform(-0.06, 0.06, size=(40, 3))
    for shape, sizes in _PRIMITIVES.values():
        sizes = np.array(sizes)
        distance, normal = np.empty(40), np.empty((40, 3))
        closest, curvature = np.empty((40, 3)), np.empty((40, 3, 3))
        signed_distances_into(shape, _AT, _TURN, sizes, points, distance, normal, closest,
                              curvature)
        for i, point in enumerate(points):
            one_normal, one_closest, one_curvature = np.empty(3), np.empty(3), np.empty((3, 3))
            assert distance[i] == signed_distance_at(shape, _AT, _TURN, sizes, point, one_normal,
                                                     one_closest, one_curvature)
            assert np.array_equal(normal[i], one_normal)
            assert np.array_equal(closest[i], one_closest)
            assert np.array_equal(curvature[i], one_curvature)


def test_an_unknown_shape_code_is_refused():
    """A shape code outside 0..4 raises instead of writing anything."""
    with pytest.raises(ValueError, match='unknown obstacle shape'):
        signed_distance_at(5, _AT, _TURN, np.ones(3), _AT, np.empty(3), np.empty(3),
                           np.empty((3, 3)))


def _scene_obstacles():
    return (Obstacle('floor', 'plane', [0.0, 0.0, -0.08], np.eye(3)),
            Obstacle('ball', 'sphere', _AT, _TURN, radius=0.03),
            Obstacle('crate', 'box', [0.2, 0.0, 0.0], _TURN.T, size=(0.04, 0.06, 0.1)),
            Obstacle('pill', 'capsule', [0.1, 0.1, 0.0], np.eye(3), radius=0.02, length=0.0),
            Obstacle('post', 'cylinder', [0.2, 0.08, 0.0], _TURN, radius=0.015, length=0.3))


def test_packed_obstacles_round_trip_and_answer_as_the_obstacles():
    """Each packed row rebuilds its obstacle and gives its query bit for bit; none packs empty."""
    obstacles = _scene_obstacles()
    shapes, positions, rotations, sizes = pack_obstacles(obstacles)
    for array, shape, dtype in ((shapes, (5,), np.int64), (positions, (5, 3), np.float64),
                                (rotations, (5, 3, 3), np.float64), (sizes, (5, 3), np.float64)):
        assert array.shape == shape and array.dtype == dtype and array.flags.c_contiguous
    assert [SHAPES[code] for code in shapes] == [o.shape for o in obstacles]
    points = np.random.default_rng(4).uniform(-0.1, 0.3, size=(30, 3))
    for j, obstacle in enumerate(obstacles):
        shape = SHAPES[shapes[j]]
        keys = {'sphere': {'radius': sizes[j, 0]}, 'box': {'size': sizes[j]},
                'capsule': {'radius': sizes[j, 0], 'length': sizes[j, 1]},
                'cylinder': {'radius': sizes[j, 0], 'length': sizes[j, 1]}}.get(shape, {})
        rebuilt = Obstacle(obstacle.name, shape, positions[j], rotations[j], **keys)
        for key in ('position', 'rotation', 'sizes'):
            assert np.array_equal(getattr(rebuilt, key), getattr(obstacle, key))
        assert (rebuilt.radius, rebuilt.length) == (obstacle.radius, obstacle.length)
        expected = obstacle.signed_distance(points)
        for i, point in enumerate(points):
            normal, closest, curvature = np.empty(3), np.empty(3), np.empty((3, 3))
            assert signed_distance_at(shapes[j], positions[j], rotations[j], sizes[j], point,
                                      normal, closest, curvature) == expected.distance[i]
            assert np.array_equal(normal, expected.normal[i])
            assert np.array_equal(closest, expected.closest[i])
            assert np.array_equal(curvature, expected.curvature[i])
    empty = pack_obstacles(())
    assert [a.shape for a in empty] == [(0,), (0, 3), (0, 3, 3), (0, 3)]
    assert empty[0].dtype == np.int64 and all(a.flags.c_contiguous for a in empty)


def test_every_pair_of_points_and_packed_obstacles_is_the_obstacle_query():
    """The pairwise query's column ``j`` is obstacle ``j``'s own query, bit for bit."""
    obstacles = _scene_obstacles()
    points = np.random.default_rng(3).uniform(-0.1, 0.3, size=(12, 3))
    pairs = pairwise_signed_distance(pack_obstacles(obstacles), points)
    assert pairs.distance.shape == (12, 5) and pairs.curvature.shape == (12, 5, 3, 3)
    for j, obstacle in enumerate(obstacles):
        for pair, own in zip(pairs, obstacle.signed_distance(points)):
            assert np.array_equal(pair[:, j], own)
    # read-only or Fortran-ordered points are copied, not refused
    frozen = np.asfortranarray(points)
    frozen.flags.writeable = False
    for pair, own in zip(pairwise_signed_distance(pack_obstacles(obstacles), frozen), pairs):
        assert np.array_equal(pair, own)
    for frozen_own, own in zip(obstacles[2].signed_distance(frozen),
                               obstacles[2].signed_distance(points)):
        assert np.array_equal(frozen_own, own)
    nothing = pairwise_signed_distance(pack_obstacles(()), points)
    assert nothing.distance.shape == (12, 0) and nothing.normal.shape == (12, 0, 3)


@pytest.mark.parametrize('field, value, problem', [
    (0, np.array([1, 7]), 'shape codes'),
    (0, np.array([1.0, 2.0]), 'shapes must be'),
    (1, np.zeros((2, 2)), 'positions must be'),
    (2, np.zeros((2, 3, 3))[:, :, ::-1], 'rotations must be'),
    (3, np.zeros((3, 3)), 'sizes must be'),
])
def test_badly_packed_obstacles_are_refused(field, value, problem):
    """Arrays that are not what pack_obstacles gives raise a ValueError naming the array."""
    packed = list(pack_obstacles(_scene_obstacles()[1:3]))
    packed[field] = value
    with pytest.raises(ValueError, match=problem):
        pairwise_signed_distance(tuple(packed), np.zeros((1, 3)))
    with pytest.raises(ValueError, match='finite'):
        pairwise_signed_distance(pack_obstacles(()), [[0.0, np.inf, 0.0]])


@numba.njit(cache=False)
def _smallest_clearances(shapes, positions, rotations, sizes, centres, radii, clearances):
    """Compiled caller: the smallest gap of every sphere to the packed obstacles, per point."""
    normal, closest, curvature = np.empty(3), np.empty(3), np.empty((3, 3))
    for s in range(centres.shape[0]):
        clearances[s] = np.inf
        for j in range(shapes.size):
            distance = signed_distance_at(shapes[j], positions[j], rotations[j], sizes[j],
                                          centres[s], normal, closest, curvature)
            clearances[s] = min(clearances[s], distance - radii[s])


def test_compiled_code_calls_the_point_query_on_packed_obstacles():
    """A compiled loop over spheres and packed obstacles gives the obstacles' smallest gaps."""
    from cbha_inverse.core.obstacles import sphere_gaps
    obstacles = _scene_obstacles()
    rng = np.random.default_rng(6)
    centres, radii = rng.uniform(-0.1, 0.3, size=(25, 3)), rng.uniform(0.005, 0.03, 25)
    clearances = np.empty(25)
    _smallest_clearances(*pack_obstacles(obstacles), centres, radii, clearances)
    np.testing.assert_array_equal(clearances, sphere_gaps(obstacles, centres, radii).min(axis=1))


@pytest.mark.skipif(numba.config.DISABLE_JIT, reason='counts the compiled runtime allocations')
def test_the_compiled_query_allocates_nothing_of_its_own():
    """Count one runtime allocation per array passed from Python, none of the query's own."""
    obstacles = _scene_obstacles()
    rng = np.random.default_rng(1)
    points = rng.uniform(-0.1, 0.3, size=(20, 3))
    buffers = np.empty(20), np.empty((20, 3)), np.empty((20, 3)), np.empty((20, 3, 3))
    packed = pack_obstacles(obstacles)
    calls = []
    for j in range(len(obstacles)):
        arguments = (packed[0][j], packed[1][j], packed[2][j], packed[3][j], points, *buffers)
        signed_distances_into(*arguments)
        calls.append(arguments)
    _nrt_python.memsys_enable_stats()
    try:
        before = rtsys.get_allocation_stats()
        for arguments in calls:
            signed_distances_into(*arguments)
        after = rtsys.get_allocation_stats()
    finally:
        _nrt_python.memsys_disable_stats()
    arrays_passed = len(calls) * sum(isinstance(a, np.ndarray) for a in calls[0])
    assert after.alloc - before.alloc == arrays_passed
    assert after.free - before.free == arrays_passed
