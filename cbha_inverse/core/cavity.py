"""
Pressure cavities: closed triangle surfaces skinned to frames (paper §IV, Fig. 5, DESIGN §5).

Per unit pressure each vertex receives the outward normal times one third of the adjacent triangle
areas; the vertices follow the two frames that enclose them by linear skinning along the segment
axis, and the transposed skinning Jacobian maps the vertex forces to frame wrenches. For a closed
surface the vertex force is exactly the gradient of the enclosed volume, so a column is
``+d(volume)/dq`` (see :mod:`cbha_inverse.core.actuation` for the sign conventions).

Two evaluators share this geometry:

- :class:`CavityGroup` evaluates the skinned mesh (exact, cost proportional to the vertices);
- :class:`LinearCavityGroup` condenses each skinned segment cavity, like the compliance of a
  segment, onto its two frames: the wrench on the upper frame is affine in the corotational
  deformation of the segment (``G0 + H δ``, frame-i axes, fitted by central differences of the
  exact mesh at rest) and the lower frame gets the equilibrating wrench. It costs one small
  operation per segment and is the default of the online solver; its error against the exact
  mesh is second order in the segment deformation and is checked in the tests.
"""

from dataclasses import dataclass

from cbha_inverse.core.actuation import cross, point_wrenches
from cbha_inverse.core.kernel import jl_inverse_coefficients
from cbha_inverse.core.se3 import hat, so3_exp, so3_log
import numpy as np
import scipy.sparse as sp


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

    """

    name: str
    parts: tuple
    max_pressure: float


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


def triangle_volume_terms(p0, p1, p2):
    """
    Return the signed volume of each triangle's tetrahedron with the origin.

    Parameters
    ----------
    p0, p1, p2 : (T, 3) ndarray  [m]
        Triangle corners.

    Returns
    -------
    (T,) ndarray  [m^3]
        ``p0 · (p1 × p2) / 6``; their sum over a closed outward surface is its volume.

    """
    return np.einsum('ti,ti->t', p0, cross(p1, p2)) / 6.0


class CavityGroup:
    """
    Exact evaluation of skinned cavity meshes (paper Fig. 5).

    Parameters
    ----------
    cavities : sequence of Cavity
        The pressure actuators, in column order.
    n_frames : int
        Number of frames (base included).

    """

    def __init__(self, cavities, n_frames):
        """Concatenate all parts and precompute the skinning and scatter matrices."""
        self.cavities = tuple(cavities)
        self.names = tuple(c.name for c in self.cavities)
        self.n_frames = int(n_frames)
        m = len(self.cavities)
        fa, la, lb, wb, tris, owner_v, owner_t = [], [], [], [], [], [], []
        count = 0
        for j, cavity in enumerate(self.cavities):
            for part in cavity.parts:
                if not 0 <= part.lower < n_frames - 1:
                    raise ValueError(f'cavity {cavity.name!r}: lower frame {part.lower} outside '
                                     f'0..{n_frames - 2}')
                pts = np.asarray(part.points, dtype=float)
                s = skinning_weights(pts, part.rest_offset)
                fa.append(np.full(len(pts), part.lower))
                la.append(pts)
                lb.append((pts - part.rest_offset) @ np.asarray(part.rest_rotation))
                wb.append(s)
                tris.append(np.asarray(part.triangles, dtype=int) + count)
                owner_v.append(np.full(len(pts), j))
                owner_t.append(np.full(len(part.triangles), j))
                count += len(pts)
        self.frame_a = np.concatenate(fa)
        self.frame_b = self.frame_a + 1
        self.local_a = np.concatenate(la)
        self.local_b = np.concatenate(lb)
        self.weight_b = np.concatenate(wb)
        self.weight_a = 1.0 - self.weight_b
        self.triangles = np.concatenate(tris)
        owner_v = np.concatenate(owner_v)
        owner_t = np.concatenate(owner_t)
        n_v, n_t = count, len(self.triangles)
        rows = self.triangles.reshape(-1)
        cols = np.repeat(np.arange(n_t), 3)
        self._vertex_triangle = sp.csr_matrix((np.full(rows.size, 1.0 / 6.0), (rows, cols)),
                                              shape=(n_v, n_t))
        self._triangle_sum = sp.csr_matrix((np.ones(n_t), (owner_t, np.arange(n_t))),
                                           shape=(m, n_t))
        shape = (m * self.n_frames, n_v)
        cols_v = np.arange(n_v)
        self._scatter_a = sp.csr_matrix(
            (self.weight_a, (owner_v * self.n_frames + self.frame_a, cols_v)), shape=shape)
        self._scatter_b = sp.csr_matrix(
            (self.weight_b, (owner_v * self.n_frames + self.frame_b, cols_v)), shape=shape)
        self.upper_bounds = np.array([c.max_pressure for c in self.cavities], dtype=float)
        self.lower_bounds = np.zeros(m)

    @property
    def n_actuators(self):
        """Return the number of cavities."""
        return len(self.cavities)

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
        ra = np.einsum('vij,vj->vi', rotations[self.frame_a], self.local_a)
        rb = np.einsum('vij,vj->vi', rotations[self.frame_b], self.local_b)
        points = (self.weight_a[:, None] * (positions[self.frame_a] + ra)
                  + self.weight_b[:, None] * (positions[self.frame_b] + rb))
        return points, ra, rb

    def volumes(self, positions, rotations):
        """
        Return the enclosed volume of every cavity.

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
        t = self.triangles
        return self._triangle_sum @ triangle_volume_terms(points[t[:, 0]], points[t[:, 1]],
                                                          points[t[:, 2]])

    def evaluate(self, positions, rotations):
        """
        Return the Jacobian columns and the volumes of all cavities.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        wrenches : (m, n + 1, 6) ndarray  [N, N*m per Pa]
            Frame wrenches per unit pressure (columns of ``J_aᵀ``).
        displacements : (m,) ndarray  [m^3]
            Cavity volumes (``δ_a`` up to a constant).

        """
        points, ra, rb = self.vertices(positions, rotations)
        t = self.triangles
        p0, p1, p2 = points[t[:, 0]], points[t[:, 1]], points[t[:, 2]]
        normals = cross(p1 - p0, p2 - p0)
        forces = self._vertex_triangle @ normals
        wrenches = (self._scatter_a @ point_wrenches(ra, forces)
                    + self._scatter_b @ point_wrenches(rb, forces))
        volumes = self._triangle_sum @ triangle_volume_terms(p0, p1, p2)
        return wrenches.reshape(self.n_actuators, self.n_frames, 6), volumes


