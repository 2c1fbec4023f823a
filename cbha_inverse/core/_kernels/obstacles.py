"""
Compiled signed distance of a point to a posed primitive solid (``docs/obstacles.md``).

:func:`signed_distance_at` is the package's one implementation of the obstacles' signed-distance
query: for a point it returns the distance ``φ`` to the surface (negative inside the solid) and
writes the outward unit normal ``n = ∇φ``, the closest point of the surface ``p - φ n`` and the
Hessian ``H = ∇n`` of the distance, all in base-frame axes. Compiled callers call it per point;
:meth:`cbha_inverse.core.obstacles.Obstacle.signed_distance` loops it over points
(:func:`signed_distances_into`), :func:`cbha_inverse.core.obstacles.pairwise_signed_distance`
over points and obstacles (:func:`pairwise_signed_distances_into`). Every caller passes the
obstacle's arrays read-only (an ``Obstacle``'s own, ``read_only_packed`` of the packed arrays,
a record's read-only fields), so that one compiled copy serves them all (``docs/design.md``).

An obstacle is its shape code (:data:`PLANE` ... :data:`CYLINDER`, the order of
:data:`cbha_inverse.core.obstacles.SHAPES`), its pose (``position``, and ``rotation``, its axes
as columns in the base frame) and its ``sizes`` (3,) [m]:

- plane: zeros; the solid half-space ``z <= 0`` of its own frame;
- sphere: ``(radius, 0, 0)``, about the origin;
- box: the edge lengths ``(x, y, z)``, centred;
- capsule: ``(radius, length, 0)``: within ``radius`` of the segment of ``length`` along z;
- cylinder: ``(radius, length, 0)``: about z, flat caps ``length`` apart, centred.

Each primitive has one function over the local coordinates ``q = Rᵀ (p - x)`` of the point
(``plane_at`` ... ``cylinder_at``); :func:`local_to_base_into` turns its normal, closest point
and Hessian to the base frame (``R n``, ``R c + x``, ``R H Rᵀ``). Where the normal is not
unique (the centre of a sphere, the axis of a capsule or a cylinder, the middle of a box) a
fixed candidate is chosen: ``+z`` at a sphere's centre, ``+x`` on a capsule's core segment and
a cylinder's axis, the first face (x, then y, then z) among a box's nearest; a point on a
mirror plane takes the + side (``sign(0) = +1``). Nothing here allocates: the compiled tick
calls it per point.
"""

import math

import numba

PLANE, SPHERE, BOX, CAPSULE, CYLINDER = 0, 1, 2, 3, 4
"""The shape codes (the order of :data:`cbha_inverse.core.obstacles.SHAPES`)."""


@numba.njit(cache=True)
def signed_distance_at(shape, position, rotation, sizes, point, normal, closest, curvature):
    """
    Return the signed distance of one point to an obstacle; write its normal, closest, Hessian.

    Parameters
    ----------
    shape : int
        :data:`PLANE`, :data:`SPHERE`, :data:`BOX`, :data:`CAPSULE` or :data:`CYLINDER`.
    position : (3,) ndarray  [m]
        Origin of the obstacle's frame, base frame.
    rotation : (3, 3) ndarray
        The obstacle's axes as columns, base frame.
    sizes : (3,) ndarray  [m]
        Box edges ``(x, y, z)``; ``(radius, length, 0)`` of a capsule or cylinder;
        ``(radius, 0, 0)`` of a sphere; ignored for a plane.
    point : (3,) ndarray  [m]
        The point, base frame.
    normal : (3,) ndarray
        Receives the outward unit normal ``n = ∇φ`` (base axes).
    closest : (3,) ndarray  [m]
        Receives the closest point of the surface, ``point - φ n`` (base frame).
    curvature : (3, 3) ndarray  [1/m]
        Receives the Hessian ``∇n`` of the distance (base axes, symmetric).

    Returns
    -------
    float  [m]
        The signed distance ``φ``, negative inside the solid.

    Raises
    ------
    ValueError
        On an unknown shape code.

    """
    # q = Rᵀ (p - x): the point in the obstacle's frame
    dx, dy, dz = point[0] - position[0], point[1] - position[1], point[2] - position[2]
    x = rotation[0, 0] * dx + rotation[1, 0] * dy + rotation[2, 0] * dz
    y = rotation[0, 1] * dx + rotation[1, 1] * dy + rotation[2, 1] * dz
    z = rotation[0, 2] * dx + rotation[1, 2] * dy + rotation[2, 2] * dz
    if shape == PLANE:
        distance = plane_at(x, y, z, normal, closest, curvature)
    elif shape == SPHERE:
        distance = sphere_at(sizes[0], x, y, z, normal, closest, curvature)
    elif shape == BOX:
        distance = box_at(0.5 * sizes[0], 0.5 * sizes[1], 0.5 * sizes[2], x, y, z, normal,
                          closest, curvature)
    elif shape == CAPSULE:
        distance = capsule_at(sizes[0], 0.5 * sizes[1], x, y, z, normal, closest, curvature)
    elif shape == CYLINDER:
        distance = cylinder_at(sizes[0], 0.5 * sizes[1], x, y, z, normal, closest, curvature)
    else:
        raise ValueError('unknown obstacle shape code')
    local_to_base_into(position, rotation, normal, closest, curvature)
    return distance


