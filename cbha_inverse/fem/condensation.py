"""
Condensation of a volumetric FE segment onto its two vertebra frames.

Section III, eqs. (1)-(3) of Bosman et al. 2015: the nodes on the lower face are clamped (lower
frame fixed), the nodes on the upper face follow the upper frame rigidly, the reduced stiffness
T^T K T is factorised once and the 6 unit loads at the upper frame give C = J K^-1 J^T in the
lower frame's axes (eqs. (2)-(3); docs/design.md).
"""

from dataclasses import dataclass, field
import time

from cbha_inverse.core.links import checked_compliance
from cbha_inverse.fem.coupling import build_coupling
from cbha_inverse.fem.elasticity import assemble_stiffness, mesh_volume
from cbha_inverse.fem.mesh import nodes_on_plane, TetMesh
from cbha_inverse.fem.segment_spec import BellowsGeometry, CylinderGeometry
import numpy as np
import scipy.sparse.linalg as spla


@dataclass(frozen=True)
class CondensedSegment:
    """
    Result of a condensation: the 6x6 compliance of one segment and its provenance.

    Attributes
    ----------
    compliance : (6, 6) ndarray  [m/N, rad/(N m)]
        C in the paper's convention (symmetric positive definite).
    rest_offset : (3,) ndarray  [m]
        Upper frame origin in lower frame axes.
    rest_rotation : (3, 3) ndarray
        Upper frame axes in lower frame axes.
    mass : float  [kg]
        Segment mass (material plus the lumped vertebra mass).
    element_order : int
        1 or 2.
    n_nodes, n_elements : int
        Mesh size.
    n_dofs : int
        Reduced unknowns solved for.
    asymmetry : float
        max |C_ij - C_ji| / sqrt(C_ii C_jj) before symmetrising.
    mesh_size : float  [m]
        Target element size used (NaN if the mesh was given).
    timings : dict
        Seconds spent in 'mesh', 'assembly', 'factor', 'solve', 'total'.
    warnings : tuple of str
        What the user should know about the result: volumetric locking of the element order
        at this Poisson ratio (:func:`locking_warnings`).
    cavities : tuple of (str, (P, 3) ndarray, (T, 3) int ndarray)
        The pressure cavities of the segment (name, surface points [m] in segment coordinates,
        outward-oriented triangles); empty for a segment without cavities.

    """

    compliance: np.ndarray
    rest_offset: np.ndarray
    rest_rotation: np.ndarray
    mass: float
    element_order: int
    n_nodes: int
    n_elements: int
    n_dofs: int
    asymmetry: float
    mesh_size: float
    timings: dict = field(default_factory=dict)
    warnings: tuple = ()
    cavities: tuple = ()

    @property
    def stiffness(self):
        """Return the 6x6 stiffness K = C^-1."""
        return np.linalg.inv(self.compliance)


def factorize_spd(matrix):
    """
    Factorise a sparse symmetric positive definite matrix with SuperLU (symmetric mode).

    Parameters
    ----------
    matrix : scipy.sparse matrix
        (n, n) SPD matrix.

    Returns
    -------
    scipy.sparse.linalg.SuperLU
        Factor with ``.solve``.

    """
    return spla.splu(matrix.tocsc(), permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                     options={'SymmetricMode': True})


def frame_compliance(stiffness, coupling, frame=-1):
    """
    Return the 6x6 compliance of one coupled frame: C = J (T^T K T)^-1 J^T (paper eq. 2-3).

    Parameters
    ----------
    stiffness : scipy.sparse matrix
        Full (3N, 3N) FE stiffness.
    coupling : RigidCoupling
        Elimination with the clamped set and the coupled frames.
    frame : int
        Frame whose compliance is returned (default the last one).

    Returns
    -------
    compliance : (6, 6) ndarray
        Raw (unsymmetrised) compliance.
    timings : dict
        Seconds for 'reduce', 'factor', 'solve'.

    """
    t0 = time.perf_counter()
    t_mat = coupling.transformation
    k_red = (t_mat.T @ stiffness @ t_mat).tocsc()
    t1 = time.perf_counter()
    lu = factorize_spd(k_red)
    t2 = time.perf_counter()
    rhs = coupling.selector(frame).T.toarray()
    sol = lu.solve(rhs)
    compliance = sol[coupling.frame_dofs(frame)]
    t3 = time.perf_counter()
    return compliance, {'reduce': t1 - t0, 'factor': t2 - t1, 'solve': t3 - t2}