def segment_deformation(x_i, r_i, x_j, r_j, rest_offset, rest_rotation):
    """
    Return the corotational deformation of segments (DESIGN §3).

    Parameters
    ----------
    x_i, x_j : (E, 3) ndarray  [m]
        Lower and upper frame origins.
    r_i, r_j : (E, 3, 3) ndarray
        Lower and upper frame rotations.
    rest_offset : (E, 3) ndarray  [m]
        Rest offsets ``d0``.
    rest_rotation : (E, 3, 3) ndarray
        Rest relative rotations ``Q0``.

    Returns
    -------
    (E, 6) ndarray  [m, rad]
        ``[R_iᵀ(x_j - x_i) - d0; log(R_iᵀ R_j Q0ᵀ)]`` in frame-i axes.

    """
    lin = np.einsum('eji,ej->ei', r_i, x_j - x_i) - rest_offset
    rel = np.einsum('eki,ekl,eml->eim', r_i, r_j, rest_rotation)
    return np.concatenate([lin, so3_log(rel)], axis=1)


class LinearCavityGroup:
    """
    Cavities condensed per segment onto the two frames (affine in the segment deformation).

    Parameters
    ----------
    cavities : sequence of Cavity
        The pressure actuators, in column order.
    n_frames : int
        Number of frames (base included).
    step : float
        Relative finite-difference step of the fit (times the segment length for translations,
        radians for rotations).

    """

    def __init__(self, cavities, n_frames, step=1e-5):
        """Fit ``G0``, ``H`` and the volume of every segment part from the exact mesh."""
        self.cavities = tuple(cavities)
        self.names = tuple(c.name for c in self.cavities)
        self.n_frames = int(n_frames)
        lower, owner, g0, hess, d0, q0, v0 = [], [], [], [], [], [], []
        for j, cavity in enumerate(self.cavities):
            for part in cavity.parts:
                g, h, vol = fit_linear_cavity(part, step)
                lower.append(part.lower)
                owner.append(j)
                g0.append(g)
                hess.append(h)
                d0.append(np.asarray(part.rest_offset, dtype=float))
                q0.append(np.asarray(part.rest_rotation, dtype=float))
                v0.append(vol)
        self.lower = np.array(lower, dtype=int)
        self.upper = self.lower + 1
        self.g0 = np.array(g0)
        self.hessian = np.array(hess)
        self._volume_hessian = 0.5 * (self.hessian + np.transpose(self.hessian, (0, 2, 1)))
        self.rest_offset = np.array(d0)
        self.rest_rotation = np.array(q0)
        self.v0 = np.array(v0)
        m, n_e = len(self.cavities), len(lower)
        owner = np.array(owner, dtype=int)
        cols = np.arange(n_e)
        shape = (m * self.n_frames, n_e)
        self._scatter_lower = sp.csr_matrix((np.ones(n_e), (owner * self.n_frames + self.lower,
                                                            cols)), shape=shape).toarray()
        self._scatter_upper = sp.csr_matrix((np.ones(n_e), (owner * self.n_frames + self.upper,
                                                            cols)), shape=shape).toarray()
        self._sum = np.zeros((m, n_e))
        self._sum[owner, cols] = 1.0
        self._owner = owner
        size = 6 * self.n_frames
        f = np.stack([self.lower, self.upper], axis=1)
        i6 = np.arange(6)
        rows = 6 * f[:, :, None, None, None] + i6[None, None, None, :, None]
        cols6 = 6 * f[:, None, :, None, None] + i6[None, None, None, None, :]
        self._tangent_index = (rows * size + cols6).reshape(-1)
        self.upper_bounds = np.array([c.max_pressure for c in self.cavities], dtype=float)
        self.lower_bounds = np.zeros(m)

    @property
    def n_actuators(self):
        """Return the number of cavities."""
        return len(self.cavities)

    def load_tangent(self, positions, rotations, pressures, symmetric=True):
        """
        Return the load stiffness ``-d(J_aᵀ p)/dq`` of the condensed cavities.

        Pressure forces follow the structure (the caps turn with the vertebrae); like the cable
        load stiffness this term is needed for Newton's method to converge at high pressure.
        Exact derivative of the affine model (symmetrised on request).

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        pressures : (m,) ndarray  [Pa]
            Gauge pressures.
        symmetric : bool
            Return the symmetric part (for Cholesky) instead of the exact derivative.

        Returns
        -------
        (6n, 6n) ndarray
            Over frames 1..n.

        """
        return _linear_cavity_load_tangent(self, positions, rotations, pressures, symmetric)

    def evaluate(self, positions, rotations):
        """
        Return the Jacobian columns and the (second-order) volumes of all cavities.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        wrenches : (m, n + 1, 6) ndarray  [N, N*m per Pa]
            Frame wrenches per unit pressure.
        displacements : (m,) ndarray  [m^3]
            ``V0 + G0·δ + ½ δᵀ sym(H) δ`` summed over the parts.

        """
        r_i, x_i, x_j = rotations[self.lower], positions[self.lower], positions[self.upper]
        delta = segment_deformation(x_i, r_i, x_j, rotations[self.upper], self.rest_offset,
                                    self.rest_rotation)
        local = self.g0 + np.einsum('eab,eb->ea', self.hessian, delta)
        force = np.einsum('eij,ej->ei', r_i, local[:, :3])
        moment = np.einsum('eij,ej->ei', r_i, local[:, 3:])
        upper = np.concatenate([force, moment], axis=1)
        lower = np.concatenate([-force, -moment - cross(x_j - x_i, force)], axis=1)
        wrenches = self._scatter_upper @ upper + self._scatter_lower @ lower
        vol = (self.v0 + np.einsum('ea,ea->e', self.g0, delta)
               + 0.5 * np.einsum('ea,eab,eb->e', delta, self._volume_hessian, delta))
        return wrenches.reshape(self.n_actuators, self.n_frames, 6), self._sum @ vol


