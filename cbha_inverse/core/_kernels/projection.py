"""
Compiled projection of a solved linearisation onto effectors and actuators (paper eq. 11-12).

:func:`effector_levers` and :func:`effector_points` are the one implementation of the effector
levers ``r = R_f o`` and points ``p = x_f + R_f o``; :func:`project_effectors` forms ``W_ea``,
``W_aa`` and the free effector positions from ``K⁻¹ [r, J_aᵀ]``; :func:`tick_outcome` the
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
def project_effectors(solved, rhs, positions, rotations, effector_frames, effector_offsets,
                      previous):
    """
    Project a solved tick onto the effectors and actuators (paper eq. 11-12).

    With ``solved = K⁻¹ [r, J_aᵀ]`` and the effector Jacobian ``J_e`` (block ``[I, -r^]`` on
    the effector's frame, ``r = R_f o``, :mod:`cbha_inverse.core.actuation.effectors`):
    ``W_ea = J_e K⁻¹ J_aᵀ``, ``W_aa = J_a K⁻¹ J_aᵀ`` and the free effector positions
    ``p_e + J_e K⁻¹ r``, returned relative to the previous actuation so that
    ``δ_free = offset - target``.

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
    width = solved.shape[1]
    k = effector_frames.size
    w_ea, w_aa, offset = np.empty((3 * k, width - 1)), np.empty((width - 1, width - 1)), np.empty(
        3 * k)
    residual_norm = project_effectors_into(
        solved, rhs, positions, rotations, effector_frames, effector_offsets, previous, w_ea,
        w_aa, offset, np.empty((3 * k, width)), np.empty((k, 3)))
    return w_ea, w_aa, offset, residual_norm


@numba.njit(cache=True)
def project_effectors_into(solved, rhs, positions, rotations, effector_frames, effector_offsets,
                           previous, w_ea, w_aa, offset, moved, levers):
    """
    :func:`project_effectors` into preallocated ``w_ea``, ``w_aa`` and ``offset``.

    ``moved`` (3k, m + 1) and ``levers`` (k, 3) are its workspace. Returns ``|r|``.
    """
    size, width = solved.shape
    m = width - 1
    k = effector_frames.size
    effector_levers_into(rotations, effector_frames, effector_offsets, levers)
    for e in range(k):
        lever = levers[e]
        for i in range(3):
            offset[3 * e + i] = positions[effector_frames[e], i] + lever[i]
        base = 6 * (effector_frames[e] - 1)
        for col in range(width):
            rx, ry, rz = solved[base + 3, col], solved[base + 4, col], solved[base + 5, col]
            # dp = dx + dθ x r
            moved[3 * e, col] = solved[base, col] + ry * lever[2] - rz * lever[1]
            moved[3 * e + 1, col] = solved[base + 1, col] + rz * lever[0] - rx * lever[2]
            moved[3 * e + 2, col] = solved[base + 2, col] + rx * lever[1] - ry * lever[0]
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
        for i in range(m):
            weight = rhs[q, 1 + i]
            if weight != 0.0:
                for j in range(m):
                    w_aa[i, j] += weight * solved[q, 1 + j]
    return math.sqrt(residual)


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
