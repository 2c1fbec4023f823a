"""
Compiled skinned-mesh cavities (paper Sec. IV, Fig. 5): their columns of ``J_aᵀ`` and volumes.

A cavity is a closed triangle surface whose vertices follow the two frames that enclose them by
linear skinning, ``p = (1 - s)(x_a + R_a a) + s (x_b + R_b b)``
(:class:`cbha_inverse.core.actuation.cavities.CavityGroup` builds the arrays). Per unit pressure
each vertex receives the outward normal times one third of the adjacent triangles' areas (the
gradient of the enclosed volume), and the transposed skinning Jacobian maps those forces to
wrenches of the two frames: :func:`mesh_cavity_wrenches`. :func:`mesh_cavity_pass` adds them to
the equilibrium (columns of ``J_aᵀ`` and the residual); their load stiffness is not modelled
(the condensed cavities of :mod:`cbha_inverse.core._kernels.links` have it).
"""

import numba


@numba.njit(cache=True)
def skinned_vertices(positions, rotations, frame_a, local_a, local_b, weight_b, points,
                     levers_a, levers_b):
    """
    Write the skinned world vertices and their levers from both frames.

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    frame_a : (V,) int ndarray
        Lower frame of every vertex (the upper one is ``frame_a + 1``).
    local_a, local_b : (V, 3) ndarray  [m]
        The vertex in the lower and in the upper frame's axes.
    weight_b : (V,) ndarray
        Skinning weight ``s`` of the upper frame.
    points, levers_a, levers_b : (V, 3) ndarray  [m]
        Receive ``p``, ``R_a a`` and ``R_b b``.

    """
    for v in range(frame_a.size):
        a, b, s = frame_a[v], frame_a[v] + 1, weight_b[v]
        for i in range(3):
            levers_a[v, i] = (rotations[a, i, 0] * local_a[v, 0]
                              + rotations[a, i, 1] * local_a[v, 1]
                              + rotations[a, i, 2] * local_a[v, 2])
            levers_b[v, i] = (rotations[b, i, 0] * local_b[v, 0]
                              + rotations[b, i, 1] * local_b[v, 1]
                              + rotations[b, i, 2] * local_b[v, 2])
            points[v, i] = ((1.0 - s) * (positions[a, i] + levers_a[v, i])
                            + s * (positions[b, i] + levers_b[v, i]))


@numba.njit(cache=True)
def mesh_cavity_wrenches(positions, rotations, frame_a, local_a, local_b, weight_b, triangles,
                         owner, gains, points, levers_a, levers_b, forces, wrenches):
    """
    Write the frame wrenches of every cavity per unit pressure (its column of ``J_aᵀ``).

    Each triangle adds ``(p1 - p0) × (p2 - p0) / 6`` (a third of its area times its normal) to
    each of its vertices; a vertex's force ``F`` at lever ``r`` from a frame gives that frame the
    wrench ``[F; r × F]``, weighted by its skinning weight and its cavity's gain.

    Parameters
    ----------
    positions, rotations, frame_a, local_a, local_b, weight_b
        As :func:`skinned_vertices`.
    triangles : (T, 3) int ndarray
        Vertices of every triangle (outward orientation).
    owner : (V,) int ndarray
        Cavity of every vertex (0..c - 1).
    gains : (c,) ndarray  [-]
        Gain of every cavity on its force.
    points, levers_a, levers_b, forces : (V, 3) ndarray
        Scratch (the skinned vertices, their forces per unit pressure [m^2]).
    wrenches : (c, n + 1, 6) ndarray  [N/Pa, N*m/Pa]
        Receives the wrench of every cavity on every frame.

    """
    skinned_vertices(positions, rotations, frame_a, local_a, local_b, weight_b, points, levers_a,
                     levers_b)
    forces[:, :] = 0.0
    for t in range(triangles.shape[0]):
        v0, v1, v2 = triangles[t, 0], triangles[t, 1], triangles[t, 2]
        e0, e1, e2 = (points[v1, 0] - points[v0, 0], points[v1, 1] - points[v0, 1],
                      points[v1, 2] - points[v0, 2])
        g0, g1, g2 = (points[v2, 0] - points[v0, 0], points[v2, 1] - points[v0, 1],
                      points[v2, 2] - points[v0, 2])
        n0, n1, n2 = ((e1 * g2 - e2 * g1) / 6.0, (e2 * g0 - e0 * g2) / 6.0,
                      (e0 * g1 - e1 * g0) / 6.0)
        for v in (v0, v1, v2):
            forces[v, 0] += n0
            forces[v, 1] += n1
            forces[v, 2] += n2
    wrenches[:, :, :] = 0.0
    for v in range(frame_a.size):
        cavity = owner[v]
        for side in range(2):
            if side == 0:
                frame, weight, levers = frame_a[v], (1.0 - weight_b[v]) * gains[cavity], levers_a
            else:
                frame, weight, levers = frame_a[v] + 1, weight_b[v] * gains[cavity], levers_b
            f0, f1, f2 = weight * forces[v, 0], weight * forces[v, 1], weight * forces[v, 2]
            r0, r1, r2 = levers[v, 0], levers[v, 1], levers[v, 2]
            out = wrenches[cavity, frame]
            out[0] += f0
            out[1] += f1
            out[2] += f2
            out[3] += r1 * f2 - r2 * f1
            out[4] += r2 * f0 - r0 * f2
            out[5] += r0 * f1 - r1 * f0