def condense_mesh(mesh, youngs_modulus, poisson_ratio, *, lower_x, upper_x, segment_length,
                  density=0.0, extra_mass=0.0, mesh_size=float('nan'), mesh_time=0.0):
    """
    Condense a meshed segment whose end faces are the planes x = lower_x and x = upper_x.

    Parameters
    ----------
    mesh : TetMesh
        Segment mesh in segment coordinates.
    youngs_modulus : float  [Pa]
        Young's modulus.
    poisson_ratio : float
        Poisson's ratio.
    lower_x, upper_x : float  [m]
        Planes of the nodes coupled to the lower (clamped) and upper frame.
    segment_length : float  [m]
        Upper frame origin is (segment_length, 0, 0); lower frame at the origin.
    density : float  [kg/m^3]
        Material density for the mass.
    extra_mass : float  [kg]
        Rigid mass added to the segment (e.g. one vertebra).
    mesh_size : float  [m]
        Recorded provenance.
    mesh_time : float  [s]
        Meshing time, recorded in the timings.

    Returns
    -------
    CondensedSegment
        The condensed segment.

    """
    t0 = time.perf_counter()
    lower = nodes_on_plane(mesh, lower_x)
    upper = nodes_on_plane(mesh, upper_x)
    if len(lower) == 0 or len(upper) == 0:
        raise ValueError(f'no nodes on the end planes x={lower_x} / x={upper_x}')
    offset = np.array([segment_length, 0.0, 0.0])
    coupling = build_coupling(mesh.points, [upper], [offset], clamped_nodes=lower)
    stiffness = assemble_stiffness(mesh, youngs_modulus, poisson_ratio)
    t1 = time.perf_counter()
    raw, sub = frame_compliance(stiffness, coupling)
    compliance, asym = checked_compliance(raw, 'condensed compliance')
    mass = density * mesh_volume(mesh) + extra_mass if density else extra_mass
    t2 = time.perf_counter()
    timings = {'mesh': mesh_time, 'assembly': t1 - t0, **sub}
    timings['total'] = mesh_time + t2 - t0
    return CondensedSegment(compliance, offset, np.eye(3), float(mass), mesh.order,
                            mesh.n_nodes, mesh.n_elements, coupling.n_reduced, asym,
                            float(mesh_size), timings,
                            locking_warnings(mesh.order, poisson_ratio))


#: Poisson ratio from which each element order locks (``cbha_report stability``, cylinder
#: L 40 mm x R 10 mm, 3 mm mesh: P1 torsion compliance 6 % below its nu = 0.3 value on the
#: same mesh at nu = 0.45, 24 % at 0.49, 95 % at 0.4999; P2 torsion within 0.2 %, but its
#: bending compliance keeps falling, ~8 % below its nu = 0.3 value at 0.499, ~9 % at 0.4999)
LOCKING_POISSON_RATIO = {1: 0.45, 2: 0.499}


def locking_warnings(order, poisson_ratio):
    """
    Warn when tetrahedra of this order lock volumetrically at this Poisson ratio.

    Parameters
    ----------
    order : {1, 2}
        Element order.
    poisson_ratio : float
        Poisson's ratio.

    Returns
    -------
    tuple of str
        Empty below ``LOCKING_POISSON_RATIO[order]``.

    """
    limit = LOCKING_POISSON_RATIO[int(order)]
    if float(poisson_ratio) < limit:
        return ()
    advice = 'use order 2 elements' if int(order) == 1 else 'keep nu below 0.499'
    return (f'P{int(order)} tetrahedra lock at nu = {float(poisson_ratio):g} (>= {limit:g}): '
            f'the condensed compliance is too stiff; {advice}',)