@numba.njit(cache=True)
def signed_distances_into(shape, position, rotation, sizes, points, distance, normal, closest,
                          curvature):
    """
    Write the signed distance of N points to one obstacle (:func:`signed_distance_at` per point).

    Parameters
    ----------
    shape, position, rotation, sizes
        The obstacle, as :func:`signed_distance_at`.
    points : (N, 3) ndarray  [m]
        The points, base frame.
    distance : (N,) ndarray  [m]
        Receives the signed distances.
    normal : (N, 3) ndarray
        Receives the outward unit normals.
    closest : (N, 3) ndarray  [m]
        Receives the closest surface points.
    curvature : (N, 3, 3) ndarray  [1/m]
        Receives the Hessians of the distance.

    """
    for i in range(points.shape[0]):
        distance[i] = signed_distance_at(shape, position, rotation, sizes, points[i], normal[i],
                                         closest[i], curvature[i])


@numba.njit(cache=True)
def pairwise_signed_distances_into(shapes, positions, rotations, sizes, points, distance, normal,
                                   closest, curvature):
    """
    Write the signed distance of N points to each of ``o`` obstacles (every pair).

    Parameters
    ----------
    shapes : (o,) int64 ndarray
        Shape codes.
    positions, rotations, sizes : (o, 3), (o, 3, 3), (o, 3) ndarray
        The obstacles' poses and sizes, one row each, as :func:`signed_distance_at` takes them
        (:func:`cbha_inverse.core.obstacles.pack_obstacles`).
    points : (N, 3) ndarray  [m]
        The points, base frame.
    distance : (N, o) ndarray  [m]
        Receives the signed distance of point ``i`` to obstacle ``j`` at ``[i, j]``.
    normal, closest : (N, o, 3) ndarray
        Receive the outward unit normals and the closest surface points [m].
    curvature : (N, o, 3, 3) ndarray  [1/m]
        Receives the Hessians of the distance.

    """
    for i in range(points.shape[0]):
        for j in range(shapes.size):
            distance[i, j] = signed_distance_at(shapes[j], positions[j], rotations[j], sizes[j],
                                                points[i], normal[i, j], closest[i, j],
                                                curvature[i, j])


# --- the primitives, in their own frame (local coordinates x, y, z of the point) -------------


@numba.njit(cache=True)
def plane_at(x, y, z, normal, closest, curvature):
    """Half-space ``z <= 0``: distance ``z``, normal ``+z``, closest ``(x, y, 0)``, flat."""
    set_vector(normal, 0.0, 0.0, 1.0)
    set_vector(closest, x, y, 0.0)
    curvature[:, :] = 0.0
    return z


@numba.njit(cache=True)
def sphere_at(radius, x, y, z, normal, closest, curvature):
    """
    Sphere of ``radius`` about the origin: ``φ = |q| - r``, ``n = q / |q|``.

    The Hessian is ``(I - n nᵀ) / |q|``; at the centre the normal is ``+z``, the Hessian zero.
    """
    centre_distance = unit_or_into(x, y, z, 0.0, 0.0, 1.0, normal)
    set_vector(closest, radius * normal[0], radius * normal[1], radius * normal[2])
    offset_curvature_into(centre_distance, 1.0, 1.0, 1.0, normal, curvature)
    return centre_distance - radius


