"""
Compiled projection of a solved linearisation onto effectors and actuators (paper eq. 11-12).

:func:`effector_levers` and :func:`effector_points` are the one implementation of the effector
levers ``r = R_f o`` and points ``p = x_f + R_f o``, :func:`effector_columns_into` of the
position columns of ``J_eᵀ``, :func:`effector_jacobian_into` of all of ``J_eᵀ`` (with the
rotational rows of ``axis`` and ``pose`` effectors, :mod:`cbha_inverse.core.actuation.effectors`)
and :func:`orientation_errors_into` of their orientation errors; :func:`project_effectors_into`
forms ``W_ea``, ``W_aa`` and the free effector gaps from the half-solves of the block factor or
from ``K⁻¹ [r, J_aᵀ]``; :func:`tick_outcome` the actuation and remaining gap of a QP solution;
:func:`target_status` checks the targets of a tick.

Rows of ``J_e`` (and of ``W_ea``, ``δ_free``, the gap): the ``3k`` position rows, three per
effector in effector order, then the ``o`` rotational rows (``orientation_effectors`` names the
effector of each).
"""

import math

from cbha_inverse.core._kernels.so3 import rotation_log_scalars
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
def effector_jacobian_into(rotations, effector_frames, effector_offsets, orientation_effectors,
                           orientation_axes, levers, orientation_directions, columns):
    """
    Write ``J_eᵀ`` of effectors with rotational rows (``docs/effectors.md``).

    The position columns ``0 ... 3k - 1`` of :func:`effector_columns_into`, then one column per
    rotational row ``ρ``: the row's world direction ``c = R_f v`` (``v`` in the frame's axes)
    turns by ``c · dθ_f`` to first order, its ``J_e`` row is ``[0, cᵀ]`` on frame ``f``: column
    ``3k + ρ`` of ``J_eᵀ`` is ``c`` in rows ``6 (f - 1) + 3 ... 6 f - 1``, zero elsewhere.

    Parameters
    ----------
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (frame axes → world).
    effector_frames : (k,) int ndarray
        Frame of every effector (1..n).
    effector_offsets : (k, 3) ndarray  [m]
        Effector points in their frame's axes.
    orientation_effectors : (o,) int ndarray
        The effector of every rotational row.
    orientation_axes : (o, 3) ndarray
        Each rotational row's unit vector ``v`` in its frame's axes.
    levers : (k, 3) ndarray  [m]
        Receives ``R_f o``.
    orientation_directions : (o, 3) ndarray
        Receives ``c = R_f v``.
    columns : (6n, 3k + o) ndarray  [1, m]
        Receives ``J_eᵀ``.

    """
    effector_columns_into(rotations, effector_frames, effector_offsets, levers, columns)
    first = 3 * effector_frames.size
    for row in range(orientation_effectors.size):
        frame = effector_frames[orientation_effectors[row]]
        rot, axis = rotations[frame], orientation_axes[row]
        base = 6 * (frame - 1) + 3
        for i in range(3):
            direction = rot[i, 0] * axis[0] + rot[i, 1] * axis[1] + rot[i, 2] * axis[2]
            orientation_directions[row, i] = direction
            columns[base + i, first + row] = direction


