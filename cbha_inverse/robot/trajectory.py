"""
Reference paths for the tip: circle, square and waypoint polylines at constant speed.

Pure numpy, no ROS. A path is parametrised by its arc length ``s`` [m]; the time law is
``s(t) = speed * (t - start_hold)`` (clamped at 0 before the start), so every path is traversed at
constant speed along the path. The paper's experiments (Bosman et al. 2015, section V) use a circle
of radius 60 mm at 2.5 cm/s and a square of side 80 mm at 3.1 cm/s in the y-z plane of the base.

Conventions: positions in metres, (N, 3) batch-first, ``plane`` names the two base axes that span
the path (``'yz'``: first axis +y, second axis +z); circles and squares run counter-clockwise
about the plane normal ``u x v`` and start at ``center + half_extent * u``.
"""

from dataclasses import dataclass
import math

import numpy as np

_AXES = {'x': np.array([1.0, 0.0, 0.0]), 'y': np.array([0.0, 1.0, 0.0]),
         'z': np.array([0.0, 0.0, 1.0])}
PLANES = ('xy', 'yz', 'zx', 'yx', 'zy', 'xz')
SHAPES = ('circle', 'square', 'waypoints')


def plane_axes(plane):
    """
    Return the two unit vectors that span a named coordinate plane.

    Parameters
    ----------
    plane : str
        Two distinct letters from ``x``, ``y``, ``z``, e.g. ``'yz'`` (first axis, second axis).

    Returns
    -------
    u, v : (3,) ndarray
        The first and the second in-plane axis (orthonormal).

    Raises
    ------
    ValueError
        If ``plane`` is not one of ``PLANES``.

    """
    if not isinstance(plane, str) or plane.lower() not in PLANES:
        raise ValueError(f'plane must be one of {PLANES}, got {plane!r}')
    plane = plane.lower()
    return _AXES[plane[0]].copy(), _AXES[plane[1]].copy()


def _finite_vector(value, name, size=3):
    array = np.asarray(value, dtype=float)
    if array.shape != (size,):
        raise ValueError(f'{name} must have {size} components, got shape {array.shape}')
    if not np.all(np.isfinite(array)):
        raise ValueError(f'{name} must be finite, got {array.tolist()}')
    return array


def _positive(value, name):
    value = float(value)
    if not math.isfinite(value) or value <= 0.0:
        raise ValueError(f'{name} must be a finite number > 0, got {value}')
    return value


def circle_points(center, radius, plane, arc_length):
    """
    Return points of a circle at given arc lengths (counter-clockwise about ``u x v``).

    ``p(s) = c + r (cos(s / r) u + sin(s / r) v)``.

    Parameters
    ----------
    center : (3,) array_like  [m]
        Circle centre.
    radius : float  [m]
        Radius (> 0).
    plane : str
        Plane name, see :func:`plane_axes`.
    arc_length : (N,) array_like  [m]
        Arc lengths from the start point ``c + r u``.

    Returns
    -------
    (N, 3) ndarray  [m]
        The points.

    """
    center = _finite_vector(center, 'center')
    radius = _positive(radius, 'radius')
    u_axis, v_axis = plane_axes(plane)
    angle = np.atleast_1d(np.asarray(arc_length, dtype=float)) / radius
    return (center + radius * (np.cos(angle)[:, None] * u_axis
                               + np.sin(angle)[:, None] * v_axis))


def square_vertices(center, side, plane):
    """
    Return the closed vertex list of a square path, starting at the middle of its +u side.

    Parameters
    ----------
    center : (3,) array_like  [m]
        Square centre.
    side : float  [m]
        Side length (> 0).
    plane : str
        Plane name, see :func:`plane_axes`.

    Returns
    -------
    (6, 3) ndarray  [m]
        ``c + a(u)``, ``c + a(u + v)``, ``c + a(-u + v)``, ``c + a(-u - v)``, ``c + a(u - v)``,
        ``c + a(u)`` with ``a = side / 2`` (first and last vertex coincide: the path is closed).

    """
    center = _finite_vector(center, 'center')
    half = 0.5 * _positive(side, 'side')
    u_axis, v_axis = plane_axes(plane)
    corners = np.array([[1, 0], [1, 1], [-1, 1], [-1, -1], [1, -1], [1, 0]], dtype=float)
    return center + half * (corners[:, :1] * u_axis + corners[:, 1:] * v_axis)