@numba.njit(cache=True)
def box_at(half_x, half_y, half_z, x, y, z, normal, closest, curvature):
    """
    Box of half edges ``h``, centred: outside, to the clamped point; inside, to the nearest face.

    Per axis the excess ``e = |q| - h``. Outside (some ``e > 0``), ``u = sign(q) max(e, 0)``
    joins the clamped point ``clip(q, -h, h)`` (the closest point) to ``q``: ``φ = |u|``,
    ``n = u / |u|``, ``H = (D - n nᵀ) / |u|`` with ``D`` the projector on the axes where
    ``e > 0`` (zero on a face, the curvature of a rounded edge or corner otherwise). Inside,
    ``φ`` is the largest excess, ``n`` the outward axis of that face (the first of x, y, z on a
    tie), the closest point ``q`` moved onto it, ``H = 0``.
    """
    excess_x, sign_x, clamped_x = box_axis(half_x, x)
    excess_y, sign_y, clamped_y = box_axis(half_y, y)
    excess_z, sign_z, clamped_z = box_axis(half_z, z)
    set_vector(closest, clamped_x, clamped_y, clamped_z)
    if excess_x > 0.0 or excess_y > 0.0 or excess_z > 0.0:
        beyond_x, beyond_y, beyond_z = (max(excess_x, 0.0), max(excess_y, 0.0),
                                        max(excess_z, 0.0))
        distance = unit_or_into(sign_x * beyond_x, sign_y * beyond_y, sign_z * beyond_z,
                                0.0, 0.0, 1.0, normal)
        offset_curvature_into(distance, step(excess_x), step(excess_y), step(excess_z),
                              normal, curvature)
        return distance
    curvature[:, :] = 0.0
    if excess_x >= excess_y and excess_x >= excess_z:
        set_vector(normal, sign_x, 0.0, 0.0)
        closest[0] = sign_x * half_x
        return excess_x
    if excess_y >= excess_z:
        set_vector(normal, 0.0, sign_y, 0.0)
        closest[1] = sign_y * half_y
        return excess_y
    set_vector(normal, 0.0, 0.0, sign_z)
    closest[2] = sign_z * half_z
    return excess_z


@numba.njit(cache=True)
def box_axis(half, coordinate):
    """Return the excess ``|q| - h``, ``sign(q)`` (+1 at 0) and ``clip(q, -h, h)`` on one axis."""
    sign = -1.0 if coordinate < 0.0 else 1.0
    return abs(coordinate) - half, sign, min(max(coordinate, -half), half)


@numba.njit(cache=True)
def capsule_at(radius, half_length, x, y, z, normal, closest, curvature):
    """
    Capsule: the distance to its core segment (z in ``[-l/2, l/2]``) minus ``radius``.

    With ``a = clip(z, -l/2, l/2)`` the closest point of the segment and ``u = q - a e_z``:
    ``φ = |u| - r``, ``n = u / |u|`` (``+x`` on the segment), ``H = (D - n nᵀ) / |u|``,
    ``D = I - e_z e_zᵀ`` beside the segment (``|z| < l/2``), ``I`` beyond its ends.
    """
    axial = min(max(z, -half_length), half_length)
    core_distance = unit_or_into(x, y, z - axial, 1.0, 0.0, 0.0, normal)
    set_vector(closest, radius * normal[0], radius * normal[1], radius * normal[2] + axial)
    beyond_ends = 0.0 if abs(z) < half_length else 1.0
    offset_curvature_into(core_distance, 1.0, 1.0, beyond_ends, normal, curvature)
    return core_distance - radius


@numba.njit(cache=True)
def cylinder_at(radius, half_length, x, y, z, normal, closest, curvature):
    """
    Flat-capped cylinder: the box query in (distance from the axis, axial coordinate).

    With ``s = |(x, y)|``, the radial direction ``e_s`` (``+x`` on the axis), ``e_t = e_z x
    e_s`` and the excesses ``a = (s - r, |z| - l/2)``: outside (some ``a > 0``), ``φ = |u|``
    along ``u = max(a_s, 0) e_s + max(a_z, 0) sign(z) e_z``; inside, the larger of ``a`` (the
    side on a tie), its outward direction the normal. ``n = w_s e_s + w_z sign(z) e_z``, and the
    Hessian is the 2D query's, ``(D - n nᵀ) / |u|`` outside with ``D = [a_s > 0] e_s e_sᵀ +
    [a_z > 0] e_z e_zᵀ`` (zero inside), plus the turn of the radial direction about the axis,
    ``(w_s / s) e_t e_tᵀ``.
    """
    axis_distance = math.hypot(x, y)
    radial_x, radial_y = (x / axis_distance, y / axis_distance) if axis_distance > 0.0 else (
        1.0, 0.0)
    tangent_x, tangent_y = -radial_y, radial_x
    sign_z = -1.0 if z < 0.0 else 1.0
    excess_radial, excess_axial = axis_distance - radius, abs(z) - half_length
    outside = excess_radial > 0.0 or excess_axial > 0.0
    beyond_radial, beyond_axial = max(excess_radial, 0.0), max(excess_axial, 0.0)
    on_side = not outside and excess_radial >= excess_axial
    if outside:
        distance = math.hypot(beyond_radial, beyond_axial)
        weight_radial, weight_axial = beyond_radial / distance, beyond_axial / distance
    elif on_side:
        distance = excess_radial
        weight_radial, weight_axial = 1.0, 0.0
    else:
        distance = excess_axial
        weight_radial, weight_axial = 0.0, 1.0
    set_vector(normal, weight_radial * radial_x, weight_radial * radial_y,
               weight_axial * sign_z)
    closest_radial = radius if on_side else min(axis_distance, radius)
    closest_axial = (sign_z * half_length if not outside and not on_side
                     else min(max(z, -half_length), half_length))
    set_vector(closest, closest_radial * radial_x, closest_radial * radial_y, closest_axial)
    curvature[:, :] = 0.0
    if outside:
        add_outer(curvature, step(excess_radial) / distance, radial_x, radial_y, 0.0)
        add_outer(curvature, step(excess_axial) / distance, 0.0, 0.0, 1.0)
        add_outer(curvature, -1.0 / distance, normal[0], normal[1], normal[2])
    if axis_distance > 0.0:
        add_outer(curvature, weight_radial / axis_distance, tangent_x, tangent_y, 0.0)
    return distance


