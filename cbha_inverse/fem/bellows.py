"""
Bellows segment geometry in plain numpy: corrugation profile, tube placement, cavity surfaces.

No gmsh here: the cavity surfaces (docs/design.md) and the tube placement are needed at run time by
the loader and the pressure actuators. Segment coordinates: axis +x, lower vertebra frame at the
origin, upper frame at (L, 0, 0), metres.
"""

import numpy as np


def corrugation_profile(s, mean_radius, amplitude, pitch):
    """
    Return the inner radius of a sinusoidally corrugated bellows tube.

    r(s) = mean_radius - amplitude cos(2 pi s / pitch): a neck (valley) at s = 0 and at every
    full pitch, where a vertebra holds the tube.

    Parameters
    ----------
    s : ndarray  [m]
        Axial coordinate from the start of the deformable part.
    mean_radius, amplitude, pitch : float  [m]
        Corrugation parameters.

    Returns
    -------
    ndarray  [m]
        Inner radius.

    """
    return mean_radius - amplitude * np.cos(2.0 * np.pi * np.asarray(s) / pitch)


def tube_centres(pitch_radius, angles_deg):
    """
    Return the (y, z) centres of tubes placed at angles in the y-z plane.

    Parameters
    ----------
    pitch_radius : float  [m]
        Distance of each tube axis from the segment axis.
    angles_deg : (m,) array_like  [deg]
        Angle of each tube from +y towards +z.

    Returns
    -------
    (m, 2) ndarray  [m]
        Tube centres (y, z).

    """
    ang = np.radians(np.asarray(angles_deg, dtype=float))
    return pitch_radius * np.column_stack([np.cos(ang), np.sin(ang)])


def geometry_tube_centres(geometry):
    """
    Return the (y, z) tube centres of a bellows segment geometry.

    Parameters
    ----------
    geometry : cbha_inverse.fem.segment_spec.BellowsGeometry
        Bellows segment geometry.

    Returns
    -------
    (m, 2) ndarray  [m]
        Tube centres.

    """
    return tube_centres(geometry.tube_pitch_radius, [t.angle_deg for t in geometry.tubes])


def cavity_radius(x, geometry):
    """
    Return the cavity (inner wall) radius of a tube at segment abscissa x.

    Inside the vertebrae (|x| < t_v / 2 or |x - L| < t_v / 2) the tube is held at its neck
    radius; between them it follows :func:`corrugation_profile`.

    Parameters
    ----------
    x : ndarray  [m]
        Abscissa in [0, L].
    geometry : cbha_inverse.fem.segment_spec.BellowsGeometry
        Bellows segment geometry.

    Returns
    -------
    ndarray  [m]
        Inner radius.

    """
    g = geometry
    s = np.clip(np.asarray(x, dtype=float), g.wall_start, g.wall_end) - g.wall_start
    return corrugation_profile(s, g.tube_mean_radius, g.corrugation_amplitude,
                               g.corrugation_pitch)


def cavity_surface(geometry, tube, n_around=36, n_along=25):
    """
    Return the closed triangle surface of one tube's cavity in segment coordinates.

    The lateral inner wall runs from the lower frame plane x = 0 to the upper frame plane
    x = L (the tube passes through the vertebrae), closed by a flat cap on each plane.
    Normals (right-hand rule on the triangle vertex order) point out of the cavity.

    Parameters
    ----------
    geometry : cbha_inverse.fem.segment_spec.BellowsGeometry
        Bellows segment geometry.
    tube : int
        Tube index in ``geometry.tubes``.
    n_around : int
        Vertices around the circumference.
    n_along : int
        Vertex rings along the axis.

    Returns
    -------
    points : (P, 3) ndarray  [m]
        Vertices.
    triangles : (T, 3) int ndarray
        Outward-oriented triangles.

    """
    y_c, z_c = geometry_tube_centres(geometry)[tube]
    x0, x1 = geometry.wall_start, geometry.wall_end
    n_mid = max(2, n_along - 4)
    xs = np.unique(np.concatenate([np.linspace(0.0, x0, 3), np.linspace(x0, x1, n_mid),
                                   np.linspace(x1, geometry.segment_length, 3)]))
    phi = np.linspace(0.0, 2.0 * np.pi, n_around, endpoint=False)
    r = cavity_radius(xs, geometry)
    ring = np.stack([np.broadcast_to(xs[:, None], (len(xs), n_around)),
                     y_c + r[:, None] * np.cos(phi)[None],
                     z_c + r[:, None] * np.sin(phi)[None]], axis=-1).reshape(-1, 3)
    centres = np.array([[0.0, y_c, z_c], [xs[-1], y_c, z_c]])
    points = np.vstack([ring, centres])
    n_x = len(xs)
    i = np.arange(n_x - 1)[:, None]
    j = np.arange(n_around)[None, :]
    j1 = (j + 1) % n_around
    a, b = i * n_around + j, i * n_around + j1
    c, d = (i + 1) * n_around + j, (i + 1) * n_around + j1
    # outward normal of the lateral wall points away from the tube axis
    lateral = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3),
                              np.stack([b, d, c], -1).reshape(-1, 3)])
    lower, upper = len(ring), len(ring) + 1
    jj = np.arange(n_around)
    cap_lo = np.column_stack([np.full(n_around, lower), (jj + 1) % n_around, jj])
    top = (n_x - 1) * n_around
    cap_hi = np.column_stack([np.full(n_around, upper), top + jj, top + (jj + 1) % n_around])
    return points, np.vstack([lateral, cap_lo, cap_hi]).astype(np.int64)


def enclosed_volume(points, triangles):
    """
    Return the signed volume of a closed triangle surface (positive for outward normals).

    Parameters
    ----------
    points : (P, 3) ndarray  [m]
        Vertices.
    triangles : (T, 3) int ndarray
        Triangles.

    Returns
    -------
    float  [m^3]
        Volume by the divergence theorem.

    """
    p = points[triangles]
    return float(np.einsum('ti,ti->', p[:, 0], np.cross(p[:, 1], p[:, 2])) / 6.0)


def cavity_frame_wrenches(points, triangles, segment_length):
    """
    Return the wrenches per unit pressure that a cavity applies to its two segment frames.

    Each vertex receives the outward normal times one third of the adjacent triangle
    areas; the vertex forces are skinned linearly along the axis between the lower frame (x = 0)
    and the upper frame (x = L) and summed into wrenches at the frame origins.

    Parameters
    ----------
    points : (P, 3) ndarray  [m]
        Cavity vertices (segment coordinates).
    triangles : (T, 3) int ndarray
        Outward triangles.
    segment_length : float  [m]
        L.

    Returns
    -------
    (2, 6) ndarray  [N/Pa, N*m/Pa]
        Wrench on the lower and on the upper frame, segment axes, per pascal.

    """
    tri = points[triangles]
    area_vec = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    force = np.zeros_like(points)
    for k in range(3):
        np.add.at(force, triangles[:, k], area_vec / 3.0)
    upper = np.clip(points[:, 0] / segment_length, 0.0, 1.0)
    out = np.zeros((2, 6))
    origins = np.array([[0.0, 0.0, 0.0], [segment_length, 0.0, 0.0]])
    for row, weight in enumerate((1.0 - upper, upper)):
        f_w = weight[:, None] * force
        out[row, :3] = f_w.sum(axis=0)
        out[row, 3:] = np.cross(points - origins[row], f_w).sum(axis=0)
    return out
