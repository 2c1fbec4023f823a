"""
Compiled projection of a solved linearisation onto effectors and actuators (paper eq. 11-12).

:func:`effector_levers` and :func:`effector_points` are the one implementation of the effector
levers ``r = R_f o`` and points ``p = x_f + R_f o``, :func:`effector_columns_into` of ``J_eᵀ``;
:func:`project_effectors_into` forms ``W_ea``, ``W_aa`` and the free effector positions from
the half-solves of the block factor or from ``K⁻¹ [r, J_aᵀ]``; :func:`tick_outcome` the
actuation and remaining gap of a QP solution; :func:`target_status` checks the targets of a tick.
"""

import math

import numba
import numpy as np


@numba.njit(cache=True)
def effector_levers(rotations, effector_frames, effector_offsets):
    """
    Return the levers ``r = R_f o`` of effector points (paper Sec. IV, ``J_e``).

    The lever gives the ``[I, -r^]`` block of ``J_e`` on the effector's frame ``f``
    (:mod:`cbha_inverse.core.actuation.effectors`).

    Parameters
    ----------
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (frame axes → world).
    effector_frames : (k,) int ndarray
        Frame of every effector (1..n).
    effector_offsets : (k, 3) ndarray  [m]
        Effector points in their frame's axes.

    Returns
    -------
    (k, 3) ndarray  [m]
        ``R_f o``.

    """
    levers = np.empty((effector_frames.size, 3))
    effector_levers_into(rotations, effector_frames, effector_offsets, levers)
    return levers


@numba.njit(cache=True)
def effector_levers_into(rotations, effector_frames, effector_offsets, levers):
    """:func:`effector_levers` into a preallocated ``levers`` (k, 3)."""
    for e in range(effector_frames.size):
        rot = rotations[effector_frames[e]]
        offset = effector_offsets[e]
        for i in range(3):
            levers[e, i] = rot[i, 0] * offset[0] + rot[i, 1] * offset[1] + rot[i, 2] * offset[2]


@numba.njit(cache=True)
def effector_points(positions, rotations, effector_frames, effector_offsets):
    """
    Return the world positions ``p = x_f + R_f o`` of effector points.

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (frame axes → world).
    effector_frames : (k,) int ndarray
        Frame of every effector (1..n).
    effector_offsets : (k, 3) ndarray  [m]
        Effector points in their frame's axes.

    Returns
    -------
    (k, 3) ndarray  [m]
        ``x_f + R_f o`` (the lever ``R_f o`` from :func:`effector_levers`).

    """
    points = np.empty((effector_frames.size, 3))
    effector_points_into(positions, rotations, effector_frames, effector_offsets, points)
    return points


@numba.njit(cache=True)
def effector_points_into(positions, rotations, effector_frames, effector_offsets, points):
    """:func:`effector_points` into a preallocated ``points`` (k, 3)."""
    effector_levers_into(rotations, effector_frames, effector_offsets, points)
    for e in range(effector_frames.size):
        for i in range(3):
            points[e, i] += positions[effector_frames[e], i]


@numba.njit(cache=True)
def effector_columns_into(rotations, effector_frames, effector_offsets, levers, columns):
    """
    Write ``J_eᵀ`` of effector points (paper Sec. IV).

    Effector ``e`` on frame ``f`` moves by ``dp = dx_f + dθ_f x r = [I, -r^] [dx_f; dθ_f]``
    (``r = R_f o``, :func:`effector_levers`): its columns ``3e ... 3e + 2`` of ``J_eᵀ`` are
    ``[I; r^]`` in rows ``6 (f - 1) ... 6 f - 1``, zero elsewhere.

    Parameters
    ----------
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (frame axes → world).
    effector_frames : (k,) int ndarray
        Frame of every effector (1..n).
    effector_offsets : (k, 3) ndarray  [m]
        Effector points in their frame's axes.
    levers : (k, 3) ndarray  [m]
        Receives ``R_f o``.
    columns : (6n, 3k) ndarray  [1, m]
        Receives ``J_eᵀ``.

    """
    effector_levers_into(rotations, effector_frames, effector_offsets, levers)
    columns[:, :] = 0.0
    for e in range(effector_frames.size):
        base = 6 * (effector_frames[e] - 1)
        rx, ry, rz = levers[e, 0], levers[e, 1], levers[e, 2]
        for i in range(3):
            columns[base + i, 3 * e + i] = 1.0
        # r^ = [[0, -rz, ry], [rz, 0, -rx], [-ry, rx, 0]]
        columns[base + 3, 3 * e + 1] = -rz
        columns[base + 3, 3 * e + 2] = ry
        columns[base + 4, 3 * e] = rz
        columns[base + 4, 3 * e + 2] = -rx
        columns[base + 5, 3 * e] = -ry
        columns[base + 5, 3 * e + 1] = rx


