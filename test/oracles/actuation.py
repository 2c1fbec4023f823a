"""
Actuator columns ``J_aᵀ``, loads and load stiffness in batched numpy (oracle of the kernels).

The readable reference of the cable, condensed-cavity and skinned-mesh cavity terms that
:func:`cbha_inverse.core._kernels.cables.cable_pass`,
:func:`cbha_inverse.core._kernels.links.link_pass` and
:mod:`cbha_inverse.core._kernels.mesh_cavities` compute: :func:`oracle` wraps a production
group (or an :class:`~cbha_inverse.core.actuation.actuators.ActuatorSet`) in an object with
``evaluate`` / ``load_tangent`` / ``loads`` / ``lengths`` (a skinned-mesh
:class:`~cbha_inverse.core.actuation.cavities.CavityGroup` in :class:`MeshCavityOracle`, which
rebuilds the skinning from the cavities' parts and has no load stiffness, as the production
group).

Sign conventions (the actuator's virtual work is ``λ · dδ_a``): cable ``δ_a`` is the shortening
(column ``-d(length)/dq``), cavity ``δ_a`` the volume (column ``+d(volume)/dq``).
"""

from cbha_inverse.core.actuation.actuators import ActuatorSet
from cbha_inverse.core.actuation.cables import CableGroup
from cbha_inverse.core.actuation.cavities import CavityGroup
from cbha_inverse.core.actuation.condensed_cavities import LinearCavityGroup
import numpy as np
from oracles.chain_forces import link_deformation
from oracles.so3 import hat, so3_left_jacobian_inverse, so3_log
import scipy.sparse as sp


def cross(a, b):
    """Return the row-wise cross product (numpy)."""
    return np.cross(a, b)


def point_wrenches(levers, forces):
    """Return the wrenches ``[F; r x F]`` at the frame origins of forces at points."""
    return np.concatenate([forces, np.cross(levers, forces)], axis=1)


def oracle(actuators):
    """
    Return the numpy evaluator of a group or an actuator set.

    Parameters
    ----------
    actuators : CableGroup, LinearCavityGroup, CavityGroup or ActuatorSet
        Production actuators.

    Returns
    -------
    object
        With ``evaluate``, ``load_tangent`` (and ``loads`` for a set, ``lengths`` for cables,
        ``vertices`` and ``volumes`` for mesh cavities, which have no ``load_tangent``).

    Raises
    ------
    TypeError
        For a group of no known kind.

    """
    if isinstance(actuators, ActuatorSet):
        return ActuatorSetOracle(actuators)
    if isinstance(actuators, CableGroup):
        return CableOracle(actuators)
    if isinstance(actuators, LinearCavityGroup):
        return LinearCavityOracle(actuators)
    if isinstance(actuators, CavityGroup):
        return MeshCavityOracle(actuators)
    raise TypeError(f'no oracle of {type(actuators).__name__}')


