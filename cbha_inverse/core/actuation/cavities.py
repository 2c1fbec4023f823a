"""
Pressure cavities: closed triangle surfaces skinned to frames (paper Sec. IV, Fig. 5).

Per unit pressure each vertex receives the outward normal times one third of the adjacent triangle
areas; the vertices follow the two frames that enclose them by linear skinning along the segment
axis, and the transposed skinning Jacobian maps the vertex forces to frame wrenches. For a closed
surface the vertex force is exactly the gradient of the enclosed volume, so a column is
``+d(volume)/dq`` (see :mod:`cbha_inverse.core.actuation.cables` for the sign conventions).

Two evaluators share this geometry:

- :class:`CavityGroup` evaluates the skinned mesh (exact, cost proportional to the vertices);
- :class:`cbha_inverse.core.actuation.condensed_cavities.LinearCavityGroup` condenses each
  skinned segment cavity, like the compliance of a segment, onto its two frames: the wrench on
  the upper frame is affine in the corotational deformation of the segment (``G0 + H δ``,
  frame-i axes, fitted by central differences of the exact mesh at rest) and the lower frame
  gets the equilibrating wrench. It costs one small operation per segment and is the default of
  the online solver; its error against the exact mesh is second order in the segment
  deformation (tested).
"""

from dataclasses import dataclass

from cbha_inverse.core._kernels.mesh_cavities import (mesh_cavity_volumes, mesh_cavity_wrenches,
                                                      skinned_vertices)
import numpy as np


@dataclass(frozen=True)
class CavityPart:
    """
    A closed triangle surface inside one segment (between frames ``lower`` and ``lower + 1``).

    Attributes
    ----------
    points : (V, 3) ndarray  [m]
        Vertices in segment coordinates (frame ``lower`` at the origin, its axes).
    triangles : (T, 3) ndarray of int
        Triangles with outward (counter-clockwise seen from outside) orientation.
    lower : int
        Index of the lower frame.
    rest_offset : (3,) ndarray  [m]
        Origin of frame ``lower + 1`` in frame ``lower`` at rest.
    rest_rotation : (3, 3) ndarray
        Rotation of frame ``lower + 1`` in frame ``lower`` at rest.

    """

    points: np.ndarray
    triangles: np.ndarray
    lower: int
    rest_offset: np.ndarray
    rest_rotation: np.ndarray


@dataclass(frozen=True)
class Cavity:
    """
    One pressure actuator: the union of its segment parts.

    Attributes
    ----------
    name : str
        Actuator name.
    parts : tuple of CavityPart
        Its closed surfaces (caps shared by two segments cancel in the sum).
    max_pressure : float  [Pa]
        Upper bound (gauge).
    gain : float  [-]
        Effective-area factor: scales the wrenches per unit pressure and the work-conjugate
        volume (a scene's ``calibration.actuator_gain``; 1 = the geometric cavity).

    """

    name: str
    parts: tuple
    max_pressure: float
    gain: float = 1.0


def skinning_weights(points, rest_offset):
    """
    Return the linear skinning weight of the upper frame for points of a segment.

    Parameters
    ----------
    points : (V, 3) ndarray  [m]
        Points in segment coordinates.
    rest_offset : (3,) ndarray  [m]
        Upper frame origin at rest.

    Returns
    -------
    (V,) ndarray
        ``s = clip(p·d0 / |d0|², 0, 1)``; the lower frame has weight ``1 - s`` (caps on the
        vertebra faces get weight 1 on their frame).

    """
    d0 = np.asarray(rest_offset, dtype=float)
    return np.clip(points @ d0 / (d0 @ d0), 0.0, 1.0)


