"""
The compliance links' equations (paper eq. 4-8), one compiled function per equation.

A link joins frame ``a`` (its lower frame) to frame ``b = a + 1``; its stiffness ``K = C⁻¹`` acts
on the corotational deformation ``δ``. :func:`link_pass` runs, for every link, in order:

1. :func:`link_deformation`, eq. 4: ``δ = [R_aᵀ (x_b - x_a) - d0; log(R_aᵀ R_b Q0ᵀ)]``;
2. :func:`local_wrench`, eq. 5 with ``B = diag(I, Jl⁻¹(φ))``: the b-side wrench in frame-a axes
   ``L = -Bᵀ K δ`` and ``A = Bᵀ K``; :func:`add_cavity_wrenches`, the condensed cavities of
   :mod:`cbha_inverse.core.actuation.condensed_cavities`: ``L += Σ_c p_c (G0_c + H_c δ)``, one
   column of ``J_aᵀ`` per cavity, and their load stiffness ``A -= p_c H_c``;
3. :func:`world_wrench`, :func:`add_to_frame_b`, :func:`add_to_frame_a`, eq. 5-7: ``L``
   rotated to world axes onto frame ``b``, the equilibrating wrench onto frame ``a`` (the moment
   transported from ``x_b`` to ``x_a``; none for the base);
4. :func:`add_stress_terms` (exact tangent) and :func:`local_tangent`, eq. 8:
   ``M = (A + Z - ½ s_r^) B`` with ``Z = d(Jl⁻ᵀ(φ) s_r)/dφ``, or ``Bᵀ K B`` alone (material);
5. :func:`world_tangent`: the 12 x 12 tangent of the pair in world axes, ``Eᵀ R M Rᵀ E``
   (``R = diag(R_a, R_a)``, ``E = [E_a, I]``, ``E_a = [-I, d^; 0, -I]``);
6. :func:`add_geometric_terms` (exact tangent): the terms of the rotated wrench and of its lever.

The control tick factors the symmetric part of the tangent: ``Eᵀ R sym(M) Rᵀ E`` plus the
symmetric part of the geometric terms, whose blocks on and below the diagonal alone are formed
(the same tangent as the symmetric part of the exact one, up to rounding).

The one implementation of these equations, behind the control tick, the static solver, the
scenes' forward model and the plant (:mod:`cbha_inverse.core._kernels.evaluation`); the readable
numpy version is a test oracle (``test/oracles/chain_forces.py``).
"""

from cbha_inverse.core._kernels.assembly import add_link_block
from cbha_inverse.core._kernels.so3 import (add_scaled_hat, jl_coefficient,
                                            left_jacobian_inverse_into, rotation_log_scalars)
import numba


@numba.njit(cache=True, inline='always')
def link_deformation(positions, rotations, rest_offsets, rest_rotations_t, link, difference,
                     relative, delta):
    """
    Write the deformation ``δ`` of a link (paper eq. 4) and return its angle ``|φ|``.

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (frame axes → world).
    rest_offsets : (n, 3) ndarray  [m]
        ``d0``: frame ``b`` in frame ``a`` at rest.
    rest_rotations_t : (n, 3, 3) ndarray
        ``Q0ᵀ``: the rest rotation of frame ``b`` in frame ``a``, transposed.
    link : int
        The link (frames ``a = link``, ``b = link + 1``).
    difference : (3,) ndarray  [m]
        Receives ``x_b - x_a`` (world axes).
    relative : (3, 3) ndarray
        Receives ``R_aᵀ R_b Q0ᵀ``.
    delta : (6,) ndarray  [m, rad]
        Receives ``δ = [R_aᵀ (x_b - x_a) - d0; φ]``, ``φ = log(R_aᵀ R_b Q0ᵀ)``.

    Returns
    -------
    float  [rad]
        ``t = |φ|``.

    """
    a, b = link, link + 1
    for i in range(3):
        difference[i] = positions[b, i] - positions[a, i]
    for i in range(3):
        # row i of R_aᵀ R_b, then times Q0ᵀ
        t0 = (rotations[a, 0, i] * rotations[b, 0, 0] + rotations[a, 1, i] * rotations[b, 1, 0]
              + rotations[a, 2, i] * rotations[b, 2, 0])
        t1 = (rotations[a, 0, i] * rotations[b, 0, 1] + rotations[a, 1, i] * rotations[b, 1, 1]
              + rotations[a, 2, i] * rotations[b, 2, 1])
        t2 = (rotations[a, 0, i] * rotations[b, 0, 2] + rotations[a, 1, i] * rotations[b, 1, 2]
              + rotations[a, 2, i] * rotations[b, 2, 2])
        for j in range(3):
            relative[i, j] = (t0 * rest_rotations_t[link, 0, j] + t1 * rest_rotations_t[link, 1, j]
                              + t2 * rest_rotations_t[link, 2, j])
    for i in range(3):
        delta[i] = (rotations[a, 0, i] * difference[0] + rotations[a, 1, i] * difference[1]
                    + rotations[a, 2, i] * difference[2] - rest_offsets[link, i])
    theta, delta[3], delta[4], delta[5] = rotation_log_scalars(relative)
    return theta


