"""
Segment geometry and tetrahedral meshing with gmsh (the only gmsh user; imported lazily).

Conventions: segment axis +x, lower vertebra frame at the origin, upper frame at (L, 0, 0),
metres. Every function opens and closes its own gmsh session.
"""

import contextlib

from cbha_inverse.fem.bellows import corrugation_profile
from cbha_inverse.fem.mesh import compact, TetMesh
import numpy as np


@contextlib.contextmanager
def gmsh_session(mesh_size, order, name='segment', curved=True):
    """
    Open a quiet, single-threaded gmsh session configured for tetrahedra of the given order.

    Parameters
    ----------
    mesh_size : float  [m]
        Target element size (gmsh ``Mesh.MeshSizeMax``).
    order : {1, 2}
        Element order.
    name : str
        gmsh model name.
    curved : bool
        Place P2 mid-edge nodes on the curved geometry (isoparametric); False keeps straight
        edges (robust for thin corrugated walls, geometric error O(h^2)).

    Yields
    ------
    module
        The initialised ``gmsh`` module.

    """
    import gmsh
    if order not in (1, 2):
        raise ValueError(f'element order must be 1 or 2, got {order}')
    if not mesh_size > 0:
        raise ValueError(f'mesh_size must be positive, got {mesh_size}')
    gmsh.initialize(readConfigFiles=False, interruptible=False)
    try:
        gmsh.option.setNumber('General.Terminal', 0)
        gmsh.option.setNumber('General.Verbosity', 1)
        gmsh.option.setNumber('General.NumThreads', 1)
        gmsh.option.setNumber('Mesh.MeshSizeMax', float(mesh_size))
        gmsh.option.setNumber('Mesh.MeshSizeMin', 0.2 * float(mesh_size))
        gmsh.option.setNumber('Mesh.MeshSizeFromCurvature', 0)
        gmsh.option.setNumber('Mesh.ElementOrder', 1)
        gmsh.option.setNumber('Mesh.RandomSeed', 1)
        gmsh.option.setNumber('Mesh.SecondOrderLinear', 0 if curved else 1)
        gmsh.model.add(name)
        yield gmsh
    finally:
        gmsh.finalize()


def mesh_current_model(gmsh, order):
    """
    Mesh the current gmsh model in 3D and return its tetrahedra as a :class:`TetMesh`.

    Parameters
    ----------
    gmsh : module
        An initialised gmsh with a synchronised geometry.
    order : {1, 2}
        Element order (order 2 places mid-edge nodes on the curved geometry).

    Returns
    -------
    TetMesh
        Compacted mesh (only nodes referenced by tetrahedra).

    """
    gmsh.model.mesh.generate(3)
    if order == 2:
        gmsh.model.mesh.setOrder(2)
    tags, coords, _ = gmsh.model.mesh.getNodes()
    points = np.asarray(coords, dtype=float).reshape(-1, 3)
    index = np.zeros(int(tags.max()) + 1, dtype=np.int64)
    index[tags.astype(np.int64)] = np.arange(len(tags))
    elem_type = 4 if order == 1 else 11
    _, node_tags = gmsh.model.mesh.getElementsByType(elem_type)
    n_per = 4 if order == 1 else 10
    tets = index[np.asarray(node_tags, dtype=np.int64)].reshape(-1, n_per)
    return compact(TetMesh(points, tets))


def cylinder_mesh(length, outer_radius, inner_radius=0.0, *, mesh_size, order=2, n_segments=1):
    """
    Mesh a solid or hollow circular cylinder along +x from x = 0 to x = n_segments * length.

    With ``n_segments > 1`` the body is split by conforming planes at x = i * length (the
    interfaces where rigid vertebrae are attached in the full-FE reference model).

    Parameters
    ----------
    length : float  [m]
        Length of one segment.
    outer_radius : float  [m]
        Outer radius.
    inner_radius : float  [m]
        Inner radius (0 for a solid cylinder).
    mesh_size : float  [m]
        Target element size.
    order : {1, 2}
        Element order.
    n_segments : int
        Number of stacked segments.

    Returns
    -------
    TetMesh
        The mesh.

    """
    if not 0.0 <= inner_radius < outer_radius or length <= 0:
        raise ValueError('need length > 0 and 0 <= inner_radius < outer_radius')
    with gmsh_session(mesh_size, order, 'cylinder') as gmsh:
        occ = gmsh.model.occ
        vols = []
        for i in range(int(n_segments)):
            vol = occ.addCylinder(i * length, 0, 0, length, 0, 0, outer_radius)
            if inner_radius > 0:
                hole = occ.addCylinder(i * length, 0, 0, length, 0, 0, inner_radius)
                vol = occ.cut([(3, vol)], [(3, hole)])[0][0][1]
            vols.append((3, vol))
        if len(vols) > 1:
            occ.fragment(vols[:1], vols[1:])
        occ.synchronize()
        return mesh_current_model(gmsh, order)


def geo_file_mesh(path, *, mesh_size, order=2):
    """
    Mesh a gmsh ``.geo`` (or any gmsh-readable CAD) file in 3D.

    Parameters
    ----------
    path : path-like
        Geometry file in segment coordinates (axis +x, lower face on the plane of smallest x).
    mesh_size : float  [m]
        Target element size.
    order : {1, 2}
        Element order.

    Returns
    -------
    TetMesh
        The mesh.

    """
    with gmsh_session(mesh_size, order, 'geo') as gmsh:
        gmsh.open(str(path))
        gmsh.option.setNumber('Mesh.MeshSizeMax', float(mesh_size))
        return mesh_current_model(gmsh, order)


