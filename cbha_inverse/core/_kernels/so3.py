"""
Compiled SO(3) maps: exponential, logarithm, quaternion, ``Jl⁻¹`` and ``hat``.

The scalar (per-rotation) forms are called inside every kernel; the ``*_batch`` forms loop them
over arrays for :mod:`cbha_inverse.core.so3`, the package's batched SO(3) API, so each map has
this one implementation. Rotation vectors are axis * angle [rad], quaternions (x, y, z, w) with
``w >= 0``; increments act on the left in world axes, so ``Jl`` is the *left* Jacobian.
"""

import math

import numba
import numpy as np

#: ``|B_(2k+2)| / (2k+2)!``, k = 0..6 (Bernoulli numbers): the Taylor coefficients of ``c(t)`` in
#: ``t**2``, the ``hat(φ)**2`` coefficient of ``Jl⁻¹`` (truncation below round-off up to
#: ``_SERIES_LIMIT``)
JL_SERIES = np.array([1.0 / 12.0, 1.0 / 720.0, 1.0 / 30240.0, 1.0 / 1209600.0,
                      1.0 / 47900160.0, 691.0 / (2730.0 * 479001600.0),
                      7.0 / (6.0 * 87178291200.0)])
_SERIES_LIMIT = 0.5


@numba.njit(cache=True)
def jl_coefficient(theta):
    """
    Return ``c(t)`` and ``c'(t)/t`` of ``Jl⁻¹(φ) = I - φ^/2 + c φ^²``.

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
        n = JL_SERIES.size
        c = JL_SERIES[n - 1]
        dc = 2.0 * (n - 1) * JL_SERIES[n - 1]
        for k in range(n - 2, -1, -1):
            c = c * t2 + JL_SERIES[k]
            if k > 0:
                dc = dc * t2 + 2.0 * k * JL_SERIES[k]
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

    ``t = atan2(|vee(R)|, (tr R - 1) / 2)`` while ``tr R > -0.5`` (t < 2.4 rad), otherwise
    ``t = 2 atan2(|v|, w)`` through the quaternion (:func:`quaternion_into`), accurate up to pi.

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
    theta, out[0], out[1], out[2] = rotation_log_scalars(rot)
    return theta


@numba.njit(cache=True, inline='always')
def rotation_log_scalars(rot):
    """Return ``t`` and the three components of ``φ`` of :func:`rotation_log`, as floats."""
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
        return theta, d0 * ratio, d1 * ratio, d2 * ratio
    x, y, z, w = _quaternion(rot)
    v = math.sqrt(x * x + y * y + z * z)
    theta = 2.0 * math.atan2(v, w)
    ratio = theta / v
    return theta, x * ratio, y * ratio, z * ratio


@numba.njit(cache=True)
def rotation_exp(rotvec, out):
    """
    Write ``exp(hat(v))`` into ``out`` (Rodrigues: ``I + a v^ + b v^²``).

    ``a = sin t / t`` and ``b = (1 - cos t) / t²``; below 1e-4 rad from their Taylor series
    (:func:`rotation_exp_entries`).

    Parameters
    ----------
    rotvec : (3,) ndarray  [rad]
        Axis times angle.
    out : (3, 3) ndarray
        Receives the rotation.

    """
    (out[0, 0], out[0, 1], out[0, 2], out[1, 0], out[1, 1], out[1, 2], out[2, 0], out[2, 1],
     out[2, 2]) = rotation_exp_entries(rotvec[0], rotvec[1], rotvec[2])


@numba.njit(cache=True)
def rotation_exp_entries(x, y, z):
    """
    Return the entries of ``exp(hat(v))``, row by row, for ``v = (x, y, z)`` [rad].

    The arithmetic of :func:`rotation_exp`, returned as scalars: a caller that multiplies by the
    rotation at once keeps them in registers instead of a (3, 3) workspace
    (:func:`cbha_inverse.core._kernels.retraction.retract_in_place`).

    Returns
    -------
    r00, r01, r02, r10, r11, r12, r20, r21, r22 : float
        ``exp(hat(v))[i, j]`` in C order.

    """
    t2 = x * x + y * y + z * z
    if t2 < 1e-8:
        a = 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0)
        b = 0.5 - t2 / 24.0 * (1.0 - t2 / 30.0)
    else:
        t = math.sqrt(t2)
        a = math.sin(t) / t
        b = (1.0 - math.cos(t)) / t2
    cos_t = 1.0 - b * t2
    return (cos_t + b * x * x, b * x * y - a * z, b * x * z + a * y,
            b * x * y + a * z, cos_t + b * y * y, b * y * z - a * x,
            b * x * z - a * y, b * y * z + a * x, cos_t + b * z * z)


@numba.njit(cache=True, inline='always')
def hat_into(v, out):
    """Write ``hat(v)`` (``hat(v) @ b = v x b``) into a (3, 3) array."""
    out[0, 0] = out[1, 1] = out[2, 2] = 0.0
    out[0, 1], out[0, 2] = -v[2], v[1]
    out[1, 0], out[1, 2] = v[2], -v[0]
    out[2, 0], out[2, 1] = -v[1], v[0]


@numba.njit(cache=True, inline='always')
def add_scaled_hat(out, r0, c0, v0, v1, v2, weight):
    """
    Add ``weight * hat(v)`` to the 3 x 3 block of ``out`` at ``(r0, c0)`` (its diagonal is 0).

    Parameters
    ----------
    out : (p, q) ndarray
        Added to.
    r0, c0 : int
        The block's corner.
    v0, v1, v2 : float
        ``v``.
    weight : float
        The factor.

    """
    out[r0, c0 + 1] -= weight * v2
    out[r0 + 1, c0] += weight * v2
    out[r0, c0 + 2] += weight * v1
    out[r0 + 2, c0] -= weight * v1
    out[r0 + 1, c0 + 2] -= weight * v0
    out[r0 + 2, c0 + 1] += weight * v0


@numba.njit(cache=True)
def quaternion_into(rot, out):
    """
    Write the unit quaternion (x, y, z, w), ``w >= 0``, of a rotation matrix (Shepperd).

    The largest of ``(tr R, R00, R11, R22)`` picks the one of four algebraically equal formulas
    that is accurate; the result is normalised.

    Parameters
    ----------
    rot : (3, 3) ndarray
        Rotation matrix.
    out : (4,) ndarray
        Receives ``(x, y, z, w)``.

    """
    out[0], out[1], out[2], out[3] = _quaternion(rot)


@numba.njit(cache=True, inline='always')
def _quaternion(rot):
    """
    Return the quaternion of :func:`quaternion_into` as four floats.

    Scalars, not an array: :func:`rotation_log` (inside every link pass) needs no workspace.
    """
    trace = rot[0, 0] + rot[1, 1] + rot[2, 2]
    d21, d02, d10 = rot[2, 1] - rot[1, 2], rot[0, 2] - rot[2, 0], rot[1, 0] - rot[0, 1]
    s01, s02, s12 = rot[0, 1] + rot[1, 0], rot[0, 2] + rot[2, 0], rot[1, 2] + rot[2, 1]
    pivot = max(trace, rot[0, 0], rot[1, 1], rot[2, 2])
    s = math.sqrt(max(1.0 + 2.0 * pivot - trace, 1e-300))
    half, inv = 0.5 * s, 0.5 / s
    if pivot == trace:
        x, y, z, w = d21 * inv, d02 * inv, d10 * inv, half
    elif pivot == rot[0, 0]:
        x, y, z, w = half, s01 * inv, s02 * inv, d21 * inv
    elif pivot == rot[1, 1]:
        x, y, z, w = s01 * inv, half, s12 * inv, d02 * inv
    else:
        x, y, z, w = s02 * inv, s12 * inv, half, d10 * inv
    norm = math.sqrt(x * x + y * y + z * z + w * w)
    if w < 0.0:
        norm = -norm
    return x / norm, y / norm, z / norm, w / norm


@numba.njit(cache=True, inline='always')
def left_jacobian_inverse_into(phi, theta, c, out):
    """
    Write ``Jl⁻¹(φ) = I - φ^/2 + c φ^² = (1 - c t²) I + c φ φᵀ - φ^/2`` into ``out``.

    ``log(exp(e) exp(φ)) = φ + Jl⁻¹(φ) e + O(e²)``, valid for ``t = |φ| < 2 pi``.

    Parameters
    ----------
    phi : (3,) ndarray  [rad]
        Rotation vector.
    theta : float  [rad]
        ``|φ|``.
    c : float
        ``c(t)`` of :func:`jl_coefficient`.
    out : (3, 3) ndarray
        Receives the matrix.

    """
    for i in range(3):
        for j in range(3):
            out[i, j] = c * phi[i] * phi[j]
        out[i, i] += 1.0 - c * theta * theta
    add_scaled_hat(out, 0, 0, phi[0], phi[1], phi[2], -0.5)


@numba.njit(cache=True)
def hat_batch(vectors):
    """Return ``hat(v)`` of (N, 3) vectors as (N, 3, 3) (see :func:`hat_into`)."""
    out = np.empty((vectors.shape[0], 3, 3))
    for k in range(vectors.shape[0]):
        hat_into(vectors[k], out[k])
    return out


@numba.njit(cache=True)
def exp_batch(rotvecs):
    """Return ``exp(hat(v))`` of (N, 3) rotation vectors as (N, 3, 3) (:func:`rotation_exp`)."""
    out = np.empty((rotvecs.shape[0], 3, 3))
    for k in range(rotvecs.shape[0]):
        rotation_exp(rotvecs[k], out[k])
    return out


@numba.njit(cache=True)
def log_batch(rotations):
    """Return rotation vectors (N, 3) and angles (N,) of rotations (N, 3, 3) (rotation_log)."""
    vectors = np.empty((rotations.shape[0], 3))
    angles = np.empty(rotations.shape[0])
    for k in range(rotations.shape[0]):
        angles[k] = rotation_log(rotations[k], vectors[k])
    return vectors, angles


@numba.njit(cache=True)
def quaternion_batch(rotations):
    """Return the quaternions (N, 4) of (N, 3, 3) rotations (:func:`quaternion_into`)."""
    out = np.empty((rotations.shape[0], 4))
    for k in range(rotations.shape[0]):
        quaternion_into(rotations[k], out[k])
    return out


@numba.njit(cache=True)
def jl_coefficient_batch(angles):
    """Return ``c(t)`` and ``c'(t)/t`` (N,) of (N,) angles (:func:`jl_coefficient`)."""
    c = np.empty(angles.shape[0])
    dc = np.empty(angles.shape[0])
    for k in range(angles.shape[0]):
        c[k], dc[k] = jl_coefficient(angles[k])
    return c, dc


@numba.njit(cache=True)
def left_jacobian_inverse_batch(rotvecs):
    """Return ``Jl⁻¹(φ)`` (N, 3, 3) of (N, 3) rotation vectors."""
    out = np.empty((rotvecs.shape[0], 3, 3))
    for k in range(rotvecs.shape[0]):
        phi = rotvecs[k]
        theta = math.sqrt(phi[0] * phi[0] + phi[1] * phi[1] + phi[2] * phi[2])
        c, _ = jl_coefficient(theta)
        left_jacobian_inverse_into(phi, theta, c, out[k])
    return out