@numba.njit(cache=True, inline='always')
def local_wrench(stiffness, link, delta, jl_inverse, stress, weighted, local):
    """
    Write the elastic b-side wrench of a link in frame-``a`` axes (paper eq. 5).

    With ``B = diag(I, Jl⁻¹(φ))`` (the rotation increments of ``φ``): ``s = K δ``,
    ``A = Bᵀ K`` and ``L = -Bᵀ K δ = -A δ``.

    Parameters
    ----------
    stiffness : (n, 6, 6) ndarray  [N/m, N, N*m/rad]
        The links' ``K``.
    link : int
        The link.
    delta : (6,) ndarray  [m, rad]
        ``δ`` (:func:`link_deformation`).
    jl_inverse : (3, 3) ndarray
        ``Jl⁻¹(φ)``.
    stress : (6,) ndarray  [N, N*m]
        Receives ``s = K δ``.
    weighted : (6, 6) ndarray
        Receives ``A = Bᵀ K``.
    local : (6, m + 1) ndarray  [N, N*m]
        Column 0 receives ``L``.

    """
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += stiffness[link, i, j] * delta[j]
        stress[i] = acc
    for j in range(6):
        for i in range(3):
            weighted[i, j] = stiffness[link, i, j]
            weighted[3 + i, j] = (jl_inverse[0, i] * stiffness[link, 3, j]
                                  + jl_inverse[1, i] * stiffness[link, 4, j]
                                  + jl_inverse[2, i] * stiffness[link, 5, j])
    for i in range(6):
        acc = 0.0
        for j in range(6):
            acc += weighted[i, j] * delta[j]
        local[i, 0] = -acc


@numba.njit(cache=True, inline='always')
def add_cavity_wrenches(cavity_wrench, cavity_stiffness, cavity_columns, link, actuation,
                        delta, with_load, local, weighted):
    """
    Add a link's condensed cavities to its local wrench and, exact, their load stiffness.

    Cavity ``c`` (an actuator column) adds ``G0_c + H_c δ`` per pascal: column ``1 + c`` of
    ``local`` (a column of ``J_aᵀ`` before rotation), and ``p_c`` times it to column 0 (the
    wrench at the current pressure). Its load stiffness ``-p_c H_c`` enters ``A``.

    Parameters
    ----------
    cavity_wrench : (n, c, 6) ndarray  [N/Pa, N*m/Pa]
        ``G0`` per link and actuator column.
    cavity_stiffness : (n, c, 6, 6) ndarray
        ``H`` per link and actuator column.
    cavity_columns : (n, c) int ndarray
        Per link, the columns with a nonzero ``G0`` or ``H``, then -1.
    link : int
        The link.
    actuation : (m,) ndarray  [Pa]
        ``λ``.
    delta : (6,) ndarray  [m, rad]
        ``δ``.
    with_load : bool
        Subtract the load stiffness from ``weighted`` (the exact tangent).
    local : (6, m + 1) ndarray
        Column 0 is added to; the cavities' columns are written.
    weighted : (6, 6) ndarray
        ``A`` (added to).

    Returns
    -------
    int
        The number of cavity columns written.

    """
    used = 0
    while used < cavity_columns.shape[1] and cavity_columns[link, used] >= 0:
        cavity = cavity_columns[link, used]
        used += 1
        pressure = actuation[cavity]
        load = with_load and pressure != 0.0
        for i in range(6):
            acc = cavity_wrench[link, cavity, i]
            for j in range(6):
                acc += cavity_stiffness[link, cavity, i, j] * delta[j]
                if load:
                    weighted[i, j] -= pressure * cavity_stiffness[link, cavity, i, j]
            local[i, 1 + cavity] = acc
            local[i, 0] += pressure * acc
    return used


