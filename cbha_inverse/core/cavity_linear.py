"""
Pressure cavities condensed per segment onto its two frames (the online cavity model).

Each skinned segment cavity (:mod:`cbha_inverse.core.cavity`) is, like the compliance of the
segment, reduced to its two frames: the wrench on the upper frame per unit pressure is affine in
the corotational deformation of the segment, ``G(δ) ≈ G0 + H δ`` (frame-i axes), fitted by
central differences of the exact skinned mesh at rest, and the lower frame receives the
equilibrating wrench (a closed cavity exerts no net wrench). One small operation per segment
instead of one per vertex; error second order in the segment deformation (tested against the
mesh). The load stiffness of the model is exact and lets Newton's method converge at high
pressure.
"""

from cbha_inverse.core.actuation import cross
from cbha_inverse.core.cavity import Cavity, CavityGroup, CavityPart
from cbha_inverse.core.links import link_deformation
from cbha_inverse.core.se3 import hat, so3_exp, so3_left_jacobian_inverse, so3_log
import numpy as np
import scipy.sparse as sp


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
        self.owner = owner
        cols = np.arange(n_e)
        shape = (m * self.n_frames, n_e)
        self._scatter_lower = sp.csr_matrix((np.ones(n_e), (owner * self.n_frames + self.lower,
                                                            cols)), shape=shape).toarray()
        self._scatter_upper = sp.csr_matrix((np.ones(n_e), (owner * self.n_frames + self.upper,
                                                            cols)), shape=shape).toarray()
        self._sum = np.zeros((m, n_e))
        self._sum[owner, cols] = 1.0
        self._owner = owner
        self._scatter = np.concatenate([self._scatter_upper, self._scatter_lower], axis=1)
        # the deformation is computed once per segment and shared by its cavities
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