def _given(value, default):
    """Return ``value`` unless it is None (an explicit 0.0 is honoured), else ``default``."""
    return default if value is None else value


def condense_cylinder(length, outer_radius, inner_radius=0.0, *, youngs_modulus, poisson_ratio,
                      mesh_size, order=2, density=0.0):
    """
    Condense a solid or hollow cylinder segment with rigid end faces (the test geometry).

    Parameters
    ----------
    length : float  [m]
        Segment length (axis +x).
    outer_radius, inner_radius : float  [m]
        Radii (inner 0 for a solid cylinder).
    youngs_modulus : float  [Pa]
        Young's modulus.
    poisson_ratio : float
        Poisson's ratio.
    mesh_size : float  [m]
        Target element size.
    order : {1, 2}
        Element order.
    density : float  [kg/m^3]
        Density for the mass (0: massless).

    Returns
    -------
    CondensedSegment
        ``.compliance`` is directly comparable with ``timoshenko_compliance``.

    """
    from cbha_inverse.fem.geometry import cylinder_mesh
    t0 = time.perf_counter()
    mesh = cylinder_mesh(length, outer_radius, inner_radius, mesh_size=mesh_size, order=order)
    mesh_time = time.perf_counter() - t0
    return condense_mesh(mesh, youngs_modulus, poisson_ratio, lower_x=0.0, upper_x=length,
                         segment_length=length, density=density, mesh_size=mesh_size,
                         mesh_time=mesh_time)


def shift_stiffness(stiffness, offset):
    """
    Move the reference point of a 6x6 frame stiffness from a to b = a + offset.

    With A = [[I, 0], [hat(r), I]], r = b - a, a wrench at b is A w_b at a and the motion at b
    is A^T times the motion at a, so C_b = A^T C_a A and K_b = A^-1 K_a A^-T.

    Parameters
    ----------
    stiffness : (6, 6) ndarray
        K at point a, [force; moment] vs [translation; rotation].
    offset : (3,) array_like  [m]
        r = b - a.

    Returns
    -------
    (6, 6) ndarray
        K at point b.

    """
    r = np.asarray(offset, dtype=float)
    a_inv = np.eye(6)
    a_inv[3:, :3] = -np.array([[0.0, -r[2], r[1]], [r[2], 0.0, -r[0]], [-r[1], r[0], 0.0]])
    return a_inv @ stiffness @ a_inv.T


def condense_bellows(spec, *, mesh_size=None, order=None, youngs_modulus=None,
                     poisson_ratio=None):
    """
    Condense a bellows segment (identical tubes between two rigid vertebrae).

    The tubes touch only through the rigid vertebrae, so the segment stiffness is the sum of the
    tube stiffnesses moved to the segment axis (:func:`shift_stiffness`): one tube is meshed and
    condensed about its own axis, then placed at each tube centre. This equals the condensation
    of the mesh made of the translated copies (tested), at a third of the cost.

    Parameters
    ----------
    spec : cbha_inverse.fem.segment_spec.SegmentSpec
        A bellows segment file (:func:`cbha_inverse.fem.segment_spec.read_segment_spec`).
    mesh_size : float, optional  [m]
        Override of ``mesh.mesh_size``.
    order : {1, 2}, optional
        Override of ``mesh.order``.
    youngs_modulus, poisson_ratio : float, optional
        Overrides of the material.

    Returns
    -------
    CondensedSegment
        Segment compliance at the upper vertebra frame; counts cover all tubes; ``cavities``
        holds one closed surface per tube.

    """
    from cbha_inverse.fem.bellows import cavity_surface, geometry_tube_centres
    from cbha_inverse.fem.geometry import bellows_tube_mesh
    geom, mat = spec.geometry, spec.material
    mesh_size = float(_given(mesh_size, spec.mesh.mesh_size))
    order = int(_given(order, spec.mesh.order))
    t0 = time.perf_counter()
    mesh = bellows_tube_mesh(geom, mesh_size=mesh_size, order=order)
    mesh_time = time.perf_counter() - t0
    tube = condense_mesh(mesh, _given(youngs_modulus, mat.youngs_modulus),
                         _given(poisson_ratio, mat.poisson_ratio), lower_x=geom.wall_start,
                         upper_x=geom.wall_end, segment_length=geom.segment_length,
                         density=mat.density, mesh_size=mesh_size, mesh_time=mesh_time)
    t1 = time.perf_counter()
    centres = geometry_tube_centres(geom)
    stiffness = sum(shift_stiffness(tube.stiffness, [0.0, -y_c, -z_c]) for y_c, z_c in centres)
    compliance, asym = checked_compliance(np.linalg.inv(stiffness), 'condensed compliance')
    timings = dict(tube.timings)
    timings['total'] += time.perf_counter() - t1
    n_tubes = len(centres)
    return CondensedSegment(compliance, tube.rest_offset, tube.rest_rotation,
                            n_tubes * tube.mass + geom.vertebra_mass, order,
                            n_tubes * tube.n_nodes, n_tubes * tube.n_elements,
                            n_tubes * tube.n_dofs, max(asym, tube.asymmetry), mesh_size, timings,
                            tube.warnings,
                            cavities=tuple((t.name, *cavity_surface(geom, i))
                                           for i, t in enumerate(geom.tubes)))