@numba.njit(cache=True, inline='always')
def world_wrench(rotations, link, local, column, world):
    """
    Rotate one column of a link's local wrench to world axes: ``w = [R_a L_f; R_a L_m]``.

    Parameters
    ----------
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    link : int
        The link (frame ``a = link``).
    local : (6, m + 1) ndarray  [N, N*m]
        The local wrenches (column 0, then per unit actuation).
    column : int
        The column of ``local`` and ``world``.
    world : (6, m + 1) ndarray
        Receives ``w`` (column ``column``).

    """
    for i in range(3):
        world[i, column] = (rotations[link, i, 0] * local[0, column]
                            + rotations[link, i, 1] * local[1, column]
                            + rotations[link, i, 2] * local[2, column])
        world[3 + i, column] = (rotations[link, i, 0] * local[3, column]
                                + rotations[link, i, 1] * local[4, column]
                                + rotations[link, i, 2] * local[5, column])


@numba.njit(cache=True, inline='always')
def add_to_frame_b(world, column, link, rhs):
    """Add the world wrench ``w`` (column ``column``) to frame ``b``'s rows ``6 link ...``."""
    for i in range(6):
        rhs[6 * link + i, column] += world[i, column]


@numba.njit(cache=True, inline='always')
def add_to_frame_a(world, column, difference, link, rhs):
    """
    Add the equilibrating wrench to frame ``a``'s rows ``6 (link - 1) ...`` (paper eq. 5-7).

    The opposite force and the opposite moment transported to ``x_a``,
    ``-[F; M + (x_b - x_a) × F]``: the two wrenches of a link are in equilibrium.
    """
    row = 6 * (link - 1)
    f0, f1, f2 = world[0, column], world[1, column], world[2, column]
    d0, d1, d2 = difference[0], difference[1], difference[2]
    for i in range(6):
        rhs[row + i, column] -= world[i, column]
    rhs[row + 3, column] -= d1 * f2 - d2 * f1
    rhs[row + 4, column] -= d2 * f0 - d0 * f2
    rhs[row + 5, column] -= d0 * f1 - d1 * f0


@numba.njit(cache=True, inline='always')
def add_stress_terms(weighted, delta, stress, theta):
    """
    Add the stress terms of the rotation's parametrisation to ``A``: ``Z - ½ s_r^``.

    ``Z = d(Jl⁻ᵀ(φ) s_r)/dφ`` with ``Jl⁻¹ = I - φ^/2 + c(t) φ^²`` (the derivative of ``c φ^²``
    written with ``ps = φ·s_r`` and ``c' = dc t``), ``s_r`` the moment part of ``K δ``: with
    them the local tangent is exact (:func:`local_tangent`).

    Parameters
    ----------
    weighted : (6, 6) ndarray
        ``A``; its moment block is added to.
    delta : (6,) ndarray  [m, rad]
        ``δ`` (``φ`` is ``delta[3:]``).
    stress : (6,) ndarray  [N, N*m]
        ``K δ``.
    theta : float  [rad]
        ``|φ|``.

    """
    c, dc = jl_coefficient(theta)
    phi0, phi1, phi2 = delta[3], delta[4], delta[5]
    s0, s1, s2 = stress[3], stress[4], stress[5]
    ps = phi0 * s0 + phi1 * s1 + phi2 * s2
    t2 = theta * theta
    for i in range(3):
        left0 = dc * (delta[3 + i] * ps - t2 * stress[3 + i]) - 2.0 * c * stress[3 + i]
        left1 = c * delta[3 + i]
        for j in range(3):
            weighted[3 + i, 3 + j] += left0 * delta[3 + j] + left1 * stress[3 + j]
        weighted[3 + i, 3 + i] += c * ps
    add_scaled_hat(weighted, 3, 3, s0, s1, s2, -0.5)


@numba.njit(cache=True, inline='always')
def local_tangent(weighted, jl_inverse, tangent):
    """
    Write the local tangent ``M = A B`` of a link, ``-d L / d(δ increments)`` (paper eq. 8).

    ``A = Bᵀ K`` less the cavities' load stiffness, with the stress terms for the exact tangent
    (:func:`add_stress_terms`), else alone: the material part ``Bᵀ K B``, positive
    semi-definite whatever the loads; ``B = diag(I, Jl⁻¹(φ))``.

    Parameters
    ----------
    weighted : (6, 6) ndarray
        ``A``.
    jl_inverse : (3, 3) ndarray
        ``Jl⁻¹(φ)``.
    tangent : (6, 6) ndarray
        Receives ``M``.

    """
    for i in range(6):
        for j in range(3):
            tangent[i, j] = weighted[i, j]
            tangent[i, 3 + j] = (weighted[i, 3] * jl_inverse[0, j]
                                 + weighted[i, 4] * jl_inverse[1, j]
                                 + weighted[i, 5] * jl_inverse[2, j])


