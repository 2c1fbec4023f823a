"""
Obstacles and contacts as ROS messages: ``visualization_msgs/MarkerArray`` both ways.

The ``obstacles`` topic carries the obstacles as RViz markers (``docs/obstacles.md``): what an
RViz user already draws a scene with, what any node publishes without a custom interface, and
what RViz shows as it is sent. :func:`obstacles_from_markers` reads one message as the whole
obstacle set:

- ``SPHERE`` (scale x = y = z, the diameter) is a sphere, ``CUBE`` (scale: the edges) a box,
  ``CYLINDER`` (scale x = y, the diameter; z, the length between the caps) a cylinder, each
  posed by the marker's pose, in the marker's ``header.frame_id``, which must be the base frame;
  its name is ``ns/id``;
- ``DELETE`` and ``DELETEALL`` markers add nothing (an empty array, or one ``DELETEALL``,
  removes every obstacle);
- a marker of another type (an ellipsoid, a mesh, a line...), a non-finite or non-positive
  scale, a non-finite pose, a zero quaternion, another frame or two markers of one ``ns/id``
  reject the whole message, with the reason's key and a line naming the marker.

Planes and capsules have no marker type: they come from the scene file. :func:`obstacle_markers`
draws any obstacle (a plane as a 2 m square tile 1 mm thick, its top on the plane; a capsule as
a cylinder and two spheres), :func:`contact_markers` the contact points and each contact force
as an arrow, :func:`contact_array` the contacts as numbers.
"""

import math

from cbha_inverse.core.obstacles import check_names, Obstacle
from cbha_inverse.core.so3 import matrix_from_quat, quat_from_matrix
from cbha_inverse.ros.common.conversions import plain_marker
from geometry_msgs.msg import Point
import numpy as np
from std_msgs.msg import Float64MultiArray, MultiArrayDimension
from visualization_msgs.msg import Marker, MarkerArray

CONTACT_COLUMNS = ('frame', 'point_x', 'point_y', 'point_z', 'normal_x', 'normal_y', 'normal_z',
                   'penetration', 'force_x', 'force_y', 'force_z')
"""The columns of a :func:`contact_array` row (m, N in the base frame)."""

PLANE_TILE = 2.0
"""Edge [m] of the square tile that draws a plane."""

_SHAPE_OF_MARKER = {Marker.SPHERE: 'sphere', Marker.CUBE: 'box', Marker.CYLINDER: 'cylinder'}
_SAME_SCALE = 1e-9


def _reject(key, detail):
    """Return the result of a rejected message."""
    return None, key, detail


def obstacles_from_markers(message, frame_id):
    """
    Return the obstacles of a MarkerArray (module docstring), or why it is rejected.

    Parameters
    ----------
    message : visualization_msgs.msg.MarkerArray
        The ``obstacles`` message.
    frame_id : str
        The base frame every marker must be given in.

    Returns
    -------
    obstacles : tuple of cbha_inverse.core.obstacles.Obstacle or None
        None when rejected.
    key : str or None
        ``'unknown_shape'``, ``'non_finite'``, ``'bad_size'``, ``'bad_orientation'``,
        ``'wrong_frame'`` or ``'duplicate'``; None when accepted.
    detail : str
        What is wrong ('' when accepted).

    """
    obstacles = []
    for marker in message.markers:
        if marker.action in (Marker.DELETE, Marker.DELETEALL):
            continue
        name = f'{marker.ns}/{marker.id}'
        shape = _SHAPE_OF_MARKER.get(marker.type)
        if shape is None:
            return _reject('unknown_shape', f'marker {name}: type {marker.type} is no obstacle '
                           '(SPHERE, CUBE or CYLINDER)')
        if marker.header.frame_id != frame_id:
            return _reject('wrong_frame', f'marker {name}: frame_id '
                           f'{marker.header.frame_id!r}, expected {frame_id!r}')
        p, q, s = marker.pose.position, marker.pose.orientation, marker.scale
        position, quaternion = [p.x, p.y, p.z], np.array([q.x, q.y, q.z, q.w])
        scale = [s.x, s.y, s.z]
        if not all(math.isfinite(v) for v in [*position, *quaternion, *scale]):
            return _reject('non_finite', f'marker {name}: non-finite pose or scale')
        if min(scale) <= 0.0:
            return _reject('bad_size', f'marker {name}: scale {scale} must be > 0')
        norm = float(np.linalg.norm(quaternion))
        if norm < 1e-6:
            return _reject('bad_orientation', f'marker {name}: zero quaternion')
        rotation = matrix_from_quat(quaternion / norm)
        if shape == 'sphere' and not _equal(s.x, s.y, s.z):
            return _reject('unknown_shape', f'marker {name}: an ellipsoid (scale {scale}) is no '
                           'obstacle: give a sphere x = y = z')
        if shape == 'cylinder' and not _equal(s.x, s.y):
            return _reject('unknown_shape', f'marker {name}: an elliptic cylinder (scale '
                           f'{scale}) is no obstacle: give x = y')
        sizes = ({'radius': 0.5 * s.x} if shape == 'sphere' else {'size': scale}
                 if shape == 'box' else {'radius': 0.5 * s.x, 'length': s.z})
        obstacles.append(Obstacle(name, shape, position, rotation, **sizes))
    try:
        return check_names(obstacles), None, ''
    except ValueError as exc:
        return _reject('duplicate', str(exc))


def _equal(*values):
    """Return whether the values agree to a relative ``_SAME_SCALE``."""
    return max(values) - min(values) <= _SAME_SCALE * max(values)