class CableOracle:
    """Numpy evaluation of a :class:`~cbha_inverse.core.actuation.cables.CableGroup`."""

    def __init__(self, group):
        """Build the scatter matrices of the group's routing."""
        self.group = group
        self.n_frames = group.n_frames
        self.n_actuators = group.n_actuators
        self.frames, self.offsets = group.frames, group.offsets
        self.gains = np.asarray(group.gains, dtype=float)
        self.segment_start, self.segment_end = group.segment_start, group.segment_end
        self._segment_owner, self._point_owner = group.segment_owner, group.point_owner
        m, owner = group.n_actuators, group.point_owner
        n_points, n_segments = self.frames.size, self.segment_start.size
        rows = np.arange(n_segments)
        incidence = (sp.csr_matrix((np.ones(n_segments), (self.segment_start, rows)),
                                   shape=(n_points, n_segments))
                     - sp.csr_matrix((np.ones(n_segments), (self.segment_end, rows)),
                                     shape=(n_points, n_segments)))
        self._point_force = incidence.toarray()
        scatter = np.zeros((m * self.n_frames, n_points))
        scatter[owner * self.n_frames + self.frames, np.arange(n_points)] = 1.0
        self._scatter = scatter
        self._length_sum = np.zeros((m, n_segments))
        self._length_sum[self._segment_owner, rows] = 1.0
        self._tangent_index = _span_tangent_index(self.frames, self.segment_start,
                                                  self.segment_end, self.n_frames)

    def routing_points(self, positions, rotations):
        """
        Return the world positions of all routing points and their levers.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        points, levers : (P, 3) ndarray  [m]
            Routing points and ``point - frame origin`` (world axes).

        """
        levers = np.einsum('pij,pj->pi', rotations[self.frames], self.offsets)
        return positions[self.frames] + levers, levers

    def lengths(self, positions, rotations):
        """
        Return the routed length of every cable.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        Returns
        -------
        (m,) ndarray  [m]
            Sum of the straight spans between consecutive routing points.

        """
        return self._length_sum @ self._spans(positions, rotations)[2]

    def _spans(self, positions, rotations):
        """Return the routing-point levers, the span unit vectors and the span lengths."""
        points, levers = self.routing_points(positions, rotations)
        spans = points[self.segment_end] - points[self.segment_start]
        span_lengths = np.sqrt(np.einsum('si,si->s', spans, spans))
        return levers, spans / span_lengths[:, None], span_lengths

    def evaluate(self, positions, rotations, displacements=True):
        """
        Return the Jacobian columns and the displacements of all cables.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).

        displacements : bool
            Unused (the lengths come with the columns at no cost).

        Returns
        -------
        wrenches : (m, n + 1, 6) ndarray  [N, N*m per N]
            Frame wrenches per unit tension (columns of ``J_aᵀ``, times each cable's gain).
        displacements : (m,) ndarray  [m]
            ``-gain * length``: the cable shortening up to a constant (``δ_a``).

        """
        levers, units, span_lengths = self._spans(positions, rotations)
        forces = self._point_force @ units
        wrenches = self._scatter @ point_wrenches(levers, forces)
        return (self.gains[:, None, None] * wrenches.reshape(self.n_actuators, self.n_frames, 6),
                -self.gains * (self._length_sum @ span_lengths))

    def load_tangent(self, positions, rotations, tensions, symmetric=True):
        """
        Return the load stiffness of the cables, ``-d(J_aᵀ λ)/dq`` (exact or its symmetric part).

        Cable forces follow the structure, so they add a stiffness to the tangent of the
        equilibrium (paper eq. 9-10): per span ``s`` with unit direction ``u``, length ``ℓ`` and
        tension ``λ``, ``λ D_sᵀ (I - u uᵀ)/ℓ D_s`` (``D_s`` maps increments to the change of the
        span vector; positive semi-definite: it stabilises the compressed backbone), and per
        routing point with lever ``r`` and force ``F`` the moment term ``-F^ r^ = (F·r) I - r Fᵀ``
        on its frame's rotations (turning the frame turns the lever), whose symmetric part is
        ``(F·r) I - (r Fᵀ + F rᵀ)/2`` and skew part ``½ hat(r × F)``. Without it a
        tendon-compressed chain can look unstable to Newton's method.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        tensions : (m,) ndarray  [N]
            Cable tensions.
        symmetric : bool
            True: the symmetric part (for the Cholesky of the control tick); False: the exact
            tangent (Newton converges quadratically with it, linearly without the skew part).

        Returns
        -------
        (6n, 6n) ndarray  [N/m, N, N*m]
            Over frames 1..n (world-axis increments), to add to the structural tangent.

        """
        levers, units, lengths = self._spans(positions, rotations)
        start, end = self.segment_start, self.segment_end
        tensions = self.gains * tensions      # the tension along the routing
        scale = tensions[self._segment_owner] / lengths
        proj = -scale[:, None, None] * units[:, :, None] * units[:, None, :]
        proj[:, 0, 0] += scale
        proj[:, 1, 1] += scale
        proj[:, 2, 2] += scale
        lever = np.stack([levers[start], levers[end]], axis=1)
        # B = [I; r^] (6 x 3) for the start and end points of every span
        b = np.zeros((len(start), 2, 6, 3))
        b[:, :, 0, 0] = b[:, :, 1, 1] = b[:, :, 2, 2] = 1.0
        b[:, :, 3:, :] = hat(lever)
        bp = np.matmul(b, proj[:, None])
        blocks = np.matmul(bp[:, :, None], np.swapaxes(b, 2, 3)[:, None, :])
        blocks[:, 0, 1] *= -1.0
        blocks[:, 1, 0] *= -1.0
        forces = (self._point_force @ units) * tensions[self._point_owner][:, None]
        fr = np.einsum('pi,pi->p', forces, levers)
        moment = -levers[:, :, None] * forces[:, None, :]
        if symmetric:
            moment = 0.5 * (moment + np.swapaxes(moment, 1, 2))
        moment[:, 0, 0] += fr
        moment[:, 1, 1] += fr
        moment[:, 2, 2] += fr
        size = 6 * self.n_frames
        dense = np.bincount(self._tangent_index,
                            np.concatenate([blocks.reshape(-1), moment.reshape(-1)]),
                            minlength=size * size).reshape(size, size)
        return dense[6:, 6:]