@numba.njit(cache=True, inline='always')
def world_tangent(tangent, rotations, link, difference, symmetric, block):
    """
    Write a link's 12 x 12 world tangent ``Eᵀ R M Rᵀ E`` (frames ``a``, ``b``) into ``block``.

    ``δ`` moves with the world increments ``(dx, dθ)`` of its two frames as ``Rᵀ E``, with
    ``R = diag(R_a, R_a)``, ``E = [E_a, I]`` and ``E_a = [-I, d^; 0, -I]`` (``d = x_b - x_a``):
    the blocks are ``[E_aᵀ W E_a, E_aᵀ W; W E_a, W]`` for ``W = R M Rᵀ``. Rows and columns: frame
    ``a``'s six increments, then frame ``b``'s. A symmetric ``M`` gives a symmetric tangent:
    then only its entries on and below the diagonal are written.

    Parameters
    ----------
    tangent : (6, 6) ndarray
        ``M`` (:func:`local_tangent`).
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (``R_a = rotations[link]``).
    link : int
        The link.
    difference : (3,) ndarray  [m]
        ``d = x_b - x_a``.
    symmetric : bool
        ``M`` is symmetric: write the lower triangle.
    block : (12, 12) ndarray
        Receives the tangent.

    """
    # W = R M Rᵀ, 3 x 3 block by block (a symmetric M: its upper block is the lower's mirror)
    for row in range(0, 6, 3):
        for column in range(0, 6, 3):
            if column <= row or not symmetric:
                rotate_block(tangent, row, column, rotations, link, block, 6 + row, 6 + column)
    if symmetric:
        for i in range(3):
            for j in range(3):
                block[6 + i, 9 + j] = block[9 + j, 6 + i]
    d0, d1, d2 = difference[0], difference[1], difference[2]
    # W E_a: columns 0-2 are -W[:, 0:3], columns 3-5 are W[:, 0:3] d^ - W[:, 3:6]
    for r in range(6, 12):
        x0, x1, x2 = block[r, 6], block[r, 7], block[r, 8]
        block[r, 0] = -x0
        block[r, 1] = -x1
        block[r, 2] = -x2
        block[r, 3] = x1 * d2 - x2 * d1 - block[r, 9]
        block[r, 4] = x2 * d0 - x0 * d2 - block[r, 10]
        block[r, 5] = x0 * d1 - x1 * d0 - block[r, 11]
    # E_aᵀ (W E_a, W): rows 0-2 are -Y[0:3], rows 3-5 are -d^ Y[0:3] - Y[3:6]
    for c in range(6 if symmetric else 12):
        y0, y1, y2 = block[6, c], block[7, c], block[8, c]
        block[0, c] = -y0
        block[1, c] = -y1
        block[2, c] = -y2
        block[3, c] = -(y2 * d1 - d2 * y1) - block[9, c]
        block[4, c] = -(d2 * y0 - d0 * y2) - block[10, c]
        block[5, c] = -(d0 * y1 - d1 * y0) - block[11, c]


@numba.njit(cache=True, inline='always')
def symmetrize(matrix):
    """Replace a square matrix by its symmetric part ``(M + Mᵀ) / 2``, in place."""
    for i in range(1, matrix.shape[0]):
        for j in range(i):
            mean = 0.5 * (matrix[i, j] + matrix[j, i])
            matrix[i, j] = mean
            matrix[j, i] = mean


