"""
Compiled projection of a solved linearisation onto effectors and actuators (paper eq. 11-12).

:func:`effector_levers` and :func:`effector_points` are the one implementation of the effector
levers ``r = R_f o`` and points ``p = x_f + R_f o``, :func:`effector_columns_into` of ``J_eᵀ``;
:func:`project_effectors_into` forms ``W_ea``, ``W_aa`` and the free effector positions from
the half-solves of the band factor or from ``K⁻¹ [r, J_aᵀ]``; :func:`tick_outcome` the
actuation and remaining gap of a QP solution; :func:`target_status` checks the targets of a tick.
The kernels that a control tick calls once are inlined into their callers (``inline='always'``,
see :mod:`cbha_inverse.core._kernels.tick`).
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


@numba.njit(cache=True, inline='always')
def effector_points_into(positions, rotations, effector_frames, effector_offsets, points):
    """:func:`effector_points` into a preallocated ``points`` (k, 3)."""
    effector_levers_into(rotations, effector_frames, effector_offsets, points)
    for e in range(effector_frames.size):
        for i in range(3):
            points[e, i] += positions[effector_frames[e], i]


@numba.njit(cache=True, inline='always')
def effector_columns_into(rotations, effector_frames, effector_offsets, levers, columns):
    """
    Write ``J_eᵀ`` of effector points (paper Sec. IV) and return its first nonzero row.

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

    Returns
    -------
    int
        ``6 (min f - 1)``: the rows above it are zero.

    """
    effector_levers_into(rotations, effector_frames, effector_offsets, levers)
    columns[:, :] = 0.0
    first = columns.shape[0]
    for e in range(effector_frames.size):
        base = 6 * (effector_frames[e] - 1)
        first = min(first, base)
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
    return first


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
        solved, rhs, columns, False, positions, rotations, effector_frames, effector_offsets,
        previous, w_ea, w_aa, offset, np.empty((3 * k, width)))
    return w_ea, w_aa, offset, residual_norm


@numba.njit(cache=True, inline='always')
def project_effectors_into(solved, rhs, columns, half, positions, rotations, effector_frames,
                           effector_offsets, previous, w_ea, w_aa, offset, moved):
    """
    Project onto the effectors and actuators into preallocated ``w_ea``, ``w_aa``, ``offset``.

    The one implementation of paper eq. 11-12, on either operands of ``K⁻¹`` (`docs/design.md`):

    - ``half``: the half-solves of the band factor ``K = L Lᵀ``, ``solved = L⁻¹ [r, J_aᵀ]``
      and ``columns = L⁻¹ J_eᵀ`` (:func:`~cbha_inverse.core._kernels.band.band_forward`):
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
        _gram_into(solved, w_aa)
    else:
        for q in range(size):
            for i in range(m):
                weight = rhs[q, 1 + i]
                for j in range(m):
                    w_aa[i, j] += weight * solved[q, 1 + j]
    return math.sqrt(residual)


@numba.njit(cache=True)
def _gram_into(solved, w_aa):
    """
    Write ``w_aa = Yᵀ Y`` of the columns ``Y = solved[:, 1:]`` (symmetric: its lower triangle).

    By 2 x 2 blocks of ``w_aa``, two rows at a time: eight independent sums in registers
    (`docs/design.md`, step 2). A block starts at the first row where both of its column
    pairs have a nonzero entry: ``L⁻¹ J_aᵀ`` is zero above the first nonzero row of ``J_aᵀ``
    (an actuator of a later section), and those zeros add nothing.
    """
    size, width = solved.shape
    m = width - 1
    for i in range(0, m, 2):
        i1 = min(i + 1, m - 1)
        start_i = _first_nonzero(solved, 1 + i, 1 + i1)
        for j in range(0, i + 1, 2):
            j1 = min(j + 1, m - 1)
            start = max(start_i, _first_nonzero(solved, 1 + j, 1 + j1))
            a00 = a01 = a10 = a11 = 0.0
            b00 = b01 = b10 = b11 = 0.0
            q = start
            while q + 1 < size:
                yi0, yi1 = solved[q, 1 + i], solved[q, 1 + i1]
                yj0, yj1 = solved[q, 1 + j], solved[q, 1 + j1]
                a00 += yi0 * yj0
                a01 += yi0 * yj1
                a10 += yi1 * yj0
                a11 += yi1 * yj1
                yi0, yi1 = solved[q + 1, 1 + i], solved[q + 1, 1 + i1]
                yj0, yj1 = solved[q + 1, 1 + j], solved[q + 1, 1 + j1]
                b00 += yi0 * yj0
                b01 += yi0 * yj1
                b10 += yi1 * yj0
                b11 += yi1 * yj1
                q += 2
            if q < size:
                yi0, yi1 = solved[q, 1 + i], solved[q, 1 + i1]
                yj0, yj1 = solved[q, 1 + j], solved[q, 1 + j1]
                a00 += yi0 * yj0
                a01 += yi0 * yj1
                a10 += yi1 * yj0
                a11 += yi1 * yj1
            w_aa[i, j] = a00 + b00
            w_aa[i, j1] = a01 + b01
            w_aa[i1, j] = a10 + b10
            w_aa[i1, j1] = a11 + b11
    for i in range(m):
        for j in range(i):
            w_aa[j, i] = w_aa[i, j]


@numba.njit(cache=True, inline='always')
def _first_nonzero(solved, col, col1):
    """Return the first row of ``solved[:, [col, col1]]`` not zero (its length if none)."""
    for q in range(solved.shape[0]):
        if solved[q, col] != 0.0 or solved[q, col1] != 0.0:
            return q
    return solved.shape[0]


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


@numba.njit(cache=True, inline='always')
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


@numba.njit(cache=True, inline='always')
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