class CavityGroup:
    """
    Exact evaluation of skinned cavity meshes (paper Fig. 5).

    The arithmetic is compiled (:mod:`cbha_inverse.core._kernels.mesh_cavities`, which the
    equilibrium evaluation runs too); the numpy version is a test oracle
    (``test/oracles/actuation.py``).

    Parameters
    ----------
    cavities : sequence of Cavity
        The pressure actuators, in column order.
    n_frames : int
        Number of frames (base included).

    Attributes
    ----------
    frame_a : (V,) int ndarray
        Lower frame of every vertex of every part (the upper one is ``frame_a + 1``).
    local_a, local_b : (V, 3) ndarray  [m]
        The vertices in the lower and upper frame's axes.
    weight_b : (V,) ndarray
        Skinning weight of the upper frame (:func:`skinning_weights`).
    triangles : (T, 3) int ndarray
        Triangles over the concatenated vertices.
    vertex_owner, triangle_owner : (V,), (T,) int ndarray
        Cavity of every vertex and triangle.
    gains : (m,) ndarray  [-]
        Gain of every cavity.

    """

    def __init__(self, cavities, n_frames):
        """Concatenate all parts and their skinning."""
        self.cavities = tuple(cavities)
        self.names = tuple(c.name for c in self.cavities)
        self.n_frames = int(n_frames)
        fa, la, lb, wb, tris, owner_v, owner_t = [], [], [], [], [], [], []
        count = 0
        for j, cavity in enumerate(self.cavities):
            for part in cavity.parts:
                if not 0 <= part.lower < n_frames - 1:
                    raise ValueError(f'cavity {cavity.name!r}: lower frame {part.lower} outside '
                                     f'0..{n_frames - 2}')
                pts = np.asarray(part.points, dtype=float)
                fa.append(np.full(len(pts), part.lower))
                la.append(pts)
                lb.append((pts - part.rest_offset) @ np.asarray(part.rest_rotation))
                wb.append(skinning_weights(pts, part.rest_offset))
                tris.append(np.asarray(part.triangles, dtype=int) + count)
                owner_v.append(np.full(len(pts), j))
                owner_t.append(np.full(len(part.triangles), j))
                count += len(pts)
        self.frame_a = np.ascontiguousarray(np.concatenate(fa), dtype=np.int64)
        self.local_a = np.ascontiguousarray(np.concatenate(la), dtype=float)
        self.local_b = np.ascontiguousarray(np.concatenate(lb), dtype=float)
        self.weight_b = np.ascontiguousarray(np.concatenate(wb), dtype=float)
        self.triangles = np.ascontiguousarray(np.concatenate(tris), dtype=np.int64)
        self.vertex_owner = np.ascontiguousarray(np.concatenate(owner_v), dtype=np.int64)
        self.triangle_owner = np.ascontiguousarray(np.concatenate(owner_t), dtype=np.int64)
        self.gains = np.array([c.gain for c in self.cavities], dtype=float)
        for constant in (self.frame_a, self.local_a, self.local_b, self.weight_b, self.triangles,
                         self.vertex_owner, self.triangle_owner, self.gains):
            # constants of the compiled kernels, which take them read-only (one compiled type)
            constant.flags.writeable = False
        self.upper_bounds = np.array([c.max_pressure for c in self.cavities], dtype=float)
        self.lower_bounds = np.zeros(len(self.cavities))

    @property
    def n_actuators(self):
        """Return the number of cavities."""
        return len(self.cavities)

    def _scratch(self):
        """Return new arrays for the skinned vertices, their levers and forces (V, 3)."""
        return tuple(np.empty((self.frame_a.size, 3)) for _ in range(4))

    def vertices(self, positions, rotations):
        """
        Return the skinned world vertices and the levers of both attachments.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        points, levers_a, levers_b : (V, 3) ndarray  [m]
            ``p = (1 - s)(x_a + R_a a) + s (x_b + R_b b)``, ``R_a a`` and ``R_b b``.

        """
        points, levers_a, levers_b, _ = self._scratch()
        skinned_vertices(_frames(positions), _frames(rotations), self.frame_a, self.local_a,
                         self.local_b, self.weight_b, points, levers_a, levers_b)
        return points, levers_a, levers_b

    def volumes(self, positions, rotations):
        """
        Return the enclosed volume of every cavity (times its gain).

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        (m,) ndarray  [m^3]
            Volumes of the skinned surfaces.

        """
        points, _, _ = self.vertices(positions, rotations)
        volumes = np.empty(self.n_actuators)
        mesh_cavity_volumes(points, self.triangles, self.triangle_owner, self.gains, volumes)
        return volumes

    def evaluate(self, positions, rotations, displacements=True):
        """
        Return the Jacobian columns and the volumes of all cavities.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).
        displacements : bool
            Unused (the volumes come with the normals at little cost).

        Returns
        -------
        wrenches : (m, n + 1, 6) ndarray  [N, N*m per Pa]
            Frame wrenches per unit pressure (columns of ``J_aᵀ``).
        displacements : (m,) ndarray  [m^3]
            Cavity volumes (``δ_a`` up to a constant).

        """
        points, levers_a, levers_b, forces = self._scratch()
        wrenches = np.empty((self.n_actuators, self.n_frames, 6))
        mesh_cavity_wrenches(_frames(positions), _frames(rotations), self.frame_a, self.local_a,
                             self.local_b, self.weight_b, self.triangles, self.vertex_owner,
                             self.gains, points, levers_a, levers_b, forces, wrenches)
        volumes = np.empty(self.n_actuators)
        mesh_cavity_volumes(points, self.triangles, self.triangle_owner, self.gains, volumes)
        return wrenches, volumes


def _frames(array):
    """Return frame data as the compiled kernels take it (C-ordered floats)."""
    return np.ascontiguousarray(array, dtype=float)


def tube_surface(length, radius, center, n_around=16, n_along=2):
    """
    Return a closed, outward-oriented triangulated cylinder along +x (a simple cavity surface).

    Parameters
    ----------
    length : float  [m]
        Extent along x, from 0 to ``length``.
    radius : float  [m]
        Radius of the polygonal section.
    center : (2,) array_like  [m]
        (y, z) of the axis.
    n_around : int
        Vertices per ring.
    n_along : int
        Number of rings (>= 2).

    Returns
    -------
    points : (n_along * n_around + 2, 3) ndarray  [m]
        Ring vertices, then the two cap centres.
    triangles : (T, 3) ndarray of int
        Outward-oriented triangles.

    """
    theta = 2.0 * np.pi * np.arange(n_around) / n_around
    xs = np.linspace(0.0, length, n_along)
    cy, cz = float(center[0]), float(center[1])
    ring = np.stack([np.zeros(n_around), cy + radius * np.cos(theta),
                     cz + radius * np.sin(theta)], axis=1)
    points = np.concatenate([ring + [x, 0.0, 0.0] for x in xs]
                            + [[[0.0, cy, cz], [length, cy, cz]]])
    k = np.arange(n_around)
    k1 = (k + 1) % n_around
    tris = []
    for i in range(n_along - 1):
        a, b = i * n_around + k, i * n_around + k1
        c, d = a + n_around, b + n_around
        tris += [np.stack([a, b, c], 1), np.stack([b, d, c], 1)]
    bottom, top = n_along * n_around, n_along * n_around + 1
    last = (n_along - 1) * n_around
    tris += [np.stack([np.full(n_around, bottom), k1, k], 1),
             np.stack([np.full(n_around, top), last + k, last + k1], 1)]
    return points, np.concatenate(tris)
