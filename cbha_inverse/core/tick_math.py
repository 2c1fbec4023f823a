"""
SO(3) helpers of the fused tick (:mod:`cbha_inverse.core.tick`), compiled with numba.

Per-link scalar forms of the ``Jl⁻¹`` coefficients, the rotation logarithm and exponential (the
same formulas as :mod:`cbha_inverse.core.se3`, which stays the batched numpy reference and the
tests' oracle), the retraction of the frames (:func:`cbha_inverse.core.chain.retract`) and the
dense LU of the fallback tangent.
"""

import math

from cbha_inverse.core.se3 import JL_SERIES
import numba
import numpy as np

# c(t) = sum_k a_k t^(2k), the hat(phi)^2 coefficient of Jl^-1: the first 7 terms of the se3
# series (truncation below round-off up to _SERIES_LIMIT)
_JL_SERIES = np.array(JL_SERIES[:7])
_SERIES_LIMIT = 0.5


@numba.njit(cache=True)
def jl_coefficient(theta):
    """
    Return ``c(t)`` and ``c'(t)/t`` of ``Jl⁻¹(φ) = I - φ^/2 + c φ^²`` (as in ``se3``).

    ``c(t) = 1/t² - cot(t/2) / (2t)``; below 0.5 rad both from the Taylor series in ``t²``
    (7 terms, Horner), where the closed forms cancel.

    Parameters
    ----------
    theta : float  [rad]
        Angle ``t = |φ|``.

    Returns
    -------
    c, dc_over_t : float

    """
    if theta < _SERIES_LIMIT:
        t2 = theta * theta
        n = _JL_SERIES.size
        c = _JL_SERIES[n - 1]
        dc = 2.0 * (n - 1) * _JL_SERIES[n - 1]
        for k in range(n - 2, -1, -1):
            c = c * t2 + _JL_SERIES[k]
            if k > 0:
                dc = dc * t2 + 2.0 * k * _JL_SERIES[k]
        return c, dc
    half = 0.5 * theta
    sin_half = math.sin(half)
    cot = math.cos(half) / sin_half
    c = 1.0 / (theta * theta) - cot / (2.0 * theta)
    dc = (-2.0 / theta ** 3 + 1.0 / (4.0 * theta * sin_half * sin_half)
          + cot / (2.0 * theta * theta)) / theta
    return c, dc


@numba.njit(cache=True)
def rotation_log(rot, out):
    """
    Write the rotation vector of a rotation matrix into ``out`` and return its angle.

    As :func:`cbha_inverse.core.se3.so3_log`: ``t = atan2(|vee(R)|, (tr R - 1) / 2)`` while
    ``tr R > -0.5``, otherwise through the (Shepperd) quaternion, accurate up to pi.

    Parameters
    ----------
    rot : (3, 3) ndarray
        Rotation matrix.
    out : (3,) ndarray
        Receives ``φ`` [rad].

    Returns
    -------
    float
        ``t = |φ|`` [rad], in [0, pi].

    """
    d0 = 0.5 * (rot[2, 1] - rot[1, 2])
    d1 = 0.5 * (rot[0, 2] - rot[2, 0])
    d2 = 0.5 * (rot[1, 0] - rot[0, 1])
    trace = rot[0, 0] + rot[1, 1] + rot[2, 2]
    cos_t = 0.5 * trace - 0.5
    if cos_t > -0.75:
        sin_t = math.sqrt(d0 * d0 + d1 * d1 + d2 * d2)
        theta = math.atan2(sin_t, cos_t)
        # sin_t = 0 only for d = 0, where any finite ratio gives the zero vector
        ratio = theta / max(sin_t, 1e-300)
        out[0], out[1], out[2] = d0 * ratio, d1 * ratio, d2 * ratio
        return theta
    # Shepperd: the largest of (tr, R00, R11, R22) picks the accurate formula; here w < 0.5
    if rot[0, 0] >= rot[1, 1] and rot[0, 0] >= rot[2, 2]:
        s = math.sqrt(max(1.0 + 2.0 * rot[0, 0] - trace, 1e-300))
        x, y, z, w = 0.5 * s, (rot[0, 1] + rot[1, 0]) / (2.0 * s), (
            rot[0, 2] + rot[2, 0]) / (2.0 * s), d0 / s
    elif rot[1, 1] >= rot[2, 2]:
        s = math.sqrt(max(1.0 + 2.0 * rot[1, 1] - trace, 1e-300))
        x, y, z, w = (rot[0, 1] + rot[1, 0]) / (2.0 * s), 0.5 * s, (
            rot[1, 2] + rot[2, 1]) / (2.0 * s), d1 / s
    else:
        s = math.sqrt(max(1.0 + 2.0 * rot[2, 2] - trace, 1e-300))
        x, y, z, w = (rot[0, 2] + rot[2, 0]) / (2.0 * s), (rot[1, 2] + rot[2, 1]) / (
            2.0 * s), 0.5 * s, d2 / s
    if w < 0.0:
        x, y, z, w = -x, -y, -z, -w
    v = math.sqrt(x * x + y * y + z * z)
    theta = 2.0 * math.atan2(v, w)
    ratio = theta / v
    out[0], out[1], out[2] = x * ratio, y * ratio, z * ratio
    return theta