@numba.njit(cache=True)
def orientation_errors_into(rotations, effector_frames, effector_kinds, effector_axes,
                            target_rotations, target_directions, errors, relative):
    """
    Write each effector's orientation error ``ψ`` [rad], a rotation vector in world axes.

    ``pose`` (kind 2): ``ψ = log(R_f R_tᵀ)``, the rotation from the target to the frame.
    ``axis`` (kind 1): the shortest rotation from the target direction ``d`` to the axis
    ``a = R_f u``: ``ψ = atan2(|d × a|, d · a) (d × a) / |d × a|`` (orthogonal to ``a``; for
    ``a = -d`` a half turn about the first of the frame's axes orthogonal to ``u``, up to
    round-off). ``point`` (kind 0): zero. A rotation ``dθ`` of the frame changes the error by
    ``dθ`` (``pose``) or by its part orthogonal to ``a`` (``axis``) to first order.

    Parameters
    ----------
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (frame axes → world).
    effector_frames : (k,) int ndarray
        Frame of every effector (1..n).
    effector_kinds : (k,) int ndarray
        0 point, 1 axis, 2 pose.
    effector_axes : (k, 3) ndarray
        Unit axis ``u`` of every ``axis`` effector in its frame's axes.
    target_rotations : (k, 3, 3) ndarray
        Target ``R_t`` of every ``pose`` effector (world axes).
    target_directions : (k, 3) ndarray
        Unit target direction ``d`` of every ``axis`` effector (world axes).
    errors : (k, 3) ndarray  [rad]
        Receives ``ψ``.
    relative : (3, 3) ndarray
        Workspace (``R_f R_tᵀ``).

    """
    for e in range(effector_frames.size):
        rot = rotations[effector_frames[e]]
        kind = effector_kinds[e]
        if kind == 2:
            target = target_rotations[e]
            for i in range(3):
                for j in range(3):
                    relative[i, j] = (rot[i, 0] * target[j, 0] + rot[i, 1] * target[j, 1]
                                      + rot[i, 2] * target[j, 2])
            _, errors[e, 0], errors[e, 1], errors[e, 2] = rotation_log_scalars(relative)
            continue
        errors[e, 0] = errors[e, 1] = errors[e, 2] = 0.0
        if kind != 1:
            continue
        u, d = effector_axes[e], target_directions[e]
        a0 = rot[0, 0] * u[0] + rot[0, 1] * u[1] + rot[0, 2] * u[2]
        a1 = rot[1, 0] * u[0] + rot[1, 1] * u[1] + rot[1, 2] * u[2]
        a2 = rot[2, 0] * u[0] + rot[2, 1] * u[1] + rot[2, 2] * u[2]
        s0, s1, s2 = d[1] * a2 - d[2] * a1, d[2] * a0 - d[0] * a2, d[0] * a1 - d[1] * a0
        sine = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        cosine = d[0] * a0 + d[1] * a1 + d[2] * a2
        if sine < 1e-12 and cosine < 0.0:
            # a half turn about a frame axis orthogonal to the axis: least aligned with u
            pick = 0
            for i in range(1, 3):
                if abs(u[i]) < abs(u[pick]):
                    pick = i
            s0, s1, s2 = rot[0, pick], rot[1, pick], rot[2, pick]
            along = s0 * a0 + s1 * a1 + s2 * a2
            s0, s1, s2 = s0 - along * a0, s1 - along * a1, s2 - along * a2
            sine = math.sqrt(s0 * s0 + s1 * s1 + s2 * s2)
        ratio = math.atan2(sine, cosine) / max(sine, 1e-300)
        errors[e, 0], errors[e, 1], errors[e, 2] = s0 * ratio, s1 * ratio, s2 * ratio


@numba.njit(cache=True)
def free_gaps_into(offset, targets, orientation_effectors, orientation_directions, errors,
                   delta_free):
    """
    Write ``δ_free``: the free effector gaps to the targets (paper eq. 11).

    Position rows ``offset - target``; rotational row ``ρ`` of effector ``e``
    ``offset_ρ + c_ρ · ψ_e`` (``ψ`` of :func:`orientation_errors_into` at the linearisation's
    frames, ``c`` its direction from :func:`effector_jacobian_into`): the linearised error
    after the free motion.

    Parameters
    ----------
    offset : (3k + o,) ndarray  [m, rad]
        ``p_e + J_e K⁻¹ r - W_ea λ_prev`` (rotational rows: ``J_e K⁻¹ r - W_ea λ_prev``).
    targets : (k, 3) ndarray  [m]
        Effector position targets.
    orientation_effectors : (o,) int ndarray
        The effector of every rotational row.
    orientation_directions : (o, 3) ndarray
        Each rotational row's world direction ``c``.
    errors : (k, 3) ndarray  [rad]
        Orientation errors ``ψ``.
    delta_free : (3k + o,) ndarray  [m, rad]
        Receives ``δ_free``.

    """
    k = targets.shape[0]
    for e in range(k):
        for i in range(3):
            delta_free[3 * e + i] = offset[3 * e + i] - targets[e, i]
    for row in range(orientation_effectors.size):
        error, direction = errors[orientation_effectors[row]], orientation_directions[row]
        delta_free[3 * k + row] = offset[3 * k + row] + (
            direction[0] * error[0] + direction[1] * error[1] + direction[2] * error[2])


