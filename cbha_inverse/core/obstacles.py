"""
Obstacles: primitive solids posed in the base frame, and their signed distance.

An :class:`Obstacle` is a plane (a half-space), a sphere, an oriented box, a capsule or a
flat-capped cylinder, placed by a pose (position, rotation) in the scene's ``base_frame``
(``docs/obstacles.md``). Its shape is described in its own frame:

- ``plane``: the solid half-space ``z <= 0``; the free side is +z;
- ``sphere``: ``radius`` about the origin;
- ``box``: edge lengths ``size`` (x, y, z), centred at the origin;
- ``capsule``: the points within ``radius`` of the segment of ``length`` along z, centred at
  the origin (hemispherical ends);
- ``cylinder``: ``radius`` about the z axis, ``length`` between its flat caps, centred.

:meth:`Obstacle.signed_distance` is the package's one signed-distance query: for points
(the centres of the robot's collision spheres, :mod:`cbha_inverse.core.contact`) it returns the
distance to the surface (negative inside), the outward unit normal (the distance's gradient),
the closest point of the surface and the distance's Hessian (the derivative of the normal, for
exact contact tangents). The simulated plant's contact, ``cbha_scene check``'s clearance and the
obstacle rows of a controller use it. Its arithmetic is the compiled kernel
:func:`cbha_inverse.core._kernels.obstacles.signed_distance_at`, which compiled code calls per
point on the arrays of :func:`pack_obstacles`. No ROS.
"""

from dataclasses import dataclass, field
from typing import NamedTuple

from cbha_inverse.core._kernels.obstacles import (pairwise_signed_distances_into,
                                                  signed_distances_into)
import numpy as np

SHAPES = ('plane', 'sphere', 'box', 'capsule', 'cylinder')
"""The obstacle primitives."""

SHAPE_SIZES = {'plane': (), 'sphere': ('radius',), 'box': ('size',),
               'capsule': ('radius', 'length'), 'cylinder': ('radius', 'length')}
"""The size parameters each primitive takes (all in metres)."""

_ROTATION_TOLERANCE = 1e-6


class SignedDistance(NamedTuple):
    """
    The signed distance of N points to an obstacle's surface, with its first two derivatives.

    Attributes
    ----------
    distance : (N,) ndarray  [m]
        Distance to the surface, negative inside the solid.
    normal : (N, 3) ndarray
        Outward unit normal: the gradient of ``distance`` (base-frame axes).
    closest : (N, 3) ndarray  [m]
        The closest point of the surface (``point - distance * normal``).
    curvature : (N, 3, 3) ndarray  [1/m]
        The Hessian of ``distance``, ``d normal / d point`` (symmetric; zero on flat faces).

    """

    distance: np.ndarray
    normal: np.ndarray
    closest: np.ndarray
    curvature: np.ndarray


