"""
Compiled updates of the frames: world-axis retraction and the chain's deformation coordinates.

:func:`retract_frames` (``x += dx``, ``R ← exp(dθ) R``, `docs/design.md`) and the Newton step of a
factored tick (:func:`apply_linear_step_into`, on full solves or on the block factor's
half-solves); :func:`deformation_step` and :func:`deformed_poses`
apply an increment in the links' deformation coordinates (the static solver's line search).
"""

import math

from cbha_inverse.core._kernels.block_band import block_backward
from cbha_inverse.core._kernels.so3 import (jl_coefficient, left_jacobian_inverse_into,
                                            rotation_exp, rotation_exp_entries, rotation_log)
import numba
import numpy as np


@numba.njit(cache=True)
def retract_in_place(positions, rotations, increments, max_rotation):
    """
    Apply world-axis increments to frames 1..n in place, ``x += dx``, ``R ← exp(dθ) R``.

    The whole step is scaled down so that no frame rotates more than ``max_rotation`` [rad].
    ``exp(dθ)`` stays in registers (:func:`~cbha_inverse.core._kernels.so3.rotation_exp_entries`)
    and ``R`` is updated column by column, each read before it is written: no workspace
    (~30 % faster than through a (3, 3) one).
    """
    largest = 0.0
    for f in range(increments.shape[0]):
        largest = max(largest, increments[f, 3] ** 2 + increments[f, 4] ** 2
                      + increments[f, 5] ** 2)
    largest = math.sqrt(largest)
    factor = max_rotation / largest if largest > max_rotation else 1.0
    for f in range(increments.shape[0]):
        for i in range(3):
            positions[f + 1, i] += factor * increments[f, i]
        e00, e01, e02, e10, e11, e12, e20, e21, e22 = rotation_exp_entries(
            factor * increments[f, 3], factor * increments[f, 4], factor * increments[f, 5])
        rotation = rotations[f + 1]
        for j in range(3):
            r0, r1, r2 = rotation[0, j], rotation[1, j], rotation[2, j]
            rotation[0, j] = e00 * r0 + e01 * r1 + e02 * r2
            rotation[1, j] = e10 * r0 + e11 * r1 + e12 * r2
            rotation[2, j] = e20 * r0 + e21 * r1 + e22 * r2