@numba.njit(cache=True)
def project_effectors(solved, rhs, positions, rotations, effector_frames, effector_offsets,
                      previous):
    """
    Project a solved tick onto the effectors and actuators (paper eq. 11-12).

    With ``solved = K⁻¹ [r, J_aᵀ]`` and the effector Jacobian ``J_e`` (block ``[I, -r^]`` on
    the effector's frame, ``r = R_f o``, :func:`effector_columns_into`):
    ``W_ea = J_e K⁻¹ J_aᵀ``, ``W_aa = J_a K⁻¹ J_aᵀ`` and the free effector positions
    ``p_e + J_e K⁻¹ r``, returned relative to the previous actuation so that
    ``δ_free = offset - target`` (:func:`project_effectors_into` on full solves).

    Parameters
    ----------
    solved : (6n, m + 1) ndarray
        ``K⁻¹ [r, J_aᵀ]``.
    rhs : (6n, m + 1) ndarray
        ``[r, J_aᵀ]``.
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    effector_frames : (k,) int ndarray
        Frame of every effector (1..n).
    effector_offsets : (k, 3) ndarray  [m]
        Effector points in their frame's axes.
    previous : (m,) ndarray
        ``λ_prev``.

    Returns
    -------
    w_ea : (3k, m) ndarray  [m/N, m/Pa]
    w_aa : (m, m) ndarray
    offset : (3k,) ndarray  [m]
        ``p_e + J_e K⁻¹ r - W_ea λ_prev``.
    residual_norm : float  [N, N*m]
        ``|r|``.

    """
    size, width = solved.shape
    k = effector_frames.size
    w_ea, w_aa, offset = np.empty((3 * k, width - 1)), np.empty((width - 1, width - 1)), np.empty(
        3 * k)
    columns = np.empty((size, 3 * k))
    effector_columns_into(rotations, effector_frames, effector_offsets, np.empty((k, 3)),
                          columns)
    residual_norm = project_effectors_into(
        solved, rhs, columns, False, np.zeros(width, dtype=np.int64), positions, rotations,
        effector_frames, effector_offsets, previous, w_ea, w_aa, offset, np.empty((3 * k, width)))
    return w_ea, w_aa, offset, residual_norm