def _span_tangent_index(frames, start, end, n_frames):
    """Flat dense indices of the span blocks and point moment blocks of a cable group."""
    size = 6 * n_frames
    f = np.stack([frames[start], frames[end]], axis=1)
    i6 = np.arange(6)
    rows = 6 * f[:, :, None, None, None] + i6[None, None, None, :, None]
    cols = 6 * f[:, None, :, None, None] + i6[None, None, None, None, :]
    span_index = (rows * size + cols).reshape(-1)
    i3 = np.arange(3)
    prow = 6 * frames[:, None, None] + 3 + i3[None, :, None]
    pcol = 6 * frames[:, None, None] + 3 + i3[None, None, :]
    return np.concatenate([span_index, (prow * size + pcol).reshape(-1)])


class LinearCavityOracle:
    """Numpy evaluation of a condensed-cavity group (``LinearCavityGroup``)."""

    def __init__(self, group):
        """Build the scatter matrices and per-segment data of the group."""
        self.group = group
        self.n_frames, self.n_actuators = group.n_frames, group.n_actuators
        self.lower, self.upper, self.g0, self.hessian = (group.lower, group.upper, group.g0,
                                                         group.hessian)
        self.rest_offset, self.rest_rotation, self.v0 = (group.rest_offset, group.rest_rotation,
                                                         group.v0)
        self._volume_hessian = 0.5 * (self.hessian + np.transpose(self.hessian, (0, 2, 1)))
        m, n_e = group.n_actuators, group.lower.size
        owner = group.owner
        cols = np.arange(n_e)
        shape = (m * self.n_frames, n_e)
        scatter_lower = sp.csr_matrix((np.ones(n_e), (owner * self.n_frames + self.lower,
                                                      cols)), shape=shape).toarray()
        scatter_upper = sp.csr_matrix((np.ones(n_e), (owner * self.n_frames + self.upper,
                                                      cols)), shape=shape).toarray()
        self._sum = np.zeros((m, n_e))
        self._sum[owner, cols] = 1.0
        self._owner = owner
        self._scatter = np.concatenate([scatter_upper, scatter_lower], axis=1)
        keys = np.concatenate([self.lower[:, None], self.rest_offset,
                               self.rest_rotation.reshape(n_e, 9)], axis=1)
        unique, self._segment_of_entry = np.unique(keys, axis=0, return_inverse=True)
        self._segment_of_entry = self._segment_of_entry.reshape(-1)
        self._segment_lower = unique[:, 0].astype(int)
        self._segment_offset = unique[:, 1:4]
        self._segment_rotation_t = np.ascontiguousarray(
            np.swapaxes(unique[:, 4:].reshape(-1, 3, 3), 1, 2))
        self._hessian_t = np.ascontiguousarray(np.swapaxes(self.hessian, 1, 2))
        size = 6 * self.n_frames
        f = np.stack([self.lower, self.upper], axis=1)
        i6 = np.arange(6)
        rows = 6 * f[:, :, None, None, None] + i6[None, None, None, :, None]
        cols6 = 6 * f[:, None, :, None, None] + i6[None, None, None, None, :]
        self._tangent_index = (rows * size + cols6).reshape(-1)

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

    def _deformation(self, positions, rotations):
        """Return per entry the segment deformation δ (E, 6) and R_i, x_j - x_i of its segment."""
        # links.link_deformation inlined (pre-transposed rest rotations, R_i and x_j - x_i kept for
        # the caller): ~4 us less per evaluate, on the forward solve's Newton path
        lo = self._segment_lower
        r_i = rotations[lo]
        r_it = np.swapaxes(r_i, 1, 2)
        diff = positions[lo + 1] - positions[lo]
        delta = np.empty((lo.size, 6))
        delta[:, :3] = np.matmul(r_it, diff[:, :, None])[:, :, 0] - self._segment_offset
        delta[:, 3:] = so3_log(np.matmul(np.matmul(r_it, rotations[lo + 1]),
                                         self._segment_rotation_t))
        seg = self._segment_of_entry
        return delta[seg], r_i[seg], diff[seg]

    def evaluate(self, positions, rotations, displacements=True):
        """
        Return the Jacobian columns and the (second-order) volumes of all cavities.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).
        displacements : bool
            Also evaluate the volumes (else ``None`` is returned for them).

        Returns
        -------
        wrenches : (m, n + 1, 6) ndarray  [N, N*m per Pa]
            Frame wrenches per unit pressure.
        displacements : (m,) ndarray  [m^3]
            ``V0 + G0·δ + ½ δᵀ sym(H) δ`` summed over the parts.

        """
        delta, r_i, diff = self._deformation(positions, rotations)
        local = self.g0 + np.matmul(delta[:, None, :], self._hessian_t)[:, 0, :]
        world = np.matmul(r_i, local.reshape(-1, 2, 3).transpose(0, 2, 1))
        force = world[:, :, 0]
        both = np.empty((2 * len(delta), 6))
        n_e = len(delta)
        both[:n_e, :3] = force
        both[:n_e, 3:] = world[:, :, 1]
        both[n_e:, :3] = -force
        both[n_e:, 3:] = -world[:, :, 1] - cross(diff, force)
        wrenches = (self._scatter @ both).reshape(self.n_actuators, self.n_frames, 6)
        if not displacements:
            return wrenches, None
        vol = (self.v0 + np.einsum('ea,ea->e', self.g0, delta)
               + 0.5 * np.einsum('ea,eab,eb->e', delta, self._volume_hessian, delta))
        return wrenches, self._sum @ vol