@numba.njit(cache=True)
def mesh_cavity_volumes(points, triangles, owner_of_triangle, gains, volumes):
    """
    Write the enclosed volume of every cavity (times its gain) from its skinned vertices.

    Parameters
    ----------
    points : (V, 3) ndarray  [m]
        Skinned vertices (:func:`skinned_vertices`).
    triangles : (T, 3) int ndarray
        Vertices of every triangle (outward orientation).
    owner_of_triangle : (T,) int ndarray
        Cavity of every triangle.
    gains : (c,) ndarray  [-]
        Gain of every cavity.
    volumes : (c,) ndarray  [m^3]
        Receives ``g Σ p0 · (p1 × p2) / 6`` over each cavity's triangles.

    """
    volumes[:] = 0.0
    for t in range(triangles.shape[0]):
        p0, p1, p2 = points[triangles[t, 0]], points[triangles[t, 1]], points[triangles[t, 2]]
        cross0 = p1[1] * p2[2] - p1[2] * p2[1]
        cross1 = p1[2] * p2[0] - p1[0] * p2[2]
        cross2 = p1[0] * p2[1] - p1[1] * p2[0]
        cavity = owner_of_triangle[t]
        volumes[cavity] += gains[cavity] * (p0[0] * cross0 + p0[1] * cross1
                                            + p0[2] * cross2) / 6.0


@numba.njit(cache=True)
def mesh_cavity_pass(system, positions, rotations, actuation):
    """
    Add the mesh cavities' columns of ``J_aᵀ`` and their loads to ``system.rhs``.

    Parameters
    ----------
    system : EquilibriumRecord
        The cavities' skinning and scratch (:mod:`cbha_inverse.core._kernels.evaluation`).
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    actuation : (m,) ndarray  [Pa]
        All actuators (the pressures are at the cavities' columns).

    """
    wrenches = system.mesh_wrenches
    mesh_cavity_wrenches(positions, rotations, system.mesh_frame_a, system.mesh_local_a,
                         system.mesh_local_b, system.mesh_weight_b, system.mesh_triangles,
                         system.mesh_owner, system.mesh_gains, system.mesh_points,
                         system.mesh_levers_a, system.mesh_levers_b, system.mesh_forces,
                         wrenches)
    rhs, columns = system.rhs, system.mesh_columns
    for cavity in range(wrenches.shape[0]):
        column = columns[cavity]
        pressure = actuation[column]
        for frame in range(1, wrenches.shape[1]):
            row = 6 * (frame - 1)
            for i in range(6):
                rhs[row + i, 1 + column] += wrenches[cavity, frame, i]
                rhs[row + i, 0] += pressure * wrenches[cavity, frame, i]
