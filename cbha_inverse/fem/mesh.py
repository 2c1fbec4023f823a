"""
Plain tetrahedral mesh data class and node-set helpers (no gmsh, no file I/O).

Node ordering follows gmsh (and meshio's ``tetra`` / ``tetra10``): the four vertices first, then
the six mid-edge nodes on edges (0,1), (1,2), (0,2), (0,3), (2,3), (1,3).
"""

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class TetMesh:
    """
    An immutable tetrahedral mesh of order 1 (4-node) or 2 (10-node).

    Attributes
    ----------
    points : (N, 3) ndarray  [m]
        Node coordinates.
    tets : (E, 4) or (E, 10) int ndarray
        Element connectivity, gmsh node order.

    """

    points: np.ndarray
    tets: np.ndarray

    def __post_init__(self):
        """Validate shapes and freeze the arrays."""
        points = np.ascontiguousarray(self.points, dtype=float)
        tets = np.ascontiguousarray(self.tets, dtype=np.int64)
        if points.ndim != 2 or points.shape[1] != 3:
            raise ValueError(f'points must be (N, 3), got {points.shape}')
        if tets.ndim != 2 or tets.shape[1] not in (4, 10):
            raise ValueError(f'tets must be (E, 4) or (E, 10), got {tets.shape}')
        if tets.size and (tets.min() < 0 or tets.max() >= len(points)):
            raise ValueError('tets index outside points')
        points.setflags(write=False)
        tets.setflags(write=False)
        object.__setattr__(self, 'points', points)
        object.__setattr__(self, 'tets', tets)

    @property
    def order(self):
        """Return the element order: 1 for 4-node, 2 for 10-node tetrahedra."""
        return 1 if self.tets.shape[1] == 4 else 2

    @property
    def n_nodes(self):
        """Return the number of nodes."""
        return len(self.points)

    @property
    def n_elements(self):
        """Return the number of tetrahedra."""
        return len(self.tets)

    def used_nodes(self):
        """Return the sorted indices of the nodes referenced by at least one element."""
        return np.unique(self.tets)


def compact(mesh):
    """
    Drop nodes that no element references and renumber.

    Parameters
    ----------
    mesh : TetMesh
        Input mesh (gmsh output may contain geometric points without elements).

    Returns
    -------
    TetMesh
        The same elements on the referenced nodes only.

    """
    used = mesh.used_nodes()
    if len(used) == mesh.n_nodes:
        return mesh
    new_index = -np.ones(mesh.n_nodes, dtype=np.int64)
    new_index[used] = np.arange(len(used))
    return TetMesh(mesh.points[used], new_index[mesh.tets])


def nodes_on_plane(mesh, x_value, tolerance=None, axis=0):
    """
    Return the indices of used nodes lying on the plane ``points[:, axis] == x_value``.

    Parameters
    ----------
    mesh : TetMesh
        The mesh.
    x_value : float  [m]
        Plane coordinate.
    tolerance : float, optional  [m]
        Distance tolerance; default 1e-9 times the mesh bounding-box size.
    axis : int
        Coordinate axis normal to the plane (0 = x).

    Returns
    -------
    (k,) int ndarray
        Sorted node indices.

    """
    used = mesh.used_nodes()
    coords = mesh.points[used]
    if tolerance is None:
        extent = float(np.ptp(coords, axis=0).max()) if len(coords) else 1.0
        tolerance = 1e-7 * max(extent, 1e-12)
    return used[np.abs(coords[:, axis] - x_value) <= tolerance]