@numba.njit(cache=True)
def apply_linear_step(positions, rotations, free_step, solved_actuators, change, max_rotation):
    """
    Apply the Newton step of a factored tick, ``dq = K⁻¹ r + K⁻¹ J_aᵀ Δλ``, in place.

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins (updated).
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations (updated).
    free_step : (6n,) ndarray  [m, rad]
        ``K⁻¹ r``.
    solved_actuators : (6n, m) ndarray
        ``K⁻¹ J_aᵀ``.
    change : (m,) ndarray
        ``Δλ = λ - λ_prev``.
    max_rotation : float  [rad]
        Scale the whole step down so that no frame rotates more than this.

    """
    size = solved_actuators.shape[0]
    apply_linear_step_into(positions, rotations, free_step, solved_actuators, change,
                           max_rotation, np.empty((size // 6, 6)), np.empty((0, 2, 6, 6)), False)


@numba.njit(cache=True)
def apply_linear_step_into(positions, rotations, free_step, solved_actuators, change,
                           max_rotation, increments, factor, half):
    """
    :func:`apply_linear_step` with its workspace given, on full solves or on half-solves.

    The step is ``free_step + solved_actuators Δλ``; with ``half`` the operands are the
    half-solves of the block factor ``K = L Lᵀ`` (``L⁻¹ r``, ``L⁻¹ J_aᵀ``,
    :func:`~cbha_inverse.core._kernels.block_band.block_forward`) and one backward sweep
    (:func:`~cbha_inverse.core._kernels.block_band.block_backward`) gives
    ``dq = L⁻ᵀ (L⁻¹ r + L⁻¹ J_aᵀ Δλ) = K⁻¹ (r + J_aᵀ Δλ)`` (`docs/design.md`, step 4).

    Parameters
    ----------
    positions, rotations, free_step, solved_actuators, change, max_rotation
        As :func:`apply_linear_step` (``free_step`` and ``solved_actuators`` the half-solves
        with ``half``); ``change`` may be a buffer of the caller (not ``increments``).
    increments : (n, 6) ndarray
        Workspace (C order): the step.
    factor : (n, B + 1, 6, 6) ndarray
        ``L`` in block band storage (read only with ``half``).
    half : bool
        Whether the operands are half-solves.

    """
    size, m = solved_actuators.shape
    step = increments.reshape((size, 1))
    for row in range(size):
        step[row, 0] = free_step[row]
    # column by column, each row summed in the order of a row's dot product: ``Δλ_j`` is
    # read once per column (a row loop reads all of it again per row, as its stores may alias
    # it: ~2x slower at m = 6)
    for j in range(m):
        weight = change[j]
        for row in range(size):
            step[row, 0] += solved_actuators[row, j] * weight
    if half:
        block_backward(factor, step)
    retract_in_place(positions, rotations, increments, max_rotation)


@numba.njit(cache=True)
def deformation_step(positions, rotations, rest_rotations, step, coordinates):
    """
    Map world increments of frames 1..n to increments of the links' deformation coordinates.

    The coordinates of link ``l`` (frames ``a = l``, ``b = l + 1``) are its offset
    ``u = R_aᵀ (x_b - x_a)`` and rotation vector ``φ = log(R_aᵀ R_b Q0ᵀ)``; their increments
    linearise the link deformation (paper eq. 4-8)::

        du = R_aᵀ (dx_b - dx_a - dθ_a x (x_b - x_a)),   dφ = Jl⁻¹(φ) R_aᵀ (dθ_b - dθ_a)

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    rest_rotations : (n, 3, 3) ndarray
        ``Q0``.
    step : (n, 6) ndarray  [m, rad]
        World increments ``(dx, dθ)`` of frames 1..n.
    coordinates : (n, 12) ndarray
        Receives ``(u, φ, du, dφ)`` per link.

    Returns
    -------
    float  [rad]
        The largest ``|dφ|``.

    """
    n = step.shape[0]
    rel = np.empty((3, 3))
    tmp = np.empty((3, 3))
    phi = np.empty(3)
    dx = np.empty(3)
    dt = np.empty(3)
    local = np.empty(3)
    jinv = np.empty((3, 3))
    largest = 0.0
    for link in range(n):
        ra = rotations[link]
        rb = rotations[link + 1]
        q0 = rest_rotations[link]
        for i in range(3):
            for j in range(3):
                tmp[i, j] = ra[0, i] * rb[0, j] + ra[1, i] * rb[1, j] + ra[2, i] * rb[2, j]
        for i in range(3):
            for j in range(3):
                rel[i, j] = tmp[i, 0] * q0[j, 0] + tmp[i, 1] * q0[j, 1] + tmp[i, 2] * q0[j, 2]
        theta = rotation_log(rel, phi)
        c, _ = jl_coefficient(theta)
        diff0 = positions[link + 1, 0] - positions[link, 0]
        diff1 = positions[link + 1, 1] - positions[link, 1]
        diff2 = positions[link + 1, 2] - positions[link, 2]
        if link > 0:
            a = step[link - 1]
            dx[0] = step[link, 0] - a[0] - (a[4] * diff2 - a[5] * diff1)
            dx[1] = step[link, 1] - a[1] - (a[5] * diff0 - a[3] * diff2)
            dx[2] = step[link, 2] - a[2] - (a[3] * diff1 - a[4] * diff0)
            for i in range(3):
                dt[i] = step[link, 3 + i] - a[3 + i]
        else:
            for i in range(3):
                dx[i] = step[link, i]
                dt[i] = step[link, 3 + i]
        out = coordinates[link]
        for i in range(3):
            out[i] = ra[0, i] * diff0 + ra[1, i] * diff1 + ra[2, i] * diff2
            out[3 + i] = phi[i]
            out[6 + i] = ra[0, i] * dx[0] + ra[1, i] * dx[1] + ra[2, i] * dx[2]
            local[i] = ra[0, i] * dt[0] + ra[1, i] * dt[1] + ra[2, i] * dt[2]
        left_jacobian_inverse_into(phi, theta, c, jinv)
        size = 0.0
        for i in range(3):
            value = jinv[i, 0] * local[0] + jinv[i, 1] * local[1] + jinv[i, 2] * local[2]
            out[9 + i] = value
            size += value * value
        largest = max(largest, size)
    return math.sqrt(largest)


@numba.njit(cache=True)
def deformed_poses(coordinates, alpha, rest_rotations, positions, rotations):
    """
    Set frames 1..n from deformation coordinates advanced by ``alpha`` (forward kinematics).

    ``R_b = R_a exp(φ + α dφ) Q0`` and ``x_b = x_a + R_a (u + α du)`` from the fixed base
    (coordinates of :func:`deformation_step`): a bending increment carries the rest of the chain
    along rigidly, which keeps full Newton steps acceptable at large rotations.

    Parameters
    ----------
    coordinates : (n, 12) ndarray
        ``(u, φ, du, dφ)`` per link.
    alpha : float
        Step length.
    rest_rotations : (n, 3, 3) ndarray
        ``Q0``.
    positions : (n + 1, 3) ndarray  [m]
        Row 0 is the base (kept); rows 1..n are written.
    rotations : (n + 1, 3, 3) ndarray
        Row 0 is the base (kept); rows 1..n are written.

    """
    n = coordinates.shape[0]
    vec = np.empty(3)
    rel = np.empty((3, 3))
    tmp = np.empty((3, 3))
    for link in range(n):
        out = coordinates[link]
        for i in range(3):
            vec[i] = out[3 + i] + alpha * out[9 + i]
        rotation_exp(vec, tmp)
        q0 = rest_rotations[link]
        for i in range(3):
            for j in range(3):
                rel[i, j] = tmp[i, 0] * q0[0, j] + tmp[i, 1] * q0[1, j] + tmp[i, 2] * q0[2, j]
        ra = rotations[link]
        for i in range(3):
            arm = 0.0
            for j in range(3):
                arm += ra[i, j] * (out[j] + alpha * out[6 + j])
                rotations[link + 1, i, j] = (ra[i, 0] * rel[0, j] + ra[i, 1] * rel[1, j]
                                             + ra[i, 2] * rel[2, j])
            positions[link + 1, i] = positions[link, i] + arm


def retract_frames(positions, rotations, increments, max_rotation=None, in_place=False):
    """
    Apply world-axis increments to frames 1..n (behind :func:`cbha_inverse.core.chain.retract`).

    Parameters
    ----------
    positions : (n + 1, 3) ndarray  [m]
        Frame origins.
    rotations : (n + 1, 3, 3) ndarray
        Frame rotations.
    increments : (n, 6) ndarray  [m, rad]
        ``(dx, dθ)`` per mobile frame.
    max_rotation : float, optional  [rad]
        Scale the whole step down so that no frame rotates more than this.
    in_place : bool
        Update ``positions`` and ``rotations`` (C-contiguous float arrays) instead of new arrays.

    Returns
    -------
    positions, rotations : ndarray
        ``x += dx``, ``R ← exp(dθ) R``.

    """
    if not in_place:
        positions, rotations = positions.copy(), rotations.copy()
    retract_in_place(positions, rotations, np.ascontiguousarray(increments, dtype=float),
                     math.inf if max_rotation is None else float(max_rotation))
    return positions, rotations