# --- small shared steps ------------------------------------------------------------------------


@numba.njit(cache=True)
def set_vector(out, x, y, z):
    """Write ``(x, y, z)`` into ``out`` (3,)."""
    out[0], out[1], out[2] = x, y, z


@numba.njit(cache=True)
def step(value):
    """Return 1.0 where ``value > 0``, else 0.0 (the indicator of an active direction)."""
    return 1.0 if value > 0.0 else 0.0


@numba.njit(cache=True)
def unit_or_into(x, y, z, fallback_x, fallback_y, fallback_z, unit):
    """Write ``u / |u|`` (the fallback where ``u = 0``) into ``unit`` (3,); return ``|u|``."""
    length = math.sqrt(x * x + y * y + z * z)
    if length > 0.0:
        set_vector(unit, x / length, y / length, z / length)
    else:
        set_vector(unit, fallback_x, fallback_y, fallback_z)
    return length


@numba.njit(cache=True)
def offset_curvature_into(length, active_x, active_y, active_z, normal, curvature):
    """
    Write the Hessian ``(D - n nᵀ) / |u|`` of ``|u|``, ``u`` the offset from a closest point.

    ``D = diag(active)`` projects on the axes along which the closest point stays put as the
    point moves (1.0) rather than sliding with it (0.0); zero where ``|u| = 0``.
    """
    curvature[:, :] = 0.0
    if length > 0.0:
        inverse_length = 1.0 / length
        curvature[0, 0] = active_x * inverse_length
        curvature[1, 1] = active_y * inverse_length
        curvature[2, 2] = active_z * inverse_length
        add_outer(curvature, -inverse_length, normal[0], normal[1], normal[2])


@numba.njit(cache=True)
def add_outer(matrix, weight, x, y, z):
    """Add ``weight u uᵀ`` to ``matrix`` (3, 3), ``u = (x, y, z)``."""
    u = (x, y, z)
    for i in range(3):
        for j in range(3):
            matrix[i, j] += weight * u[i] * u[j]


@numba.njit(cache=True)
def local_to_base_into(position, rotation, normal, closest, curvature):
    """
    Turn a primitive's normal, closest point and Hessian from its frame to the base frame.

    ``n ← R n``, ``c ← R c + x``, ``H ← R H Rᵀ``, in place.
    """
    rotate_into(rotation, normal)
    rotate_into(rotation, closest)
    for i in range(3):
        closest[i] += position[i]
    rotate_matrix_into(rotation, curvature)


@numba.njit(cache=True)
def rotate_into(rotation, vector):
    """Replace ``vector`` (3,) by ``R vector``."""
    x, y, z = vector[0], vector[1], vector[2]
    for i in range(3):
        vector[i] = rotation[i, 0] * x + rotation[i, 1] * y + rotation[i, 2] * z


@numba.njit(cache=True)
def rotate_matrix_into(rotation, matrix):
    """Replace ``matrix`` (3, 3) by ``R matrix Rᵀ``."""
    # M Rᵀ: row i of M becomes R times it
    for i in range(3):
        row_0, row_1, row_2 = matrix[i, 0], matrix[i, 1], matrix[i, 2]
        for j in range(3):
            matrix[i, j] = (rotation[j, 0] * row_0 + rotation[j, 1] * row_1
                            + rotation[j, 2] * row_2)
    # R (M Rᵀ): column j becomes R times it
    for j in range(3):
        column_0, column_1, column_2 = matrix[0, j], matrix[1, j], matrix[2, j]
        for i in range(3):
            matrix[i, j] = (rotation[i, 0] * column_0 + rotation[i, 1] * column_1
                            + rotation[i, 2] * column_2)