@numba.njit(cache=True)
def rotation_exp(rotvec, out):
    """
    Write ``exp(hat(v))`` into ``out`` (Rodrigues: ``I + a v^ + b v^²``).

    ``a = sin t / t`` and ``b = (1 - cos t) / t²``; below 1e-4 rad from their Taylor series.

    Parameters
    ----------
    rotvec : (3,) ndarray  [rad]
        Axis times angle.
    out : (3, 3) ndarray
        Receives the rotation.

    """
    x, y, z = rotvec[0], rotvec[1], rotvec[2]
    t2 = x * x + y * y + z * z
    if t2 < 1e-8:
        a = 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0)
        b = 0.5 - t2 / 24.0 * (1.0 - t2 / 30.0)
    else:
        t = math.sqrt(t2)
        a = math.sin(t) / t
        b = (1.0 - math.cos(t)) / t2
    cos_t = 1.0 - b * t2
    out[0, 0] = cos_t + b * x * x
    out[1, 1] = cos_t + b * y * y
    out[2, 2] = cos_t + b * z * z
    out[0, 1] = b * x * y - a * z
    out[1, 0] = b * x * y + a * z
    out[0, 2] = b * x * z + a * y
    out[2, 0] = b * x * z - a * y
    out[1, 2] = b * y * z - a * x
    out[2, 1] = b * y * z + a * x


@numba.njit(cache=True)
def _retract_into(positions, rotations, increments, max_rotation):
    """Apply the increments to frames 1..n in place (see :func:`retract_frames`)."""
    largest = 0.0
    for f in range(increments.shape[0]):
        largest = max(largest, increments[f, 3] ** 2 + increments[f, 4] ** 2
                      + increments[f, 5] ** 2)
    largest = math.sqrt(largest)
    factor = max_rotation / largest if largest > max_rotation else 1.0
    step = np.empty(3)
    rot = np.empty((3, 3))
    old = np.empty((3, 3))
    for f in range(increments.shape[0]):
        for i in range(3):
            positions[f + 1, i] += factor * increments[f, i]
            step[i] = factor * increments[f, 3 + i]
        rotation_exp(step, rot)
        old[:, :] = rotations[f + 1]
        for i in range(3):
            for j in range(3):
                rotations[f + 1, i, j] = (rot[i, 0] * old[0, j] + rot[i, 1] * old[1, j]
                                          + rot[i, 2] * old[2, j])


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
    size, m = solved_actuators.shape
    increments = np.empty((size // 6, 6))
    for row in range(size):
        acc = free_step[row]
        for j in range(m):
            acc += solved_actuators[row, j] * change[j]
        increments[row // 6, row % 6] = acc
    _retract_into(positions, rotations, increments, max_rotation)


@numba.njit(cache=True)
def deformation_step(positions, rotations, rest_rotations, step, coordinates):
    """
    Map world increments of frames 1..n to increments of the links' deformation coordinates.

    The coordinates of link ``l`` (frames ``a = l``, ``b = l + 1``) are its offset
    ``u = R_aᵀ (x_b - x_a)`` and rotation vector ``φ = log(R_aᵀ R_b Q0ᵀ)``; their increments
    linearise the link deformation (DESIGN §3)::

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
        # Jl^-1 = (1 - c t^2) I + c phi phi^T - hat(phi) / 2
        dot = phi[0] * local[0] + phi[1] * local[1] + phi[2] * local[2]
        cross = (phi[1] * local[2] - phi[2] * local[1], phi[2] * local[0] - phi[0] * local[2],
                 phi[0] * local[1] - phi[1] * local[0])
        size = 0.0
        for i in range(3):
            value = (1.0 - c * theta * theta) * local[i] + c * phi[i] * dot - 0.5 * cross[i]
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
    Apply world-axis increments to frames 1..n (as :func:`cbha_inverse.core.chain.retract`).

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
    _retract_into(positions, rotations, np.ascontiguousarray(increments, dtype=float),
                  math.inf if max_rotation is None else float(max_rotation))
    return positions, rotations
