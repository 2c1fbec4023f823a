"""
Condensation checks shared by the tests and the reports.

The mesh study of a condensed cylinder against a finer mesh, and the chain of condensed
segments against the full FE of the whole body with the same rigid vertebrae, linear and under
large bending (the paper reports < 0.72 % between the two; docs/stability-and-accuracy.md).
"""

import time

from cbha_inverse.fem.condensation import condense_cylinder
from cbha_inverse.fem.full_fe import linear_tip_compliance, solve_nonlinear
from cbha_inverse.fem.geometry import cylinder_mesh
from cbha_inverse.fem.segment_io import chain_from_segments
import numpy as np


def chain_tip_compliance(model):
    """
    Return the linear 6x6 compliance of the last frame of a chain at rest.

    The rest tangent of the chain (block tridiagonal, frames 1..n) is inverted; its last
    diagonal block is the tip compliance in world axes.

    Parameters
    ----------
    model : ChainModel
        The chain.

    Returns
    -------
    (6, 6) ndarray
        Tip compliance.

    """
    from cbha_inverse.core.system import chain_stiffness
    return np.linalg.inv(chain_stiffness(model))[-6:, -6:]


def relative_diagonal_error(test, reference):
    """
    Return |diag(test) / diag(reference) - 1| for the six diagonal terms.

    Parameters
    ----------
    test, reference : (6, 6) ndarray
        Compliances.

    Returns
    -------
    (6,) ndarray
        Relative errors.

    """
    return np.abs(np.diag(test) / np.diag(reference) - 1.0)


#: Element size of the P2 reference of :func:`cylinder_mesh_study`, over the smallest size studied
REFERENCE_REFINEMENT = 0.6


def cylinder_mesh_study(length, radius, mesh_sizes, *, youngs_modulus, poisson_ratio):
    """
    Condense a solid cylinder at P1 and P2 for each mesh size, against a finer P2 reference.

    The reference is P2 at :data:`REFERENCE_REFINEMENT` times the smallest of ``mesh_sizes``.

    Parameters
    ----------
    length, radius : float  [m]
        Segment length and cylinder radius.
    mesh_sizes : sequence of float  [m]
        Element sizes studied.
    youngs_modulus : float  [Pa]
        Young's modulus.
    poisson_ratio : float
        Poisson's ratio.

    Returns
    -------
    reference : CondensedSegment
        The P2 reference.
    cases : list of (int, float, CondensedSegment, (6,) ndarray)
        ``(order, mesh_size, segment, relative_diagonal_error(segment, reference))``, P1 then
        P2, each over ``mesh_sizes`` in their order.

    """
    material = {'youngs_modulus': youngs_modulus, 'poisson_ratio': poisson_ratio}
    reference = condense_cylinder(
        length, radius, mesh_size=REFERENCE_REFINEMENT * min(mesh_sizes), **material)
    cases = []
    for order in (1, 2):
        for size in mesh_sizes:
            segment = condense_cylinder(length, radius, mesh_size=size, order=order, **material)
            cases.append((order, size, segment,
                          relative_diagonal_error(segment.compliance, reference.compliance)))
    return reference, cases


def linear_chain_vs_full(n_segments, length, radius, *, youngs_modulus, poisson_ratio,
                         mesh_size, order=2):
    """
    Compare the tip compliance of a chain of condensed cylinders with the full linear FE body.

    Parameters
    ----------
    n_segments : int
        Segments stacked.
    length, radius : float  [m]
        Segment length and cylinder radius.
    youngs_modulus : float  [Pa]
        Young's modulus.
    poisson_ratio : float
        Poisson's ratio.
    mesh_size : float  [m]
        Element size of both models.
    order : {1, 2}
        Element order.

    Returns
    -------
    dict
        'chain', 'full' (6, 6) compliances, 'error' (6,) relative diagonal errors, 'full_seconds'
        (assembly + factor + solve of the body), 'chain_seconds' (tangent + solve of the chain),
        'body_nodes'.

    """
    seg = condense_cylinder(length, radius, youngs_modulus=youngs_modulus,
                            poisson_ratio=poisson_ratio, mesh_size=mesh_size, order=order)
    model = chain_from_segments([seg] * n_segments)
    t0 = time.perf_counter()
    chain = chain_tip_compliance(model)
    chain_seconds = time.perf_counter() - t0
    body = cylinder_mesh(length, radius, mesh_size=mesh_size, order=order, n_segments=n_segments)
    full, timings = linear_tip_compliance(body, youngs_modulus, poisson_ratio, n_segments, length)
    return {'chain': chain, 'full': full, 'error': relative_diagonal_error(chain, full),
            'full_seconds': sum(timings.values()), 'chain_seconds': chain_seconds,
            'body_nodes': body.n_nodes, 'segment': seg}