def polyline_points(vertices, arc_length):
    """
    Return points of a polyline at given arc lengths (clamped to ``[0, length]``).

    Parameters
    ----------
    vertices : (V, 3) array_like  [m]
        Polyline vertices, V >= 2; repeated consecutive vertices are allowed (zero-length pieces).
    arc_length : (N,) array_like  [m]
        Arc lengths from the first vertex.

    Returns
    -------
    (N, 3) ndarray  [m]
        The points, linearly interpolated along the pieces.

    """
    vertices = np.asarray(vertices, dtype=float)
    cumulative = np.concatenate(
        [[0.0], np.cumsum(np.linalg.norm(np.diff(vertices, axis=0), axis=1))])
    s = np.clip(np.atleast_1d(np.asarray(arc_length, dtype=float)), 0.0, cumulative[-1])
    piece = np.clip(np.searchsorted(cumulative, s, side='right') - 1, 0, len(vertices) - 2)
    piece_length = cumulative[piece + 1] - cumulative[piece]
    fraction = np.divide(s - cumulative[piece], piece_length,
                         out=np.zeros_like(s), where=piece_length > 0.0)
    start = vertices[piece]
    return start + fraction[:, None] * (vertices[piece + 1] - start)


@dataclass(frozen=True)
class Trajectory:
    """
    A tip path traversed at constant speed.

    Attributes
    ----------
    shape : str
        ``'circle'``, ``'square'`` or ``'waypoints'``.
    speed : float  [m/s]
        Speed along the path.
    length : float  [m]
        Length of one lap (circle circumference, square perimeter, polyline length).
    closed : bool
        Whether the path returns to its start (circle, square, looped waypoints).
    laps : int
        Number of laps to run, 0 = forever (closed paths only; an open polyline runs once).
    start_hold : float  [s]
        Time spent at the start point before moving.
    center : (3,) ndarray or None  [m]
        Circle centre (circle only).
    radius : float or None  [m]
        Circle radius (circle only).
    plane : str or None
        Plane of a circle or square.
    vertices : (V, 3) ndarray or None  [m]
        Polyline vertices (square and waypoints; closed paths repeat the first vertex at the end).

    """

    shape: str
    speed: float
    length: float
    closed: bool
    laps: int
    start_hold: float
    center: np.ndarray = None
    radius: float = None
    plane: str = None
    vertices: np.ndarray = None

    @property
    def lap_time(self):
        """Time of one lap [s]."""
        return self.length / self.speed

    @property
    def duration(self):
        """Total time including ``start_hold`` [s]; ``inf`` for endless closed paths."""
        if self.closed and self.laps == 0:
            return math.inf
        laps = self.laps if self.closed else 1
        return self.start_hold + laps * self.lap_time

    def arc_length(self, time):
        """
        Return the arc length reached at given times (within one lap for closed paths).

        Parameters
        ----------
        time : (N,) array_like  [s]
            Times since the trajectory started.

        Returns
        -------
        (N,) ndarray  [m]
            Arc length in ``[0, length]``; after the last lap (or the end of an open path) it
            stays at the end point.

        """
        moving = np.atleast_1d(np.asarray(time, dtype=float)) - self.start_hold
        travelled = self.speed * np.clip(moving, 0.0, None)
        if not self.closed:
            return np.minimum(travelled, self.length)
        if self.laps > 0:
            finished = travelled >= self.laps * self.length
            return np.where(finished, self.length, np.mod(travelled, self.length))
        return np.mod(travelled, self.length)

    def points_at_arc_length(self, arc_length):
        """
        Return path points at given arc lengths.

        Parameters
        ----------
        arc_length : (N,) array_like  [m]
            Arc lengths in ``[0, length]``.

        Returns
        -------
        (N, 3) ndarray  [m]
            The points.

        """
        if self.shape == 'circle':
            return circle_points(self.center, self.radius, self.plane, arc_length)
        return polyline_points(self.vertices, arc_length)

    def sample(self, time):
        """
        Return the target positions at given times.

        Parameters
        ----------
        time : (N,) array_like or float  [s]
            Times since the trajectory started (before ``start_hold`` the start point is returned).

        Returns
        -------
        (N, 3) ndarray  [m]
            The targets.

        """
        return self.points_at_arc_length(self.arc_length(time))

    def finished(self, time):
        """Return whether the trajectory has ended at ``time`` [s] (never for endless paths)."""
        return float(time) >= self.duration

    def waypoints(self, max_chord_error=1e-5):
        """
        Return the whole path as timed waypoints, linear in between (one trajectory goal).

        A polyline's vertices are its waypoints; a circle is cut into chords whose sagitta
        ``r (1 - cos(pi / n))`` stays within ``max_chord_error``. The first waypoint is the
        start at time 0, a ``start_hold`` adds it again at that time, then every lap follows.

        Parameters
        ----------
        max_chord_error : float  [m]
            Largest distance between a circle and its chords (> 0).

        Returns
        -------
        times : (n,) ndarray  [s]
            Strictly increasing, from 0 to :attr:`duration`.
        points : (n, 3) ndarray  [m]

        Raises
        ------
        ValueError
            For an endless path (``laps`` 0 of a closed one) or a bad ``max_chord_error``.

        """
        if not math.isfinite(self.duration):
            raise ValueError('an endless path (a closed path with laps 0) has no last waypoint')
        max_chord_error = _positive(max_chord_error, 'max_chord_error')
        if self.shape == 'circle':
            ratio = max(-1.0, 1.0 - max_chord_error / self.radius)
            pieces = max(3, math.ceil(math.pi / math.acos(ratio)))
            lap = np.linspace(0.0, self.length, pieces + 1)
        else:
            lap = np.concatenate([[0.0], np.cumsum(np.linalg.norm(
                np.diff(self.vertices, axis=0), axis=1))])
            lap = lap[np.concatenate([[True], np.diff(lap) > 0.0])]   # no zero-length piece
        laps = self.laps if self.closed else 1
        arc = np.concatenate([lap] + [lap[1:] + i * self.length for i in range(1, laps)])
        times = arc / self.speed + self.start_hold
        if self.start_hold > 0.0:
            times, arc = np.concatenate([[0.0], times]), np.concatenate([[0.0], arc])
        return times, self.points_at_arc_length(np.mod(arc, self.length)
                                                if self.closed else arc)


