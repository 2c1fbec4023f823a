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
obstacle rows of a controller use it. No ROS, no numba: a handful of numpy operations per
obstacle and query.
"""

from dataclasses import dataclass
from typing import NamedTuple

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
        p = np.asarray(points, dtype=float)
        if p.ndim == 1:
            p = p[None, :]
        if p.ndim != 2 or p.shape[1] != 3:
            raise ValueError(f'points must be (N, 3), got shape {np.shape(points)}')
        if not np.all(np.isfinite(p)):
            raise ValueError('points must be finite')
        local = (p - self.position) @ self.rotation
        distance, normal, closest, curvature = _LOCAL[self.shape](self, local)
        r = self.rotation
        return SignedDistance(distance, normal @ r.T, closest @ r.T + self.position,
                              r @ curvature @ r.T)

    def near(self, points, reach):
        """
        Return which points may lie within ``reach`` of the solid (a cheap conservative test).

        Parameters
        ----------
        points : (N, 3) ndarray  [m]
            Base-frame points.
        reach : (N,) ndarray or float  [m]
            How far from the solid a point counts as near.

        Returns
        -------
        (N,) bool ndarray
            False only where the point is farther than ``reach`` from the solid (its bounding
            box, or the capsule holding a cylinder).

        """
        if self.shape == 'plane':
            return np.ones(len(points), dtype=bool)
        q = (np.asarray(points, dtype=float) - self.position) @ self.rotation
        if self.shape == 'box':
            return np.all(np.abs(q) <= 0.5 * self.size + np.reshape(reach, (-1, 1)), axis=1)
        if self.shape != 'sphere':
            half = 0.5 * self.length
            q[:, 2] -= np.clip(q[:, 2], -half, half)
        return np.einsum('ij,ij->i', q, q) <= (self.radius + reach) ** 2

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
    gaps = np.empty((radii.size, len(obstacles)))
    for j, obstacle in enumerate(obstacles):
        gaps[:, j] = obstacle.signed_distance(centres).distance - radii
    return gaps


def check_names(obstacles):
    """Raise ``ValueError`` if two obstacles share a name; return them as a tuple."""
    obstacles = tuple(obstacles)
    names = [o.name for o in obstacles]
    for name in names:
        if names.count(name) > 1:
            raise ValueError(f'obstacle {name!r} named twice')
    return obstacles


def _unit_or(vectors, lengths, fallback):
    """Return ``vectors / lengths`` row-wise, ``fallback`` where the length is zero."""
    out = np.empty_like(vectors)
    zero = lengths <= 0.0
    np.divide(vectors, np.where(zero, 1.0, lengths)[:, None], out=out)
    out[zero] = fallback
    return out


def _outer(a, b):
    """Return the batched outer products ``a bᵀ`` (N, 3, 3)."""
    return a[:, :, None] * b[:, None, :]


def _plane(obstacle, q):
    """Half-space ``z <= 0``: distance z, normal +z, flat."""
    n = q.shape[0]
    normal = np.zeros((n, 3))
    normal[:, 2] = 1.0
    closest = q.copy()
    closest[:, 2] = 0.0
    return q[:, 2].copy(), normal, closest, np.zeros((n, 3, 3))


def _sphere(obstacle, q):
    """Sphere of ``radius``: distance ``|q| - r``, Hessian ``(I - n nᵀ) / |q|``."""
    rho = np.linalg.norm(q, axis=1)
    normal = _unit_or(q, rho, (0.0, 0.0, 1.0))
    safe = np.where(rho > 0.0, rho, np.inf)
    curvature = (np.eye(3) - _outer(normal, normal)) / safe[:, None, None]
    return rho - obstacle.radius, normal, obstacle.radius * normal, curvature


def _box(obstacle, q):
    """
    Box of half edges ``h``: outside, the distance to the clamped point; inside, the nearest face.

    Outside, ``u = sign(q) max(|q| - h, 0)`` joins the closest point to ``q``: distance ``|u|``,
    normal ``u / |u|``, Hessian ``(D - n nᵀ) / |u|`` with ``D`` the projector on the axes where
    ``|q| > h`` (zero on a face, the curvature of a rounded edge or corner otherwise).
    """
    half = 0.5 * obstacle.size
    excess = np.abs(q) - half
    sign = np.where(q < 0.0, -1.0, 1.0)
    outside = np.any(excess > 0.0, axis=1)
    n = q.shape[0]
    distance, normal = np.empty(n), np.zeros((n, 3))
    closest, curvature = np.clip(q, -half, half), np.zeros((n, 3, 3))
    if np.any(outside):
        u = sign[outside] * np.maximum(excess[outside], 0.0)
        length = np.linalg.norm(u, axis=1)
        unit = u / length[:, None]
        active = np.zeros((unit.shape[0], 3, 3))
        active[:, [0, 1, 2], [0, 1, 2]] = excess[outside] > 0.0
        distance[outside] = length
        normal[outside] = unit
        curvature[outside] = (active - _outer(unit, unit)) / length[:, None, None]
    inside = ~outside
    if np.any(inside):
        face = np.argmax(excess[inside], axis=1)
        rows = np.flatnonzero(inside)
        distance[inside] = excess[rows, face]
        normal[rows, face] = sign[rows, face]
        closest[rows, face] = sign[rows, face] * half[face]
    return distance, normal, closest, curvature


def _capsule(obstacle, q):
    """
    Capsule: distance to the axis segment minus ``radius``.

    With ``p`` the closest point of the segment and ``u = q - p``: normal ``u / |u|``, Hessian
    ``(D - n nᵀ) / |u|``, ``D = I - e_z e_zᵀ`` beside the segment, ``I`` beyond its ends.
    """
    half = 0.5 * obstacle.length
    axial = np.clip(q[:, 2], -half, half)
    u = q.copy()
    u[:, 2] -= axial
    rho = np.linalg.norm(u, axis=1)
    normal = _unit_or(u, rho, (1.0, 0.0, 0.0))
    beside = np.abs(q[:, 2]) < half
    active = np.tile(np.eye(3), (q.shape[0], 1, 1))
    active[beside, 2, 2] = 0.0
    safe = np.where(rho > 0.0, rho, np.inf)
    curvature = (active - _outer(normal, normal)) / safe[:, None, None]
    closest = obstacle.radius * normal
    closest[:, 2] += axial
    return rho - obstacle.radius, normal, closest, curvature


def _cylinder(obstacle, q):
    """
    Flat-capped cylinder: the box query in (radial distance, axial coordinate).

    ``a = (s - r, |z| - l/2)`` with ``s`` the distance from the axis. Outside, the distance is
    ``|max(a, 0)|`` along ``u = max(a_0, 0) e_s + max(a_1, 0) sign(z) e_z``; inside, the larger
    of ``a``. The Hessian is that of the 2D query plus the turn of the radial direction,
    ``(n · e_s) / s e_t e_tᵀ`` (``e_t = e_z x e_s``).
    """
    radius, half = obstacle.radius, 0.5 * obstacle.length
    s = np.hypot(q[:, 0], q[:, 1])
    radial = _unit_or(np.column_stack([q[:, 0], q[:, 1], np.zeros_like(s)]), s,
                      (1.0, 0.0, 0.0))
    axis = np.array([0.0, 0.0, 1.0])
    tangent = np.column_stack([-radial[:, 1], radial[:, 0], np.zeros_like(s)])
    sign = np.where(q[:, 2] < 0.0, -1.0, 1.0)
    a_radial, a_axial = s - radius, np.abs(q[:, 2]) - half
    outside = (a_radial > 0.0) | (a_axial > 0.0)
    u_radial, u_axial = np.maximum(a_radial, 0.0), np.maximum(a_axial, 0.0)
    length = np.hypot(u_radial, u_axial)
    # inside: the nearer of the side and the cap
    side = ~outside & (a_radial >= a_axial)
    distance = np.where(outside, length, np.maximum(a_radial, a_axial))
    # the normal's components along e_s and sign(z) e_z
    scale = np.where(outside, length, 1.0)
    w_radial = np.where(outside, u_radial / scale, np.where(side, 1.0, 0.0))
    w_axial = np.where(outside, u_axial / scale, np.where(side, 0.0, 1.0))
    normal = w_radial[:, None] * radial + (w_axial * sign)[:, None] * axis
    closest_radial = np.where(side, radius, np.minimum(s, radius))
    closest_axial = np.where(~outside & ~side, sign * half, np.clip(q[:, 2], -half, half))
    closest = closest_radial[:, None] * radial + closest_axial[:, None] * axis
    active = (_outer(radial, radial) * (a_radial > 0.0)[:, None, None]
              + np.outer(axis, axis)[None] * (a_axial > 0.0)[:, None, None])
    safe_length = np.where(outside, length, np.inf)
    curvature = (active - _outer(normal, normal)) / safe_length[:, None, None]
    curvature[~outside] = 0.0
    safe_s = np.where(s > 0.0, s, np.inf)
    curvature += (w_radial / safe_s)[:, None, None] * _outer(tangent, tangent)
    return distance, normal, closest, curvature


_LOCAL = {'plane': _plane, 'sphere': _sphere, 'box': _box, 'capsule': _capsule,
          'cylinder': _cylinder}