@dataclass(frozen=True, eq=False)
class Obstacle:
    """
    A primitive solid posed in the base frame (module docstring).

    Parameters
    ----------
    name : str
        Unique within a scene.
    shape : str
        One of :data:`SHAPES`.
    position : (3,) array_like  [m]
        Origin of the obstacle's frame in the base frame.
    rotation : (3, 3) array_like
        Axes of the obstacle's frame in the base frame (a rotation matrix).
    radius : float, optional  [m]
        Sphere, capsule, cylinder.
    length : float, optional  [m]
        Capsule (between its hemisphere centres, may be 0), cylinder (between its caps).
    size : (3,) array_like, optional  [m]
        Box edge lengths along its x, y, z.

    Attributes
    ----------
    shape_code : int
        The shape's index in :data:`SHAPES`, the compiled query's shape code
        (:mod:`cbha_inverse.core._kernels.obstacles`).
    sizes : (3,) ndarray  [m]
        The sizes as the compiled query takes them (read-only): the box's edges,
        ``(radius, length, 0)`` of a capsule or cylinder, ``(radius, 0, 0)`` of a sphere, zeros
        for a plane.

    Raises
    ------
    ValueError
        On an unknown shape, a missing, extra, non-finite or non-positive size, a non-finite
        position or a rotation that is not one.

    """

    name: str
    shape: str
    position: np.ndarray
    rotation: np.ndarray
    radius: float = None
    length: float = None
    size: np.ndarray = None
    shape_code: int = field(init=False, repr=False)
    sizes: np.ndarray = field(init=False, repr=False)

    def __post_init__(self):
        """Check the shape, its sizes and the pose; store them as floats."""
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f'an obstacle needs a non-empty name, got {self.name!r}')
        where = f'obstacle {self.name!r}'
        if self.shape not in SHAPES:
            raise ValueError(f'{where}: unknown shape {self.shape!r} (one of {list(SHAPES)})')
        position = np.array(self.position, dtype=float)
        rotation = np.array(self.rotation, dtype=float)
        if position.shape != (3,) or not np.all(np.isfinite(position)):
            raise ValueError(f'{where}: position must be 3 finite numbers')
        if (rotation.shape != (3, 3) or not np.all(np.isfinite(rotation))
                or not np.allclose(rotation.T @ rotation, np.eye(3), atol=_ROTATION_TOLERANCE)
                or np.linalg.det(rotation) <= 0.0):
            raise ValueError(f'{where}: rotation must be a 3 x 3 rotation matrix')
        position.flags.writeable = rotation.flags.writeable = False
        object.__setattr__(self, 'position', position)
        object.__setattr__(self, 'rotation', rotation)
        wanted = SHAPE_SIZES[self.shape]
        for key in ('radius', 'length', 'size'):
            value = getattr(self, key)
            if key not in wanted:
                if value is not None:
                    raise ValueError(f'{where}: a {self.shape} takes no {key}')
                continue
            if value is None:
                raise ValueError(f'{where}: a {self.shape} needs its {key}')
            checked = np.array(value, dtype=float)
            if checked.shape != ((3,) if key == 'size' else ()) or not np.all(
                    np.isfinite(checked)):
                raise ValueError(f'{where}: {key} must be '
                                 + ('3 finite numbers' if key == 'size' else 'a finite number'))
            low_ok = checked >= 0.0 if (key == 'length' and self.shape == 'capsule') else (
                checked > 0.0)
            if not np.all(low_ok):
                raise ValueError(f'{where}: {key} must be '
                                 + ('>= 0' if self.shape == 'capsule' and key == 'length'
                                    else '> 0') + f', got {checked.tolist()}')
            if key == 'size':
                checked.flags.writeable = False
                object.__setattr__(self, key, checked)
            else:
                object.__setattr__(self, key, float(checked))
        object.__setattr__(self, 'shape_code', SHAPES.index(self.shape))
        object.__setattr__(self, 'sizes', _kernel_sizes(self))

    def signed_distance(self, points):
        """
        Return the signed distance of points to the surface, its normal, closest point, Hessian.

        Parameters
        ----------
        points : (N, 3) array_like  [m]
            Base-frame points (a single (3,) point is taken as N = 1).

        Returns
        -------
        SignedDistance
            Per point: distance (negative inside), outward unit normal, closest surface point,
            Hessian of the distance. Where the normal is not unique (the centre of a sphere,
            the axis of a capsule or a cylinder, the middle of a box) one of the candidates is
            returned, chosen deterministically.

        Raises
        ------
        ValueError
            If ``points`` is not (N, 3) or not finite.

        """
        p = _checked_points(points)
        n = p.shape[0]
        query = SignedDistance(np.empty(n), np.empty((n, 3)), np.empty((n, 3)),
                               np.empty((n, 3, 3)))
        signed_distances_into(self.shape_code, self.position, self.rotation, self.sizes, p,
                              *query)
        return query

    def describe(self):
        """Return one line naming the obstacle, its shape, sizes [mm] and position [mm]."""
        sizes = []
        for key in SHAPE_SIZES[self.shape]:
            value = np.atleast_1d(getattr(self, key)) * 1e3
            sizes.append(f'{key} ' + ' x '.join(f'{v:.1f}' for v in value) + ' mm')
        at = ', '.join(f'{v * 1e3:.1f}' for v in self.position)
        return f'{self.name}: {self.shape}' + (f' {", ".join(sizes)}' if sizes else '') + \
            f' at ({at}) mm'