@numba.njit(cache=True)
def project_effectors(solved, rhs, positions, rotations, effector_frames, effector_offsets,
                      previous):
    """
    Project a solved tick onto the effectors and actuators (paper eq. 11-12).

    With ``solved = K⁻¹ [r, J_aᵀ]`` and the effector Jacobian ``J_e`` (block ``[I, -r^]`` on
    the effector's frame, ``r = R_f o``, :func:`effector_columns_into`):
    ``W_ea = J_e K⁻¹ J_aᵀ``, ``W_aa = J_a K⁻¹ J_aᵀ`` and the free effector positions
    ``p_e + J_e K⁻¹ r``, returned relative to the previous actuation so that
    ``δ_free = offset - target`` (:func:`project_effectors_into` on full solves; position rows
    only).

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
        effector_frames, effector_offsets, np.zeros(0, dtype=np.int64), previous, w_ea, w_aa,
        offset, np.empty((3 * k, width)))
    return w_ea, w_aa, offset, residual_norm


@numba.njit(cache=True)
def project_effectors_into(solved, rhs, columns, half, starts, positions, rotations,
                           effector_frames, effector_offsets, orientation_effectors, previous,
                           w_ea, w_aa, offset, moved):
    """
    Project onto the effectors and actuators into preallocated ``w_ea``, ``w_aa``, ``offset``.

    The one implementation of paper eq. 11-12, on either operands of ``K⁻¹`` (`docs/design.md`):

    - ``half``: the half-solves of the block factor ``K = L Lᵀ``, ``solved = L⁻¹ [r, J_aᵀ]``
      and ``columns = L⁻¹ J_eᵀ`` (:func:`~cbha_inverse.core._kernels.block_band.block_forward`):
      ``W_ea = columnsᵀ solved_a``, ``J_e K⁻¹ r = columnsᵀ solved_r`` over the rows from the
      effector's frame to the end, ``W_aa = solved_aᵀ solved_a`` (symmetric: its lower
      triangle, mirrored);
    - else full solves by another factor, ``solved = K⁻¹ [r, J_aᵀ]`` and ``columns = J_eᵀ``
      (:func:`effector_jacobian_into`): the same products over the effector frame's six rows,
      ``W_aa = J_a solved_a`` (``K`` need not be symmetric).

    The rotational rows of ``J_e`` (columns ``3k ...`` of ``columns``, one per entry of
    ``orientation_effectors``) are projected by the same products: their rows of ``W_ea`` and
    ``J_e K⁻¹ r``; their ``offset`` has no ``p_e`` (the orientation error enters with the
    target, :func:`free_gaps_into`).

    Parameters
    ----------
    solved : (6n, m + 1) ndarray
        ``L⁻¹ [r, J_aᵀ]`` or ``K⁻¹ [r, J_aᵀ]``.
    rhs : (6n, m + 1) ndarray
        ``[r, J_aᵀ]``.
    columns : (6n, 3k + o) ndarray
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
    orientation_effectors : (o,) int ndarray
        The effector of every rotational row (empty: points only).
    previous : (m,) ndarray
        ``λ_prev``.
    w_ea : (3k + o, m) ndarray  [m/N, m/Pa; rad/N, rad/Pa]
        Receives ``J_e K⁻¹ J_aᵀ``.
    w_aa : (m, m) ndarray
        Receives ``J_a K⁻¹ J_aᵀ``.
    offset : (3k + o,) ndarray  [m, rad]
        Receives ``p_e + J_e K⁻¹ r - W_ea λ_prev`` (rotational rows without ``p_e``).
    moved : (3k + o, m + 1) ndarray
        Workspace: ``J_e K⁻¹ [r, J_aᵀ]``.

    Returns
    -------
    float  [N, N*m]
        ``|r|``.

    """
    size, width = solved.shape
    m = width - 1
    k = effector_frames.size
    rows = offset.size
    effector_points_into(positions, rotations, effector_frames, effector_offsets,
                         offset[:3 * k].reshape((k, 3)))
    offset[3 * k:] = 0.0
    moved[:, :] = 0.0
    for c in range(rows):
        e = c // 3 if c < 3 * k else orientation_effectors[c - 3 * k]
        base = 6 * (effector_frames[e] - 1)
        end = size if half else base + 6
        for q in range(base, end):
            weight = columns[q, c]
            for col in range(width):
                moved[c, col] += weight * solved[q, col]
    for row in range(rows):
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
def tick_outcome(w_ea, delta_free, scale, x, x_previous, lower_bounds, upper_bounds,
                 position_rows):
    """
    Return the actuation of a QP solution and the linear model's remaining effector gap.

    Parameters
    ----------
    w_ea : (3k + o, m) ndarray  [m/N, m/Pa; rad/N, rad/Pa]
        Effector-actuator compliance.
    delta_free : (3k + o,) ndarray  [m, rad]
        ``δ_e^free`` (free effector gaps to the targets).
    scale : (m,) ndarray
        ``σ``: ``λ = σ x``.
    x, x_previous : (m,) ndarray
        QP solution and the previous actuation, dimensionless.
    lower_bounds, upper_bounds : (m,) ndarray
        Actuator bounds.
    position_rows : int
        ``3k``: the position rows (the rotational rows follow).

    Returns
    -------
    actuation : (m,) ndarray  [N, Pa]
        ``σ x`` clipped into the bounds.
    gap : (3k + o,) ndarray  [m, rad]
        ``W_ea λ + δ_free`` (paper eq. 11: predicted effector minus target).
    largest_gap : float  [m]
        Largest effector distance ``max_e |gap_e|`` (position rows).
    largest_move : float
        ``max |x - x_previous|`` (dimensionless actuation change).
    finite : bool
        Whether every ``x`` is finite (else the caller holds the actuation).

    """
    actuation, gap = np.empty(w_ea.shape[1]), np.empty(w_ea.shape[0])
    largest_gap, largest_move, finite = tick_outcome_into(
        w_ea, delta_free, scale, x, x_previous, lower_bounds, upper_bounds, position_rows,
        actuation, gap)
    return actuation, gap, largest_gap, largest_move, finite


@numba.njit(cache=True)
def tick_outcome_into(w_ea, delta_free, scale, x, x_previous, lower_bounds, upper_bounds,
                      position_rows, actuation, gap):
    """
    :func:`tick_outcome` into preallocated ``actuation`` (m,) and ``gap`` (3k + o,).

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
    for e in range(position_rows // 3):
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