@numba.njit(cache=True, inline='always')
def add_geometric_terms(world, difference, symmetric, block):
    """
    Add the geometric terms of a link's world wrenches to its 12 x 12 tangent.

    With ``(F, M)`` the b-side world wrench (column 0 of ``world``): turning frame ``a`` turns it
    (``dF = -F^ dθ_a``, ``dM = -M^ dθ_a``), and the lever ``d = x_b - x_a`` of the a-side
    moment ``-M - d × F`` moves with ``x_a`` and ``x_b``. The blocks: ``-F^`` at (0, 3), ``F^`` at
    (3, 0), ``-F^`` at (3, 6), ``F^`` at (6, 3), ``M^`` at (9, 3) and ``-(M^ + d^ F^)`` at (3, 3),
    ``d^ F^ = F dᵀ - (d·F) I``. With ``symmetric``, their symmetric part on and below the
    diagonal: the pairs at (0, 3) / (3, 0) and (3, 6) / (6, 3) are each other's transposes
    (``F^`` stays below the diagonal), ``M^`` at (9, 3) has a zero mirror (half of it stays), the
    skew ``M^`` at (3, 3) has none and ``d^ F^`` gives ``(F dᵀ + d Fᵀ) / 2 - (d·F) I``.

    Parameters
    ----------
    world : (6, m + 1) ndarray  [N, N*m]
        The link's world wrenches (:func:`world_wrench`).
    difference : (3,) ndarray  [m]
        ``d``.
    symmetric : bool
        Add the symmetric part, lower triangle (the block of :func:`world_tangent` with
        ``symmetric``).
    block : (12, 12) ndarray
        Added to.

    """
    f0, f1, f2 = world[0, 0], world[1, 0], world[2, 0]
    m0, m1, m2 = world[3, 0], world[4, 0], world[5, 0]
    dot = difference[0] * f0 + difference[1] * f1 + difference[2] * f2
    add_scaled_hat(block, 3, 0, f0, f1, f2, 1.0)
    add_scaled_hat(block, 6, 3, f0, f1, f2, 1.0)
    if symmetric:
        add_scaled_hat(block, 9, 3, m0, m1, m2, 0.5)
        for i in range(3):
            for j in range(i + 1):
                block[3 + i, 3 + j] -= 0.5 * (world[i, 0] * difference[j]
                                              + difference[i] * world[j, 0])
            block[3 + i, 3 + i] += dot
        return
    add_scaled_hat(block, 0, 3, f0, f1, f2, -1.0)
    add_scaled_hat(block, 3, 6, f0, f1, f2, -1.0)
    add_scaled_hat(block, 9, 3, m0, m1, m2, 1.0)
    add_scaled_hat(block, 3, 3, m0, m1, m2, -1.0)
    for i in range(3):
        for j in range(3):
            block[3 + i, 3 + j] -= world[i, 0] * difference[j]
        block[3 + i, 3 + i] += dot


@numba.njit(cache=True, inline='always')
def rotate_block(source, r0, c0, rotations, link, target, r1, c1):
    """
    Write ``R_a S R_aᵀ`` of the 3 x 3 block ``S`` of ``source`` at (r0, c0) into ``target``.

    ``T = S R_aᵀ`` first, then ``R_a T``; ``R_a`` and ``S`` are read once, before the first
    store (a store to ``target`` could otherwise be one to them, for all the compiler knows).

    Parameters
    ----------
    source : (p, q) ndarray
        Holds ``S`` at rows ``r0 ...``, columns ``c0 ...``.
    r0, c0 : int
        Its corner.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (``R_a = rotations[link]``).
    link : int
        The frame.
    target : (p', q') ndarray
        Receives the block at rows ``r1 ...``, columns ``c1 ...``.
    r1, c1 : int
        Its corner.

    """
    r00, r01, r02 = rotations[link, 0, 0], rotations[link, 0, 1], rotations[link, 0, 2]
    r10, r11, r12 = rotations[link, 1, 0], rotations[link, 1, 1], rotations[link, 1, 2]
    r20, r21, r22 = rotations[link, 2, 0], rotations[link, 2, 1], rotations[link, 2, 2]
    s00, s01, s02 = source[r0, c0], source[r0, c0 + 1], source[r0, c0 + 2]
    s10, s11, s12 = source[r0 + 1, c0], source[r0 + 1, c0 + 1], source[r0 + 1, c0 + 2]
    s20, s21, s22 = source[r0 + 2, c0], source[r0 + 2, c0 + 1], source[r0 + 2, c0 + 2]
    # T = S R_aᵀ
    t00, t01, t02 = (s00 * r00 + s01 * r01 + s02 * r02, s00 * r10 + s01 * r11 + s02 * r12,
                     s00 * r20 + s01 * r21 + s02 * r22)
    t10, t11, t12 = (s10 * r00 + s11 * r01 + s12 * r02, s10 * r10 + s11 * r11 + s12 * r12,
                     s10 * r20 + s11 * r21 + s12 * r22)
    t20, t21, t22 = (s20 * r00 + s21 * r01 + s22 * r02, s20 * r10 + s21 * r11 + s22 * r12,
                     s20 * r20 + s21 * r21 + s22 * r22)
    # R_a T
    target[r1, c1] = r00 * t00 + r01 * t10 + r02 * t20
    target[r1, c1 + 1] = r00 * t01 + r01 * t11 + r02 * t21
    target[r1, c1 + 2] = r00 * t02 + r01 * t12 + r02 * t22
    target[r1 + 1, c1] = r10 * t00 + r11 * t10 + r12 * t20
    target[r1 + 1, c1 + 1] = r10 * t01 + r11 * t11 + r12 * t21
    target[r1 + 1, c1 + 2] = r10 * t02 + r11 * t12 + r12 * t22
    target[r1 + 2, c1] = r20 * t00 + r21 * t10 + r22 * t20
    target[r1 + 2, c1 + 1] = r20 * t01 + r21 * t11 + r22 * t21
    target[r1 + 2, c1 + 2] = r20 * t02 + r21 * t12 + r22 * t22