def obstacle_from_rpy(name, shape, position, rpy, **sizes):
    """
    Build an obstacle from its position and roll, pitch, yaw (the scene file's pose).

    Parameters
    ----------
    name, shape : str
        As :class:`Obstacle`.
    position : (3,) array_like  [m]
        Origin of the obstacle frame in the base frame.
    rpy : (3,) array_like  [rad]
        Roll, pitch, yaw about the fixed axes (:func:`cbha_inverse.core.so3.so3_from_rpy`).
    **sizes
        ``radius``, ``length``, ``size`` as the shape takes them.

    Returns
    -------
    Obstacle

    """
    from cbha_inverse.core.so3 import so3_from_rpy
    rpy = np.asarray(rpy, dtype=float)
    if rpy.shape != (3,) or not np.all(np.isfinite(rpy)):
        raise ValueError(f'obstacle {name!r}: rpy must be 3 finite numbers')
    return Obstacle(name, shape, position, so3_from_rpy(rpy), **sizes)


def pairwise_signed_distance(packed, points, check=True):
    """
    Return the signed distance of every point to every obstacle of :func:`pack_obstacles`.

    Parameters
    ----------
    packed : tuple of 4 ndarray
        ``pack_obstacles(obstacles)`` of ``o`` obstacles.
    points : (N, 3) array_like  [m]
        Base-frame points (a single (3,) point is taken as N = 1).
    check : bool
        Check ``packed`` and ``points``. A caller that queries the same obstacles often (the
        plant's contact, :mod:`cbha_inverse.core.contact`) checks them once and passes False,
        with read-only views of the packed arrays (:func:`read_only_packed`) and finite,
        C-contiguous, writable (N, 3) float points.

    Returns
    -------
    SignedDistance
        Of point ``i`` to obstacle ``j`` at ``[i, j]``: distance (N, o), normal (N, o, 3),
        closest (N, o, 3), curvature (N, o, 3, 3), as :meth:`Obstacle.signed_distance`.

    Raises
    ------
    ValueError
        If ``points`` is not (N, 3) or not finite, or ``packed`` not arrays as
        :func:`pack_obstacles` gives them.

    """
    if check:
        points = _checked_points(points)
        packed = read_only_packed(packed)
    shapes = packed[0]
    n, o = points.shape[0], shapes.shape[0]
    query = SignedDistance(np.empty((n, o)), np.empty((n, o, 3)), np.empty((n, o, 3)),
                           np.empty((n, o, 3, 3)))
    pairwise_signed_distances_into(*packed, points, *query)
    return query


def read_only_packed(packed):
    """
    Return read-only views of the arrays of :func:`pack_obstacles`, checked.

    The compiled query then sees the same array types as from an :class:`Obstacle` (one
    compiled copy of it).

    Parameters
    ----------
    packed : tuple of 4 ndarray
        ``(shapes, positions, rotations, sizes)`` of ``o`` obstacles.

    Returns
    -------
    tuple of 4 ndarray
        The same arrays, read-only.

    Raises
    ------
    ValueError
        If an array is not C-contiguous of its dtype and shape, or a shape code is unknown.

    """
    shapes = packed[0]
    o = shapes.shape[0] if isinstance(shapes, np.ndarray) and shapes.ndim == 1 else -1
    for name, array, shape, dtype in zip(('shapes', 'positions', 'rotations', 'sizes'), packed,
                                         ((o,), (o, 3), (o, 3, 3), (o, 3)),
                                         (np.int64, np.float64, np.float64, np.float64)):
        if not (isinstance(array, np.ndarray) and array.shape == shape and array.dtype == dtype
                and array.flags.c_contiguous):
            raise ValueError(f'packed obstacles: {name} must be a C-contiguous {shape} '
                             f'{np.dtype(dtype).name} array (pack_obstacles)')
    if np.any((shapes < 0) | (shapes >= len(SHAPES))):
        raise ValueError(f'packed obstacles: shape codes must be 0..{len(SHAPES) - 1}')
    return tuple(_read_only(array) for array in packed)