def _check_common(speed, laps, start_hold):
    speed = _positive(speed, 'speed')
    if int(laps) != laps or laps < 0:
        raise ValueError(f'laps must be an integer >= 0 (0 = forever), got {laps}')
    start_hold = float(start_hold)
    if not math.isfinite(start_hold) or start_hold < 0.0:
        raise ValueError(f'start_hold must be a finite number >= 0, got {start_hold}')
    return speed, int(laps), start_hold


def circle_trajectory(center, radius, plane='yz', speed=0.025, laps=0, start_hold=0.0):
    """
    Build a circle traversed at constant speed (default: the paper's 2.5 cm/s).

    Parameters
    ----------
    center : (3,) array_like  [m]
        Centre.
    radius : float  [m]
        Radius (> 0); the paper uses 0.06.
    plane : str
        Plane name, see :func:`plane_axes` (the paper: ``'yz'``).
    speed : float  [m/s]
        Speed along the path (> 0).
    laps : int
        Laps to run, 0 = forever.
    start_hold : float  [s]
        Time at the start point before moving (>= 0).

    Returns
    -------
    Trajectory
        The circle.

    Raises
    ------
    ValueError
        On a non-finite or non-positive radius or speed, a bad centre, plane, laps or hold time.

    """
    center = _finite_vector(center, 'center')
    radius = _positive(radius, 'radius')
    plane_axes(plane)
    speed, laps, start_hold = _check_common(speed, laps, start_hold)
    return Trajectory(shape='circle', speed=speed, length=2.0 * math.pi * radius, closed=True,
                      laps=laps, start_hold=start_hold, center=center, radius=radius,
                      plane=plane.lower())