def bellows_tube_mesh(geometry, *, mesh_size, order=2, circumferential_elements=None,
                      through_thickness=None, curved=True, samples_per_pitch=16):
    """
    Mesh one corrugated bellows tube of a CBHA segment, on the x axis.

    The wall profile (inner radius from :func:`corrugation_profile`, outer = inner + wall
    thickness, measured radially) spans x = t_v / 2 to L - t_v / 2 (the faces of the two rigid,
    unmeshed vertebrae). Its triangle mesh of size ``mesh_size`` is revolved about the x axis in
    ``circumferential_elements`` layers (prisms split into tetrahedra), so the wall is resolved
    through its thickness in the meridional plane, where the corrugation bends.

    Parameters
    ----------
    geometry : cbha_inverse.fem.segment_spec.BellowsGeometry
        Bellows segment geometry (of ``meshes/cbha_segment_geometry.yaml``, say).
    mesh_size : float  [m]
        Element size in the wall profile.
    order : {1, 2}
        Element order.
    circumferential_elements : int, optional
        Layers around the tube, rounded up to a multiple of 3 (default: circumferential element
        length about 4 x mesh_size, see :func:`bellows_mesh_counts`).
    through_thickness : int, optional
        Element layers through the wall (default: wall / mesh_size, at least 2).
    curved : bool
        Isoparametric P2 (mid-edge nodes on the revolved geometry); if that inverts an
        element, the tube is remeshed with straight edges.
    samples_per_pitch : int
        Spline control points per corrugation pitch.

    Returns
    -------
    TetMesh
        Mesh of one tube, axis = x axis, in segment x coordinates.

    """
    g = geometry
    x0, x1 = g.wall_start, g.wall_end
    s = np.linspace(0.0, x1 - x0, int(samples_per_pitch * g.corrugation_periods) + 1)
    r_in = corrugation_profile(s, g.tube_mean_radius, g.corrugation_amplitude,
                               g.corrugation_pitch)
    r_out = r_in + g.wall_thickness
    n_circ, n_thick = bellows_mesh_counts(g, mesh_size)
    n_circ = n_circ if circumferential_elements is None else circumferential_elements
    n_thick = n_thick if through_thickness is None else through_thickness
    n_layers = max(1, int(np.ceil(n_circ / 3)))
    with gmsh_session(mesh_size, order, 'bellows_tube', curved=curved) as gmsh:
        geo = gmsh.model.geo
        inner = [geo.addPoint(x0 + si, ri, 0.0) for si, ri in zip(s, r_in)]
        outer = [geo.addPoint(x0 + si, ro, 0.0) for si, ro in zip(s, r_out)]
        c_in = geo.addSpline(inner)
        c_out = geo.addSpline(outer)
        c_lo = geo.addLine(inner[0], outer[0])
        c_hi = geo.addLine(inner[-1], outer[-1])
        loop = geo.addCurveLoop([c_in, c_hi, -c_out, -c_lo])
        surf = geo.addPlaneSurface([loop])
        ents = [(2, surf)]
        arc = np.sum(np.hypot(np.diff(s), np.diff(r_in)))
        n_along = max(2, int(np.ceil(arc / mesh_size))) + 1
        geo.mesh.setTransfiniteCurve(c_in, n_along)
        geo.mesh.setTransfiniteCurve(c_out, n_along)
        geo.mesh.setTransfiniteCurve(c_lo, n_thick + 1)
        geo.mesh.setTransfiniteCurve(c_hi, n_thick + 1)
        geo.mesh.setTransfiniteSurface(surf, 'Alternate')
        for _ in range(3):
            out = geo.revolve(ents, 0, 0, 0, 1, 0, 0, 2.0 * np.pi / 3.0, numElements=[n_layers])
            ents = [out[0]]
        geo.synchronize()
        mesh = merge_coincident_nodes(mesh_current_model(gmsh, order))
    if order == 2 and curved and not _jacobians_positive(mesh):
        return bellows_tube_mesh(geometry, mesh_size=mesh_size, order=order,
                                 circumferential_elements=n_circ, through_thickness=n_thick,
                                 curved=False, samples_per_pitch=samples_per_pitch)
    return mesh


def _jacobians_positive(mesh):
    """Return True if every quadrature point of every element has det J > 0."""
    from cbha_inverse.fem.elasticity import shape_gradients
    try:
        shape_gradients(mesh)
    except ValueError:
        return False
    return True


def bellows_mesh_counts(geometry, mesh_size):
    """
    Return the default (circumferential, through-thickness) element counts of a bellows tube.

    Parameters
    ----------
    geometry : cbha_inverse.fem.segment_spec.BellowsGeometry
        Bellows segment geometry.
    mesh_size : float  [m]
        Profile element size.

    Returns
    -------
    (int, int)
        Circumferential elements (multiple of 3, element length about 4 x mesh_size, at least
        24) and wall
        layers (wall / mesh_size rounded, at least 2).

    """
    circ = 2.0 * np.pi * geometry.tube_mean_radius / (4.0 * mesh_size)
    n_circ = 3 * max(8, int(np.ceil(circ / 3.0)))
    n_thick = max(2, int(round(geometry.wall_thickness / mesh_size)))
    return n_circ, n_thick


def merge_coincident_nodes(mesh, tolerance=1e-9):
    """
    Merge nodes closer than ``tolerance`` (e.g. on the seam of a 360 deg revolution).

    Parameters
    ----------
    mesh : TetMesh
        Input mesh.
    tolerance : float  [m]
        Merge distance (coordinates are snapped to this grid).

    Returns
    -------
    TetMesh
        Mesh without duplicate nodes.

    """
    keys = np.round(mesh.points / tolerance).astype(np.int64)
    _, first, inverse = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    return compact(TetMesh(mesh.points[first], inverse.ravel()[mesh.tets]))