def sphere_gaps(obstacles, centres, radii):
    """
    Return the gap between spheres and each obstacle: signed distance of the centre minus radius.

    Parameters
    ----------
    obstacles : sequence of Obstacle
        The obstacles.
    centres : (N, 3) array_like  [m]
        Sphere centres, base frame.
    radii : (N,) array_like  [m]
        Sphere radii.

    Returns
    -------
    (N, len(obstacles)) ndarray  [m]
        Negative where a sphere penetrates an obstacle.

    """
    radii = np.asarray(radii, dtype=float).reshape(-1)
    return pairwise_signed_distance(pack_obstacles(obstacles), centres).distance - radii[:, None]


def pack_obstacles(obstacles):
    """
    Return the obstacles as the arrays the compiled signed distance takes, one row each.

    Parameters
    ----------
    obstacles : sequence of Obstacle
        The obstacles (``o`` of them, possibly none).

    Returns
    -------
    shapes : (o,) int64 ndarray
        Shape codes (:attr:`Obstacle.shape_code`, the index in :data:`SHAPES`).
    positions : (o, 3) ndarray  [m]
        Origins of the obstacles' frames, base frame.
    rotations : (o, 3, 3) ndarray
        Their axes as columns, base frame.
    sizes : (o, 3) ndarray  [m]
        :attr:`Obstacle.sizes`.

    All C-contiguous and writable (copies): row ``j`` passed to
    :func:`cbha_inverse.core._kernels.obstacles.signed_distance_at` is obstacle ``j``'s query.

    """
    obstacles = tuple(obstacles)
    count = len(obstacles)
    shapes = np.array([o.shape_code for o in obstacles], dtype=np.int64).reshape(count)
    positions = np.array([o.position for o in obstacles], dtype=float).reshape(count, 3)
    rotations = np.array([o.rotation for o in obstacles], dtype=float).reshape(count, 3, 3)
    sizes = np.array([o.sizes for o in obstacles], dtype=float).reshape(count, 3)
    return shapes, positions, rotations, sizes


def check_names(obstacles):
    """Raise ``ValueError`` if two obstacles share a name; return them as a tuple."""
    obstacles = tuple(obstacles)
    names = [o.name for o in obstacles]
    for name in names:
        if names.count(name) > 1:
            raise ValueError(f'obstacle {name!r} named twice')
    return obstacles


def _kernel_sizes(obstacle):
    """Return an obstacle's sizes as the kernel takes them, (3,) read-only [m]."""
    sizes = np.zeros(3)
    if obstacle.shape == 'box':
        sizes[:] = obstacle.size
    elif obstacle.shape != 'plane':
        sizes[0] = obstacle.radius
        if obstacle.shape != 'sphere':
            sizes[1] = obstacle.length
    sizes.flags.writeable = False
    return sizes


def _checked_points(points):
    """Return points as a C-contiguous, writable (N, 3) float array, or raise ``ValueError``."""
    p = np.asarray(points, dtype=float)
    if p.ndim == 1:
        p = p[None, :]
    if p.ndim != 2 or p.shape[1] != 3:
        raise ValueError(f'points must be (N, 3), got shape {np.shape(points)}')
    if not np.isfinite(p).all():
        raise ValueError('points must be finite')
    if not (p.flags.c_contiguous and p.flags.writeable):
        # one compiled signature: C-contiguous, writable points
        p = np.array(p, order='C')
    return p


def _read_only(array):
    """Return a read-only view of an array."""
    view = array.view()
    view.flags.writeable = False
    return view