def square_trajectory(center, side, plane='yz', speed=0.031, laps=0, start_hold=0.0):
    """
    Build a square traversed at constant speed (default: the paper's 3.1 cm/s).

    Parameters
    ----------
    center : (3,) array_like  [m]
        Centre.
    side : float  [m]
        Side length (> 0); the paper uses 0.08.
    plane : str
        Plane name, see :func:`plane_axes` (the paper: ``'yz'``).
    speed : float  [m/s]
        Speed along the path (> 0).
    laps : int
        Laps to run, 0 = forever.
    start_hold : float  [s]
        Time at the start point before moving (>= 0).

    Returns
    -------
    Trajectory
        The square, see :func:`square_vertices` for its vertex order.

    Raises
    ------
    ValueError
        On a non-finite or non-positive side or speed, a bad centre, plane, laps or hold time.

    """
    vertices = square_vertices(center, side, plane)
    speed, laps, start_hold = _check_common(speed, laps, start_hold)
    return Trajectory(shape='square', speed=speed, length=4.0 * float(side), closed=True,
                      laps=laps, start_hold=start_hold, center=np.asarray(center, dtype=float),
                      plane=plane.lower(), vertices=vertices)


def waypoint_trajectory(waypoints, speed, loop=False, laps=0, start_hold=0.0):
    """
    Build a polyline through waypoints traversed at constant speed.

    Parameters
    ----------
    waypoints : (V, 3) array_like or flat (3V,) array_like  [m]
        Waypoints, V >= 2 (a flat list is read as consecutive x, y, z triples).
    speed : float  [m/s]
        Speed along the path (> 0).
    loop : bool
        Return from the last waypoint to the first and repeat (``laps`` times, 0 = forever); an
        open polyline runs once and stays at the last waypoint.
    laps : int
        Laps of a looped polyline, 0 = forever.
    start_hold : float  [s]
        Time at the first waypoint before moving (>= 0).

    Returns
    -------
    Trajectory
        The polyline.

    Raises
    ------
    ValueError
        On fewer than 2 waypoints, a flat list whose length is not a multiple of 3, non-finite
        values, a zero-length path, or a bad speed, laps or hold time.

    """
    points = np.asarray(waypoints, dtype=float)
    if points.ndim == 1:
        if points.size % 3 != 0:
            raise ValueError(
                f'a flat waypoint list needs 3 numbers per point, got {points.size} numbers')
        points = points.reshape(-1, 3)
    if points.ndim != 2 or points.shape[1] != 3 or points.shape[0] < 2:
        raise ValueError(f'waypoints must be (V, 3) with V >= 2, got shape {points.shape}')
    if not np.all(np.isfinite(points)):
        raise ValueError('waypoints must be finite')
    if loop:
        points = np.vstack([points, points[:1]])
    length = float(np.sum(np.linalg.norm(np.diff(points, axis=0), axis=1)))
    if not length > 0.0:
        raise ValueError('waypoints span a path of zero length')
    speed, laps, start_hold = _check_common(speed, laps, start_hold)
    return Trajectory(shape='waypoints', speed=speed, length=length, closed=bool(loop),
                      laps=laps, start_hold=start_hold, vertices=points)


def make_trajectory(shape, *, center=(0.0, 0.0, 0.0), radius=0.06, side=0.08, plane='yz',
                    speed=0.025, waypoints=(), loop=False, laps=0, start_hold=0.0):
    """
    Build a trajectory by shape name (what the ``trajectory`` node calls with its parameters).

    Parameters
    ----------
    shape : str
        ``'circle'``, ``'square'`` or ``'waypoints'``.
    center, radius, side, plane, speed, waypoints, loop, laps, start_hold
        As in :func:`circle_trajectory`, :func:`square_trajectory`,
        :func:`waypoint_trajectory`; the arguments the shape does not use are ignored.

    Returns
    -------
    Trajectory
        The path.

    Raises
    ------
    ValueError
        On an unknown shape or invalid arguments for that shape.

    """
    if shape == 'circle':
        return circle_trajectory(center, radius, plane, speed, laps, start_hold)
    if shape == 'square':
        return square_trajectory(center, side, plane, speed, laps, start_hold)
    if shape == 'waypoints':
        return waypoint_trajectory(waypoints, speed, loop, laps, start_hold)
    raise ValueError(f'shape must be one of {SHAPES}, got {shape!r}')
