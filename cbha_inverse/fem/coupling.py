"""
Rigid coupling of FE node sets to 6-DoF frames by elimination.

Each node k of a coupled set follows its frame f rigidly (small rotations):
u_k = u_f + theta_f x (p_k - x_f). The full displacement vector is written u = T z with the
reduced unknowns z = [free node displacements; 6 dofs per frame]; clamped nodes have zero rows.
The reduced stiffness is T^T K T (the paper's mixed system of FE nodes and frames, eq. 1).
"""

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp


@dataclass(frozen=True)
class RigidCoupling:
    """
    Transformation from reduced unknowns to full nodal displacements.

    Attributes
    ----------
    transformation : scipy.sparse.csr_matrix
        T, shape (3 N, 3 n_free + 6 n_frames).
    free_nodes : (n_free,) int ndarray
        Nodes that keep their own 3 dofs (reduced dofs 3 i .. 3 i + 2).
    frame_origins : (n_frames, 3) ndarray  [m]
        Reference point x_f of each frame.
    frame_nodes : tuple of (k,) int ndarray
        Nodes coupled to each frame.

    """

    transformation: sp.csr_matrix
    free_nodes: np.ndarray
    frame_origins: np.ndarray
    frame_nodes: tuple

    @property
    def n_frames(self):
        """Return the number of coupled frames."""
        return len(self.frame_origins)

    @property
    def n_reduced(self):
        """Return the number of reduced unknowns."""
        return self.transformation.shape[1]

    def frame_dofs(self, index):
        """
        Return the 6 reduced-dof indices (dx, dy, dz, rx, ry, rz) of frame ``index``.

        Parameters
        ----------
        index : int
            Frame index (negative counts from the last frame).

        Returns
        -------
        (6,) int ndarray
            Column indices in T.

        """
        index = range(self.n_frames)[index]
        return 3 * len(self.free_nodes) + 6 * index + np.arange(6)

    def selector(self, index):
        """
        Return J, the (6, n_reduced) Boolean selector of one frame's dofs (paper eq. 3).

        Parameters
        ----------
        index : int
            Frame index.

        Returns
        -------
        scipy.sparse.csr_matrix
            J with J z = the frame's 6 dofs.

        """
        cols = self.frame_dofs(index)
        return sp.csr_matrix((np.ones(6), (np.arange(6), cols)), shape=(6, self.n_reduced))


def rigid_coupling(n_nodes, frame_nodes, frame_origins, clamped_nodes=()):
    """
    Build the elimination transformation u = T z for rigidly coupled node sets.

    Parameters
    ----------
    n_nodes : int
        Number of mesh nodes N (all referenced by elements).
    frame_nodes : sequence of (k_f,) int arrays
        Nodes coupled to each frame (disjoint sets).
    frame_origins : (n_frames, 3) array_like  [m]
        Reference point of each frame (the point whose displacement and rotation are the dofs).
    clamped_nodes : (c,) int array_like
        Nodes with zero displacement (the clamped lower frame).

    Returns
    -------
    RigidCoupling
        T and the dof bookkeeping.

    Raises
    ------
    ValueError
        If node sets overlap or are empty.

    """
    frame_nodes = tuple(np.asarray(f, dtype=np.int64) for f in frame_nodes)
    origins = np.asarray(frame_origins, dtype=float).reshape(-1, 3)
    if len(frame_nodes) != len(origins):
        raise ValueError('one origin per frame node set is needed')
    clamped = np.asarray(clamped_nodes, dtype=np.int64)
    owner = np.full(n_nodes, -2, dtype=np.int64)
    owner[clamped] = -1
    for j, nodes in enumerate(frame_nodes):
        if len(nodes) == 0:
            raise ValueError(f'frame {j} has no coupled nodes')
        if np.any(owner[nodes] != -2):
            raise ValueError(f'frame {j} node set overlaps another set or the clamped set')
        owner[nodes] = j
    free = np.flatnonzero(owner == -2)
    return RigidCoupling(None, free, origins, frame_nodes)


def coupling_matrix(coupling, points):
    """
    Fill the transformation matrix of a coupling built by :func:`rigid_coupling`.

    Parameters
    ----------
    coupling : RigidCoupling
        Bookkeeping (its ``transformation`` may be None).
    points : (N, 3) ndarray  [m]
        Node reference coordinates.

    Returns
    -------
    RigidCoupling
        The same coupling with ``transformation`` set.

    """
    n_nodes = len(points)
    free = coupling.free_nodes
    rows = [(3 * free[:, None] + np.arange(3)).ravel()]
    cols = [np.arange(3 * len(free))]
    vals = [np.ones(3 * len(free))]
    base = 3 * len(free)
    for j, nodes in enumerate(coupling.frame_nodes):
        r = points[nodes] - coupling.frame_origins[j]
        # u_k = u_f + theta x r = u_f - hat(r) theta
        block = np.zeros((len(nodes), 3, 6))
        block[:, :, :3] = np.eye(3)
        block[:, 0, 4], block[:, 0, 5] = r[:, 2], -r[:, 1]
        block[:, 1, 3], block[:, 1, 5] = -r[:, 2], r[:, 0]
        block[:, 2, 3], block[:, 2, 4] = r[:, 1], -r[:, 0]
        row = np.broadcast_to((3 * nodes[:, None] + np.arange(3))[:, :, None], block.shape)
        col = np.broadcast_to(base + 6 * j + np.arange(6), block.shape)
        keep = block != 0.0
        rows.append(row[keep])
        cols.append(col[keep])
        vals.append(block[keep])
    n_red = base + 6 * len(coupling.frame_nodes)
    t_mat = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(3 * n_nodes, n_red)).tocsr()
    return RigidCoupling(t_mat, free, coupling.frame_origins, coupling.frame_nodes)


def build_coupling(points, frame_nodes, frame_origins, clamped_nodes=()):
    """
    Return the complete rigid coupling (bookkeeping and T) in one call.

    Parameters
    ----------
    points : (N, 3) ndarray  [m]
        Node coordinates.
    frame_nodes : sequence of int arrays
        Node set of each frame.
    frame_origins : (n_frames, 3) array_like  [m]
        Frame reference points.
    clamped_nodes : int array_like
        Clamped nodes.

    Returns
    -------
    RigidCoupling
        With ``transformation`` filled.

    """
    bookkeeping = rigid_coupling(len(points), frame_nodes, frame_origins, clamped_nodes)
    return coupling_matrix(bookkeeping, np.asarray(points, dtype=float))