def large_bending(n_segments=8, length=0.01, radius=0.0025, *, youngs_modulus=1e6,
                  poisson_ratio=0.3, mesh_size=0.0025, load_parameter=3.8):
    """
    Compare a chain of condensed segments with the nonlinear SVK body under a tip load.

    The dead tip force is -z with magnitude load_parameter * EI / (n L)^2 (EI of the circular
    section), which bends a cantilever beyond 60 deg for load_parameter >= 3.5.

    Parameters
    ----------
    n_segments : int
        Segments.
    length, radius : float  [m]
        Segment length and radius.
    youngs_modulus : float  [Pa]
        Young's modulus.
    poisson_ratio : float
        Poisson's ratio.
    mesh_size : float  [m]
        Element size (P2) of segment and body.
    load_parameter : float
        F (n L)^2 / EI.

    Returns
    -------
    dict
        'chain_tip', 'full_tip' (3,) positions, 'tip_rotation_deg' (full FE),
        'error_over_displacement', 'error_over_length', 'chain_seconds', 'full_seconds',
        'full' (NonlinearResult), 'chain' (StaticResult).

    """
    from cbha_inverse.core.so3 import so3_log
    from cbha_inverse.core.statics import solve_static
    seg = condense_cylinder(length, radius, youngs_modulus=youngs_modulus,
                            poisson_ratio=poisson_ratio, mesh_size=mesh_size)
    model = chain_from_segments([seg] * n_segments)
    total = n_segments * length
    force = load_parameter * youngs_modulus * np.pi * radius ** 4 / 4.0 / total ** 2
    wrench = np.array([0.0, 0.0, -force, 0.0, 0.0, 0.0])
    t0 = time.perf_counter()
    chain = solve_static(model, tip_wrench=wrench)
    chain_seconds = time.perf_counter() - t0
    body = cylinder_mesh(length, radius, mesh_size=mesh_size, n_segments=n_segments)
    full = solve_nonlinear(body, youngs_modulus, poisson_ratio, n_segments, length, wrench)
    err = np.linalg.norm(chain.positions[-1] - full.positions[-1])
    disp = np.linalg.norm(full.positions[-1] - np.array([total, 0.0, 0.0]))
    return {'chain_tip': chain.positions[-1], 'full_tip': full.positions[-1],
            'tip_rotation_deg': float(np.degrees(np.linalg.norm(so3_log(full.rotations[-1])))),
            'error_over_displacement': float(err / disp), 'error_over_length': float(err / total),
            'chain_seconds': chain_seconds, 'full_seconds': full.seconds, 'full': full,
            'chain': chain, 'force': force}


def bellows_body(spec, n_segments, *, mesh_size=None, order=None):
    """
    Return the full-FE mesh and coupling of n stacked bellows segments with rigid vertebrae.

    Every segment is three copies of the same tube mesh; vertebra frame i (at x = i L) holds
    the upper wall ends of segment i and the lower wall ends of segment i + 1, the wall ends at
    x = t_v / 2 are clamped.

    Parameters
    ----------
    spec : cbha_inverse.fem.segment_spec.SegmentSpec
        Bellows segment geometry file.
    n_segments : int
        Segments stacked.
    mesh_size : float, optional  [m]
        Element size (default the YAML's).
    order : {1, 2}, optional
        Element order (default the YAML's).

    Returns
    -------
    mesh : TetMesh
        Body mesh.
    coupling : RigidCoupling
        Frames 1..n.

    """
    from cbha_inverse.fem.bellows import geometry_tube_centres
    from cbha_inverse.fem.coupling import build_coupling
    from cbha_inverse.fem.geometry import bellows_tube_mesh
    from cbha_inverse.fem.mesh import nodes_on_plane, TetMesh
    g = spec.geometry
    tube = bellows_tube_mesh(g, mesh_size=mesh_size or spec.mesh.mesh_size,
                             order=order or spec.mesh.order)
    length, half = g.segment_length, g.wall_start
    shifts = [(i * length, y_c, z_c) for i in range(n_segments)
              for y_c, z_c in geometry_tube_centres(g)]
    points = np.vstack([tube.points + s for s in shifts])
    tets = np.vstack([tube.tets + k * tube.n_nodes for k in range(len(shifts))])
    mesh = TetMesh(points, tets)
    sets = [np.concatenate([nodes_on_plane(mesh, i * length - half),
                            nodes_on_plane(mesh, i * length + half)])
            for i in range(1, n_segments + 1)]
    origins = [[i * length, 0.0, 0.0] for i in range(1, n_segments + 1)]
    return mesh, build_coupling(mesh.points, sets, origins, nodes_on_plane(mesh, half))


def bellows_chain_vs_full(spec, n_segments, *, mesh_size=None, order=None):
    """
    Compare the chain of condensed bellows segments with the full linear FE of the stack.

    Parameters
    ----------
    spec : cbha_inverse.fem.segment_spec.SegmentSpec
        Bellows segment geometry file.
    n_segments : int
        Segments stacked.
    mesh_size : float, optional  [m]
        Element size.
    order : {1, 2}, optional
        Element order.

    Returns
    -------
    dict
        'error' (6,) relative diagonal error of the tip compliance, 'full_seconds' (assembly,
        factorisation and 6 solves of the body), 'chain_seconds' (one linear solve of the chain
        by core.solve_static), 'body_dofs'.

    """
    from cbha_inverse.core.statics import solve_static
    from cbha_inverse.fem.condensation import condense_bellows, frame_compliance
    from cbha_inverse.fem.elasticity import assemble_stiffness
    mat = spec.material
    seg = condense_bellows(spec, mesh_size=mesh_size, order=order)
    model = chain_from_segments([seg] * n_segments)
    chain = chain_tip_compliance(model)
    small = 1e-9 * np.array([1.0, 1.0, 1.0, 0.0, 0.0, 0.0])
    t0 = time.perf_counter()
    solve_static(model, tip_wrench=small)
    chain_seconds = time.perf_counter() - t0
    mesh, coupling = bellows_body(spec, n_segments, mesh_size=mesh_size, order=order)
    t1 = time.perf_counter()
    stiffness = assemble_stiffness(mesh, mat.youngs_modulus, mat.poisson_ratio)
    full, _ = frame_compliance(stiffness, coupling, frame=-1)
    full_seconds = time.perf_counter() - t1
    return {'chain': chain, 'full': full, 'error': relative_diagonal_error(chain, full),
            'full_seconds': full_seconds, 'chain_seconds': chain_seconds,
            'body_dofs': coupling.n_reduced}