def _linear_cavity_load_tangent(group, positions, rotations, pressures, symmetric):
    """Return ``-d(J_aᵀ p)/dq`` (frames 1..n) of a :class:`LinearCavityGroup`."""
    lo, up = group.lower, group.upper
    r_a, x_a, x_b = rotations[lo], positions[lo], positions[up]
    v = x_b - x_a
    delta = link_deformation(group.rest_offset, group.rest_rotation, x_a, r_a, x_b, rotations[up])
    local = group.g0 + np.einsum('eab,eb->ea', group.hessian, delta)
    p = pressures[group._owner]
    f = np.einsum('eij,ej->ei', r_a, local[:, :3])
    m = np.einsum('eij,ej->ei', r_a, local[:, 3:])
    jinv = so3_left_jacobian_inverse(delta[:, 3:])
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


class MeshCavityOracle:
    """
    Numpy evaluation of a skinned-mesh :class:`~cbha_inverse.core.actuation.cavities.CavityGroup`.

    Built from the group's cavities (their parts' points, triangles, lower frames and rest
    transforms), not from the arrays the group derived from them: every vertex follows its two
    frames by linear skinning along the segment axis, ``p = (1 - s)(x_a + R_a a) + s (x_b + R_b
    b)`` with ``s = clip(p0·d0 / |d0|², 0, 1)``, ``a = p0`` and ``b = Q0ᵀ (p0 - d0)`` (``p0``
    the vertex in segment coordinates); sparse matrices scatter the triangles' normals onto
    their vertices (a third of the area each: the volume gradient) and the vertex wrenches onto
    the frames (times the skinning weights and the cavity's gain).
    """

    def __init__(self, group):
        """Concatenate the parts and build the scatter matrices."""
        self.group = group
        self.n_frames, self.n_actuators = group.n_frames, len(group.cavities)
        frame_a, local_a, local_b, weight_b, triangles, owner_v, owner_t = ([] for _ in range(7))
        count = 0
        for j, cavity in enumerate(group.cavities):
            for part in cavity.parts:
                points = np.asarray(part.points, dtype=float)
                offset = np.asarray(part.rest_offset, dtype=float)
                rotation = np.asarray(part.rest_rotation, dtype=float)
                frame_a.append(np.full(len(points), part.lower))
                local_a.append(points)
                local_b.append(np.einsum('ji,vj->vi', rotation, points - offset))
                weight_b.append(np.clip(points @ offset / (offset @ offset), 0.0, 1.0))
                triangles.append(np.asarray(part.triangles, dtype=int) + count)
                owner_v.append(np.full(len(points), j))
                owner_t.append(np.full(len(part.triangles), j))
                count += len(points)
        self.frame_a = np.concatenate(frame_a)
        self.frame_b = self.frame_a + 1
        self.local_a, self.local_b = np.concatenate(local_a), np.concatenate(local_b)
        self.weight_b = np.concatenate(weight_b)
        self.weight_a = 1.0 - self.weight_b
        self.triangles = np.concatenate(triangles)
        owner_v, owner_t = np.concatenate(owner_v), np.concatenate(owner_t)
        gains = np.array([cavity.gain for cavity in group.cavities], dtype=float)
        m, n_v, n_t = self.n_actuators, count, len(self.triangles)
        rows = self.triangles.reshape(-1)
        self._vertex_triangle = sp.csr_matrix(
            (np.full(rows.size, 1.0 / 6.0), (rows, np.repeat(np.arange(n_t), 3))),
            shape=(n_v, n_t))
        self._triangle_sum = sp.csr_matrix((gains[owner_t], (owner_t, np.arange(n_t))),
                                           shape=(m, n_t))
        shape, vertices = (m * self.n_frames, n_v), np.arange(n_v)
        self._scatter_a = sp.csr_matrix(
            (self.weight_a * gains[owner_v], (owner_v * self.n_frames + self.frame_a, vertices)),
            shape=shape)
        self._scatter_b = sp.csr_matrix(
            (self.weight_b * gains[owner_v], (owner_v * self.n_frames + self.frame_b, vertices)),
            shape=shape)

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
            ``p``, ``R_a a`` and ``R_b b``.

        """
        levers_a = np.einsum('vij,vj->vi', rotations[self.frame_a], self.local_a)
        levers_b = np.einsum('vij,vj->vi', rotations[self.frame_b], self.local_b)
        points = (self.weight_a[:, None] * (positions[self.frame_a] + levers_a)
                  + self.weight_b[:, None] * (positions[self.frame_b] + levers_b))
        return points, levers_a, levers_b

    def _triangle_volumes(self, points):
        """Return the corners of every triangle and its signed volume with the origin."""
        t = self.triangles
        p0, p1, p2 = points[t[:, 0]], points[t[:, 1]], points[t[:, 2]]
        return p0, p1, p2, np.einsum('ti,ti->t', p0, np.cross(p1, p2)) / 6.0

    def volumes(self, positions, rotations):
        """
        Return the enclosed volume of every cavity (times its gain).

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.

        Returns
        -------
        (m,) ndarray  [m^3]
            Sum of ``p0 · (p1 × p2) / 6`` over each cavity's triangles.

        """
        points, _, _ = self.vertices(positions, rotations)
        return self._triangle_sum @ self._triangle_volumes(points)[3]

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
            Unused (the volumes come with the normals).

        Returns
        -------
        wrenches : (m, n + 1, 6) ndarray  [N, N*m per Pa]
            Frame wrenches per unit pressure (columns of ``J_aᵀ``).
        displacements : (m,) ndarray  [m^3]
            Cavity volumes (``δ_a`` up to a constant).

        """
        points, levers_a, levers_b = self.vertices(positions, rotations)
        p0, p1, p2, volumes = self._triangle_volumes(points)
        forces = self._vertex_triangle @ np.cross(p1 - p0, p2 - p0)
        wrenches = (self._scatter_a @ point_wrenches(levers_a, forces)
                    + self._scatter_b @ point_wrenches(levers_b, forces))
        return (wrenches.reshape(self.n_actuators, self.n_frames, 6),
                self._triangle_sum @ volumes)