def _linear_cavity_load_tangent(group, positions, rotations, pressures, symmetric):
    """Return ``-d(J_aᵀ p)/dq`` (frames 1..n) of a :class:`LinearCavityGroup`."""
    lo, up = group.lower, group.upper
    r_a, x_a, x_b = rotations[lo], positions[lo], positions[up]
    v = x_b - x_a
    delta = segment_deformation(x_a, r_a, x_b, rotations[up], group.rest_offset,
                                group.rest_rotation)
    local = group.g0 + np.einsum('eab,eb->ea', group.hessian, delta)
    p = pressures[group._owner]
    f = np.einsum('eij,ej->ei', r_a, local[:, :3])
    m = np.einsum('eij,ej->ei', r_a, local[:, 3:])
    phi = delta[:, 3:]
    c, _ = jl_inverse_coefficients(np.sqrt(np.einsum('ei,ei->e', phi, phi)))
    phi_hat = hat(phi)
    jinv = c[:, None, None] * (phi_hat @ phi_hat) - 0.5 * phi_hat + np.eye(3)
    r_at = np.swapaxes(r_a, 1, 2)
    n_e = len(lo)
    # dδ = D_a dq_a + D_b dq_b (frame-i axes)
    d_a = np.zeros((n_e, 6, 6))
    d_a[:, :3, :3] = -r_at
    d_a[:, :3, 3:] = r_at @ hat(v)
    d_a[:, 3:, 3:] = -jinv @ r_at
    d_b = np.zeros((n_e, 6, 6))
    d_b[:, :3, :3] = r_at
    d_b[:, 3:, 3:] = jinv @ r_at
    rr = np.zeros((n_e, 6, 6))
    rr[:, :3, :3] = r_a
    rr[:, 3:, 3:] = r_a
    rh = rr @ group.hessian
    jb_a = rh @ d_a
    jb_a[:, :3, 3:] -= hat(f)
    jb_a[:, 3:, 3:] -= hat(m)
    jb_b = rh @ d_b
    t = np.zeros((n_e, 6, 6))
    t[:, :3, :3] = -np.eye(3)
    t[:, 3:, 3:] = -np.eye(3)
    t[:, 3:, :3] = -hat(v)
    ja_a = t @ jb_a
    ja_a[:, 3:, :3] -= hat(f)
    ja_b = t @ jb_b
    ja_b[:, 3:, :3] += hat(f)
    blocks = np.stack([np.stack([ja_a, ja_b], 1), np.stack([jb_a, jb_b], 1)], 1)
    blocks *= -p[:, None, None, None, None]
    size = 6 * group.n_frames
    dense = np.bincount(group._tangent_index, blocks.reshape(-1),
                        minlength=size * size).reshape(size, size)[6:, 6:]
    return 0.5 * (dense + dense.T) if symmetric else dense