@numba.njit(cache=True)
def project_effectors_into(solved, rhs, columns, half, starts, positions, rotations,
                           effector_frames, effector_offsets, previous, w_ea, w_aa, offset,
                           moved):
    """
    Project onto the effectors and actuators into preallocated ``w_ea``, ``w_aa``, ``offset``.

    The one implementation of paper eq. 11-12, on either operands of ``K⁻¹`` (`docs/design.md`):

    - ``half``: the half-solves of the block factor ``K = L Lᵀ``, ``solved = L⁻¹ [r, J_aᵀ]``
      and ``columns = L⁻¹ J_eᵀ`` (:func:`~cbha_inverse.core._kernels.block_band.block_forward`):
      ``W_ea = columnsᵀ solved_a``, ``J_e K⁻¹ r = columnsᵀ solved_r`` over the rows from the
      effector's frame to the end, ``W_aa = solved_aᵀ solved_a`` (symmetric: its lower
      triangle, mirrored);
    - else full solves by another factor, ``solved = K⁻¹ [r, J_aᵀ]`` and ``columns = J_eᵀ``
      (:func:`effector_columns_into`): the same products over the effector frame's six rows,
      ``W_aa = J_a solved_a`` (``K`` need not be symmetric).

    Parameters
    ----------
    solved : (6n, m + 1) ndarray
        ``L⁻¹ [r, J_aᵀ]`` or ``K⁻¹ [r, J_aᵀ]``.
    rhs : (6n, m + 1) ndarray
        ``[r, J_aᵀ]``.
    columns : (6n, 3k) ndarray
        ``L⁻¹ J_eᵀ`` or ``J_eᵀ``.
    half : bool
        Which operands.
    starts : (m + 1,) int ndarray
        With ``half``, the first nonzero row of each column of ``[r, J_aᵀ]``: its half-solve is
        zero above that row's block (not read otherwise).
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    effector_frames : (k,) int ndarray
        Frame of every effector (1..n).
    effector_offsets : (k, 3) ndarray  [m]
        Effector points in their frame's axes.
    previous : (m,) ndarray
        ``λ_prev``.
    w_ea : (3k, m) ndarray  [m/N, m/Pa]
        Receives ``J_e K⁻¹ J_aᵀ``.
    w_aa : (m, m) ndarray
        Receives ``J_a K⁻¹ J_aᵀ``.
    offset : (3k,) ndarray  [m]
        Receives ``p_e + J_e K⁻¹ r - W_ea λ_prev``.
    moved : (3k, m + 1) ndarray
        Workspace: ``J_e K⁻¹ [r, J_aᵀ]``.

    Returns
    -------
    float  [N, N*m]
        ``|r|``.

    """
    size, width = solved.shape
    m = width - 1
    k = effector_frames.size
    effector_points_into(positions, rotations, effector_frames, effector_offsets,
                         offset.reshape((k, 3)))
    moved[:, :] = 0.0
    for e in range(k):
        base = 6 * (effector_frames[e] - 1)
        end = size if half else base + 6
        for q in range(base, end):
            for c in range(3 * e, 3 * e + 3):
                weight = columns[q, c]
                for col in range(width):
                    moved[c, col] += weight * solved[q, col]
    for row in range(3 * k):
        acc = offset[row] + moved[row, 0]
        for j in range(m):
            w_ea[row, j] = moved[row, 1 + j]
            acc -= moved[row, 1 + j] * previous[j]
        offset[row] = acc
    w_aa[:, :] = 0.0
    residual = 0.0
    for q in range(size):
        residual += rhs[q, 0] * rhs[q, 0]
    if half:
        _gram_into(solved, starts, w_aa)
    else:
        for q in range(size):
            for i in range(m):
                weight = rhs[q, 1 + i]
                for j in range(m):
                    w_aa[i, j] += weight * solved[q, 1 + j]
    return math.sqrt(residual)