def condense_segment(mesh_or_geometry, youngs_modulus=None, poisson_ratio=None, *,
                     mesh_size=None, order=None, lower_x=None, upper_x=None,
                     segment_length=None, density=0.0, extra_mass=0.0):
    """
    Condense a segment given as a mesh or as a geometry description.

    Parameters
    ----------
    mesh_or_geometry : TetMesh or cbha_inverse.fem.segment_spec.SegmentSpec
        A mesh in segment coordinates, or a segment geometry file
        (:func:`cbha_inverse.fem.segment_spec.read_segment_spec`; a bellows or a cylinder).
    youngs_modulus, poisson_ratio : float, optional
        Material (default: the YAML's ``material``; required for a mesh).
    mesh_size : float, optional  [m]
        Element size (default: the YAML's ``mesh.mesh_size``).
    order : {1, 2}, optional
        Element order (default: the YAML's ``mesh.order``, else 2).
    lower_x, upper_x : float, optional  [m]
        End planes of a mesh (default its x extent).
    segment_length : float, optional  [m]
        Frame spacing (default upper_x for a mesh).
    density : float  [kg/m^3]
        Density for a mesh.
    extra_mass : float  [kg]
        Rigid mass added (for a mesh).

    Returns
    -------
    CondensedSegment
        The condensed segment.

    """
    if isinstance(mesh_or_geometry, TetMesh):
        mesh = mesh_or_geometry
        xs = mesh.points[mesh.used_nodes(), 0]
        lower_x = float(xs.min()) if lower_x is None else lower_x
        upper_x = float(xs.max()) if upper_x is None else upper_x
        return condense_mesh(mesh, youngs_modulus, poisson_ratio, lower_x=lower_x,
                             upper_x=upper_x, segment_length=_given(segment_length, upper_x),
                             density=density, extra_mass=extra_mass,
                             mesh_size=_given(mesh_size, float('nan')))
    spec = mesh_or_geometry
    if isinstance(spec.geometry, BellowsGeometry):
        return condense_bellows(spec, mesh_size=mesh_size, order=order,
                                youngs_modulus=youngs_modulus, poisson_ratio=poisson_ratio)
    if isinstance(spec.geometry, CylinderGeometry):
        geom, mat = spec.geometry, spec.material
        return condense_cylinder(
            geom.length, geom.outer_radius, geom.inner_radius,
            youngs_modulus=_given(youngs_modulus, mat.youngs_modulus),
            poisson_ratio=_given(poisson_ratio, mat.poisson_ratio),
            mesh_size=_given(mesh_size, spec.mesh.mesh_size),
            order=_given(order, spec.mesh.order), density=mat.density)
    raise TypeError(f'unknown segment geometry {type(spec.geometry).__name__} '
                    '(BellowsGeometry or CylinderGeometry)')