def _posed(item, position, rotation):
    """Set a marker's pose from a position (3,) and a rotation matrix."""
    item.pose.position.x, item.pose.position.y, item.pose.position.z = map(float, position)
    x, y, z, w = quat_from_matrix(rotation)
    item.pose.orientation.x, item.pose.orientation.y = float(x), float(y)
    item.pose.orientation.z, item.pose.orientation.w = float(z), float(w)
    return item


def _scaled(item, x, y, z):
    item.scale.x, item.scale.y, item.scale.z = float(x), float(y), float(z)
    return item


def obstacle_markers(obstacles, stamp, frame_id, rgba=(0.55, 0.45, 0.35, 0.6)):
    """
    Draw obstacles as RViz markers, after a ``DELETEALL`` (the array replaces the last one).

    Parameters
    ----------
    obstacles : sequence of cbha_inverse.core.obstacles.Obstacle
        The obstacles.
    stamp : builtin_interfaces.msg.Time
        Header stamp.
    frame_id : str
        The base frame.
    rgba : tuple of 4 floats
        Their colour.

    Returns
    -------
    visualization_msgs.msg.MarkerArray
        Namespace ``obstacles``, one id per marker; a sphere, box or cylinder as the marker of
        that type, a plane as a :data:`PLANE_TILE` tile (1 mm thick, its top on the plane), a
        capsule as a cylinder and two spheres.

    """
    clear = Marker()
    clear.action = Marker.DELETEALL
    markers = [clear]

    def add(kind, position, rotation, scale):
        item = plain_marker(stamp, frame_id, 'obstacles', len(markers), kind, rgba)
        markers.append(_scaled(_posed(item, position, rotation), *scale))

    for obstacle in obstacles:
        r, c = obstacle.rotation, obstacle.position
        if obstacle.shape == 'plane':
            add(Marker.CUBE, c - 0.0005 * r[:, 2], r, (PLANE_TILE, PLANE_TILE, 0.001))
        elif obstacle.shape == 'sphere':
            add(Marker.SPHERE, c, r, (2 * obstacle.radius,) * 3)
        elif obstacle.shape == 'box':
            add(Marker.CUBE, c, r, obstacle.size)
        else:
            diameter = 2 * obstacle.radius
            add(Marker.CYLINDER, c, r, (diameter, diameter, max(obstacle.length, 1e-6)))
            if obstacle.shape == 'capsule':
                for end in (-0.5, 0.5):
                    add(Marker.SPHERE, c + end * obstacle.length * r[:, 2], r, (diameter,) * 3)
    return MarkerArray(markers=markers)


CONTACT_POINTS = 'contact_points'
"""Namespace of the marker of the contact points (one SPHERE_LIST, id 0)."""

CONTACT_POINT_DIAMETER = 0.004
"""Diameter [m] of a drawn contact point."""


def contact_markers(contacts, stamp, frame_id, metres_per_newton):
    """
    Draw the contact points and each contact force as an arrow from its point, after a DELETEALL.

    Parameters
    ----------
    contacts : cbha_inverse.core.contact.Contacts
        The plant's contacts.
    stamp : builtin_interfaces.msg.Time
        Header stamp.
    frame_id : str
        The base frame.
    metres_per_newton : float  [m/N]
        Arrow length per newton.

    Returns
    -------
    visualization_msgs.msg.MarkerArray
        One ARROW per contact, namespace the obstacle's name, id the sphere's frame; with any
        contact, one SPHERE_LIST of the contact points (namespace :data:`CONTACT_POINTS`, id 0,
        the points in the order of ``contacts``).

    """
    clear = Marker()
    clear.action = Marker.DELETEALL
    markers = [clear]
    for frame, name, point, force in zip(contacts.frames, contacts.obstacles, contacts.points,
                                         contacts.forces):
        item = plain_marker(stamp, frame_id, name, int(frame), Marker.ARROW,
                            (1.0, 0.2, 0.1, 1.0))
        item.pose.orientation.w = 1.0
        tip = point + metres_per_newton * force
        item.points = [Point(x=float(point[0]), y=float(point[1]), z=float(point[2])),
                       Point(x=float(tip[0]), y=float(tip[1]), z=float(tip[2]))]
        markers.append(_scaled(item, 0.003, 0.006, 0.006))   # shaft and head diameters [m]
    if contacts.frames.size:
        item = plain_marker(stamp, frame_id, CONTACT_POINTS, 0, Marker.SPHERE_LIST,
                            (1.0, 0.9, 0.1, 1.0))
        item.pose.orientation.w = 1.0
        item.points = [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in contacts.points]
        markers.append(_scaled(item, *(CONTACT_POINT_DIAMETER,) * 3))
    return MarkerArray(markers=markers)


def contact_array(contacts):
    """
    Return the contacts as a Float64MultiArray: one row of :data:`CONTACT_COLUMNS` per contact.

    Parameters
    ----------
    contacts : cbha_inverse.core.contact.Contacts
        The plant's contacts.

    Returns
    -------
    std_msgs.msg.Float64MultiArray
        Row-major (c, 11), dimensions labelled ``contacts`` and ``frame,point_x,...``.

    """
    rows = np.column_stack([contacts.frames.astype(float), contacts.points, contacts.normals,
                            contacts.penetrations, contacts.forces]).reshape(-1, 11)
    message = Float64MultiArray()
    count, width = rows.shape
    message.layout.dim = [
        MultiArrayDimension(label='contacts', size=count, stride=count * width),
        MultiArrayDimension(label=','.join(CONTACT_COLUMNS), size=width, stride=width)]
    message.data = rows.reshape(-1).tolist()
    return message