def fit_linear_cavity(part, step=1e-5):
    """
    Fit the affine upper-frame wrench ``G(δ) ≈ G0 + H δ`` of one skinned segment cavity.

    Frame ``i`` is held at the identity and frame ``j`` is placed at ``x = d0 + δ_lin``,
    ``R = exp(δ_ang) Q0``; ``G`` is the exact mesh wrench on frame ``j`` per unit pressure (frame-i
    axes) and ``H`` its central-difference derivative.

    Parameters
    ----------
    part : CavityPart
        The segment cavity.
    step : float
        Relative step (times ``|d0|`` for translations, radians for rotations).

    Returns
    -------
    g0 : (6,) ndarray
        Wrench on the upper frame at rest.
    hessian : (6, 6) ndarray
        ``dG/dδ``.
    volume : float  [m^3]
        Rest volume.

    """
    local = CavityPart(part.points, part.triangles, 0, part.rest_offset, part.rest_rotation)
    group = CavityGroup([Cavity('part', (local,), np.inf)], 2)
    d0 = np.asarray(part.rest_offset, dtype=float)
    q0 = np.asarray(part.rest_rotation, dtype=float)
    scale = np.array([np.linalg.norm(d0)] * 3 + [1.0] * 3) * step

    def upper_wrench(delta):
        positions = np.stack([np.zeros(3), d0 + delta[:3]])
        rotations = np.stack([np.eye(3), so3_exp(delta[3:]) @ q0])
        wrenches, volume = group.evaluate(positions, rotations)
        return wrenches[0, 1], volume[0]

    g0, volume = upper_wrench(np.zeros(6))
    hessian = np.empty((6, 6))
    for k in range(6):
        e = np.zeros(6)
        e[k] = scale[k]
        hessian[:, k] = (upper_wrench(e)[0] - upper_wrench(-e)[0]) / (2.0 * scale[k])
    return g0, hessian, float(volume)


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