@numba.njit(cache=True)
def _gram_into(solved, starts, w_aa):
    """
    Write ``w_aa = Yᵀ Y`` of the columns ``Y = solved[:, 1:]``, symmetric.

    ``L⁻¹ J_aᵀ`` is zero above the block of the first nonzero row of ``J_aᵀ`` (``starts``: an
    actuator of a later section): each product starts at the later of its two columns' blocks.
    """
    size, width = solved.shape
    for i in range(width - 1):
        for j in range(i + 1):
            value = column_dot(solved, 1 + i, 1 + j,
                               max(starts[1 + i], starts[1 + j]) // 6 * 6, size)
            w_aa[i, j] = value
            w_aa[j, i] = value


@numba.njit(cache=True, inline='always')
def column_dot(matrix, a, b, first, end):
    """
    Return the dot product of columns ``a`` and ``b`` of ``matrix`` over rows ``first ... end-1``.

    Four partial sums, every fourth row each: independent chains of multiply-adds (a single sum
    waits on each of its additions in turn).
    """
    s0 = s1 = s2 = s3 = 0.0
    q = first
    while q + 3 < end:
        s0 += matrix[q, a] * matrix[q, b]
        s1 += matrix[q + 1, a] * matrix[q + 1, b]
        s2 += matrix[q + 2, a] * matrix[q + 2, b]
        s3 += matrix[q + 3, a] * matrix[q + 3, b]
        q += 4
    while q < end:
        s0 += matrix[q, a] * matrix[q, b]
        q += 1
    return (s0 + s1) + (s2 + s3)


@numba.njit(cache=True)
def tick_outcome(w_ea, delta_free, scale, x, x_previous, lower_bounds, upper_bounds):
    """
    Return the actuation of a QP solution and the linear model's remaining effector gap.

    Parameters
    ----------
    w_ea : (3k, m) ndarray  [m/N, m/Pa]
        Effector-actuator compliance.
    delta_free : (3k,) ndarray  [m]
        ``δ_e^free`` (free effector positions minus targets).
    scale : (m,) ndarray
        ``σ``: ``λ = σ x``.
    x, x_previous : (m,) ndarray
        QP solution and the previous actuation, dimensionless.
    lower_bounds, upper_bounds : (m,) ndarray
        Actuator bounds.

    Returns
    -------
    actuation : (m,) ndarray  [N, Pa]
        ``σ x`` clipped into the bounds.
    gap : (3k,) ndarray  [m]
        ``W_ea λ + δ_free`` (paper eq. 11: predicted effector minus target).
    largest_gap : float  [m]
        Largest effector distance ``max_e |gap_e|``.
    largest_move : float
        ``max |x - x_previous|`` (dimensionless actuation change).
    finite : bool
        Whether every ``x`` is finite (else the caller holds the actuation).

    """
    actuation, gap = np.empty(w_ea.shape[1]), np.empty(w_ea.shape[0])
    largest_gap, largest_move, finite = tick_outcome_into(
        w_ea, delta_free, scale, x, x_previous, lower_bounds, upper_bounds, actuation, gap)
    return actuation, gap, largest_gap, largest_move, finite


@numba.njit(cache=True)
def tick_outcome_into(w_ea, delta_free, scale, x, x_previous, lower_bounds, upper_bounds,
                      actuation, gap):
    """
    :func:`tick_outcome` into preallocated ``actuation`` (m,) and ``gap`` (3k,).

    Returns ``(largest_gap, largest_move, finite)``.
    """
    rows, m = w_ea.shape
    largest_move = 0.0
    finite = True
    for j in range(m):
        if not math.isfinite(x[j]):
            finite = False
        actuation[j] = min(max(scale[j] * x[j], lower_bounds[j]), upper_bounds[j])
        largest_move = max(largest_move, abs(x[j] - x_previous[j]))
    for r in range(rows):
        acc = delta_free[r]
        for j in range(m):
            acc += w_ea[r, j] * actuation[j]
        gap[r] = acc
    largest = 0.0
    for e in range(rows // 3):
        largest = max(largest, gap[3 * e] ** 2 + gap[3 * e + 1] ** 2 + gap[3 * e + 2] ** 2)
    return math.sqrt(largest), largest_move, finite


@numba.njit(cache=True)
def target_status(targets, base, reach):
    """
    Check the effector targets of a tick: finite, and within reach of the chain.

    Parameters
    ----------
    targets : (k, 3) ndarray  [m]
        Effector targets.
    base : (3,) ndarray  [m]
        Base position.
    reach : (k,) ndarray  [m]
        Largest distance (max-abs component) an effector can be from the base.

    Returns
    -------
    int
        0: finite and within reach; 1: not finite; 2: finite but some target beyond reach.

    """
    status = 0
    for e in range(targets.shape[0]):
        for i in range(3):
            value = targets[e, i]
            if not math.isfinite(value):
                return 1
            if abs(value - base[i]) > reach[e]:
                status = 2
    return status