@numba.njit(cache=True)
def link_pass(system, positions, rotations, actuation, exact, into_band):
    """
    Add every link's wrenches to ``system.rhs`` and write or add its tangent (paper eq. 4-8).

    For each link, in order: :func:`link_deformation`, ``Jl⁻¹(φ)``, :func:`local_wrench`,
    :func:`add_cavity_wrenches`, :func:`world_wrench` and the frames' shares (column 0 and each
    cavity column),
    :func:`add_stress_terms` (exact), :func:`local_tangent`, :func:`world_tangent` and, exact,
    :func:`add_geometric_terms`. The
    12 x 12 tangent goes to ``system.values`` (its link block) or, ``into_band``, its symmetric
    part (of ``M`` first, :func:`symmetrize`, then of the geometric terms) into the block band
    ``system.blocks`` (:func:`~cbha_inverse.core._kernels.assembly.add_link_block`).

    Parameters
    ----------
    system : EquilibriumRecord
        The chain's terms and buffers (:mod:`cbha_inverse.core._kernels.evaluation`); its
        ``rhs`` is added to (zeroed by the caller).
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    actuation : (m,) ndarray  [Pa, N]
        ``λ`` (the cavity pressures enter the wrenches and the load stiffness).
    exact : bool
        The exact tangent (stress, geometric and load terms), else the material part.
    into_band : bool
        Add the tangents' symmetric parts into the block band instead of writing the blocks.

    """
    stiffness, rhs = system.stiffness, system.rhs
    difference, relative = system.link_difference, system.link_relative
    delta, stress = system.link_delta, system.link_stress
    jl_inverse, weighted = system.link_jl_inverse, system.link_weighted
    tangent = system.link_tangent
    local, world, block = system.link_local, system.link_world, system.link_block
    cavity_wrench, cavity_stiffness = system.cavity_wrench, system.cavity_stiffness
    cavity_columns, values, blocks = system.cavity_columns, system.values, system.blocks
    phi = delta[3:]
    for link in range(stiffness.shape[0]):
        theta = link_deformation(positions, rotations, system.rest_offsets,
                                 system.rest_rotations_t, link, difference, relative, delta)
        c, _ = jl_coefficient(theta)
        left_jacobian_inverse_into(phi, theta, c, jl_inverse)
        local_wrench(stiffness, link, delta, jl_inverse, stress, weighted, local)
        used = add_cavity_wrenches(cavity_wrench, cavity_stiffness, cavity_columns, link,
                                   actuation, delta, exact, local,
                                   weighted)
        for slot in range(1 + used):
            column = 0 if slot == 0 else 1 + cavity_columns[link, slot - 1]
            world_wrench(rotations, link, local, column, world)
            add_to_frame_b(world, column, link, rhs)
            if link > 0:
                add_to_frame_a(world, column, difference, link, rhs)
        if exact:
            add_stress_terms(weighted, delta, stress, theta)
        local_tangent(weighted, jl_inverse, tangent)
        if into_band:
            symmetrize(tangent)
        world_tangent(tangent, rotations, link, difference, into_band, block)
        if exact:
            add_geometric_terms(world, difference, into_band, block)
        if into_band:
            add_link_block(blocks, link, block)
        else:
            start = 144 * link
            for i in range(12):
                for j in range(12):
                    values[start + 12 * i + j] = block[i, j]