class ActuatorSetOracle:
    """Numpy evaluation of an :class:`~cbha_inverse.core.actuation.actuators.ActuatorSet`."""

    def __init__(self, actuators):
        """Wrap every group."""
        self.groups = tuple(oracle(g) for g in actuators.groups)
        self._columns = actuators._columns
        self.n_frames, self.n_actuators = actuators.n_frames, actuators.n_actuators

    def evaluate(self, positions, rotations, displacements=True):
        """
        Return all Jacobian columns and actuator displacements.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations (frame axes → world).
        displacements : bool
            Also evaluate ``δ_a`` (a group may return ``None`` otherwise).

        Returns
        -------
        wrenches : (m, n + 1, 6) ndarray
            Columns of ``J_aᵀ`` (frame wrenches per unit actuation, world axes).
        displacements : (m,) ndarray
            ``δ_a`` up to constants (cable shortening, cavity volume).

        """
        if len(self.groups) == 1:
            return self.groups[0].evaluate(positions, rotations, displacements)
        wrenches = np.empty((self.n_actuators, self.n_frames, 6))
        out = np.empty(self.n_actuators)
        for g, cols in zip(self.groups, self._columns):
            wrenches[cols], out[cols] = g.evaluate(positions, rotations, True)
        return wrenches, out

    def load_tangent(self, positions, rotations, actuation, symmetric=True):
        """
        Return the load stiffness ``-d(J_aᵀ λ)/dq`` of the groups that provide one.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray
            Actuation in column order.
        symmetric : bool
            Symmetric part only (for a Cholesky factorization).

        Returns
        -------
        (6n, 6n) ndarray or None
            ``None`` when no group has a load stiffness.

        """
        total = None
        for g, cols in zip(self.groups, self._columns):
            if hasattr(g, 'load_tangent'):
                part = g.load_tangent(positions, rotations, actuation[cols], symmetric)
                total = part if total is None else total + part
        return total

    def loads(self, positions, rotations, actuation):
        """
        Return the frame wrenches ``J_aᵀ λ`` of an actuation.

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        actuation : (m,) ndarray  [N or Pa]
            Tensions / pressures.

        Returns
        -------
        (n + 1, 6) ndarray  [N, N*m]
            Wrenches per frame, world axes (row 0 acts on the fixed base).

        """
        wrenches, _ = self.evaluate(positions, rotations)
        return np.einsum('m,mfa->fa', np.asarray(actuation, dtype=float), wrenches)
