"""
Rotation helpers on SO(3): hat/vee, exponential and logarithm, quaternions, Jacobians.

Conventions (DESIGN §2): rotation vectors are axis * angle [rad]; quaternions are (x, y, z, w);
every function is batched over leading axes (``(..., 3)`` vectors, ``(..., 3, 3)`` matrices).
Rotation increments are applied on the left in world axes, ``R <- so3_exp(dtheta) @ R``, so the
Jacobians used by the mechanics are the *left* Jacobians of SO(3).

The small-angle branches use Taylor series below ``_SMALL_ANGLE`` rad, where the closed forms
lose digits to cancellation; :func:`so3_log` goes through a (Shepperd) quaternion, which is
accurate at every angle including near pi.
"""

import numpy as np

_SMALL_ANGLE = 0.1


def hat(v):
    """
    Return the skew-symmetric matrix of a 3-vector (``hat_a @ b`` is ``a x b``).

    Parameters
    ----------
    v : (..., 3) array_like
        Vectors.

    Returns
    -------
    (..., 3, 3) ndarray

    """
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1] = -v[..., 2]
    out[..., 0, 2] = v[..., 1]
    out[..., 1, 0] = v[..., 2]
    out[..., 1, 2] = -v[..., 0]
    out[..., 2, 0] = -v[..., 1]
    out[..., 2, 1] = v[..., 0]
    return out


def vee(m):
    """
    Inverse of :func:`hat` (uses the skew-symmetric part of ``m``).

    Parameters
    ----------
    m : (..., 3, 3) array_like
        Matrices.

    Returns
    -------
    (..., 3) ndarray

    """
    m = np.asarray(m, dtype=float)
    return 0.5 * np.stack([m[..., 2, 1] - m[..., 1, 2],
                           m[..., 0, 2] - m[..., 2, 0],
                           m[..., 1, 0] - m[..., 0, 1]], axis=-1)


def _angle_coefficients(theta):
    """Return ``sin(t)/t`` and ``(1 - cos(t))/t**2`` with Taylor series near zero."""
    t2 = theta * theta
    small = theta < _SMALL_ANGLE
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - t2 / 6.0 * (1.0 - t2 / 20.0 * (1.0 - t2 / 42.0)),
                 np.sin(safe) / safe)
    b = np.where(small, 0.5 - t2 / 24.0 * (1.0 - t2 / 30.0 * (1.0 - t2 / 56.0)),
                 (1.0 - np.cos(safe)) / (safe * safe))
    return a, b


def so3_exp(rotvec):
    """
    Rotation matrix of a rotation vector (Rodrigues' formula).

    Parameters
    ----------
    rotvec : (..., 3) array_like  [rad]
        Axis times angle.

    Returns
    -------
    (..., 3, 3) ndarray

    """
    rotvec = np.asarray(rotvec, dtype=float)
    theta = np.linalg.norm(rotvec, axis=-1)
    a, b = _angle_coefficients(theta)
    k = hat(rotvec)
    out = a[..., None, None] * k + b[..., None, None] * (k @ k)
    out[..., 0, 0] += 1.0
    out[..., 1, 1] += 1.0
    out[..., 2, 2] += 1.0
    return out


def quat_from_matrix(rot):
    """
    Return the unit quaternion (x, y, z, w) of a rotation matrix, with w >= 0 (Shepperd's method).

    Parameters
    ----------
    rot : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    (..., 4) ndarray

    """
    rot = np.asarray(rot, dtype=float)
    r00, r11, r22 = rot[..., 0, 0], rot[..., 1, 1], rot[..., 2, 2]
    trace = r00 + r11 + r22
    # Four algebraically equal formulas; each is accurate when its pivot is the largest.
    pivots = np.stack([trace, r00, r11, r22], axis=-1)
    choice = np.argmax(pivots, axis=-1)
    p = np.maximum(1.0 + 2.0 * np.take_along_axis(pivots, choice[..., None], -1)[..., 0]
                   - trace, 1e-300)
    s = np.sqrt(p)
    d21 = rot[..., 2, 1] - rot[..., 1, 2]
    d02 = rot[..., 0, 2] - rot[..., 2, 0]
    d10 = rot[..., 1, 0] - rot[..., 0, 1]
    s01 = rot[..., 0, 1] + rot[..., 1, 0]
    s02 = rot[..., 0, 2] + rot[..., 2, 0]
    s12 = rot[..., 1, 2] + rot[..., 2, 1]
    half = 0.5 * s
    inv = 0.5 / s
    candidates = np.stack([
        np.stack([d21 * inv, d02 * inv, d10 * inv, half], axis=-1),
        np.stack([half, s01 * inv, s02 * inv, d21 * inv], axis=-1),
        np.stack([s01 * inv, half, s12 * inv, d02 * inv], axis=-1),
        np.stack([s02 * inv, s12 * inv, half, d10 * inv], axis=-1),
    ], axis=-2)
    q = np.take_along_axis(candidates, choice[..., None, None], -2)[..., 0, :]
    q = np.where(q[..., 3:4] < 0.0, -q, q)
    return q / np.linalg.norm(q, axis=-1, keepdims=True)


def matrix_from_quat(quat):
    """
    Rotation matrix of a quaternion (x, y, z, w); the quaternion is normalised first.

    Parameters
    ----------
    quat : (..., 4) array_like
        Quaternions (x, y, z, w).

    Returns
    -------
    (..., 3, 3) ndarray

    """
    q = np.asarray(quat, dtype=float)
    q = q / np.linalg.norm(q, axis=-1, keepdims=True)
    x, y, z, w = q[..., 0], q[..., 1], q[..., 2], q[..., 3]
    return np.stack([
        np.stack([1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)], -1),
        np.stack([2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)], -1),
        np.stack([2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)], -1),
    ], axis=-2)


def so3_log(rot):
    """
    Rotation vector of a rotation matrix, angle in [0, pi].

    Computed from the quaternion, ``theta = 2 atan2(|v|, w)``, which keeps full accuracy for
    small angles and near pi (where the axis is recovered from the symmetric part).

    Parameters
    ----------
    rot : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    (..., 3) ndarray  [rad]

    """
    q = quat_from_matrix(rot)
    v = q[..., :3]
    w = q[..., 3]
    s = np.linalg.norm(v, axis=-1)
    small = s < 1e-8
    safe_s = np.where(small, 1.0, s)
    safe_w = np.where(small, w, 1.0)
    scale = np.where(small, 2.0 / safe_w * (1.0 - s * s / (3.0 * safe_w * safe_w)),
                     2.0 * np.arctan2(s, w) / safe_s)
    return v * scale[..., None]


def _jl_inv_coefficient(theta):
    """
    Return ``c(t) = 1/t**2 - (1 + cos t) / (2 t sin t)`` and ``c'(t) / t``.

    ``c`` is the coefficient of ``hat(phi)**2`` in the inverse left Jacobian of SO(3).
    """
    t2 = theta * theta
    small = theta < _SMALL_ANGLE
    # c' has a 1/t**4 cancellation: its series is used up to a larger angle (error < 1e-11).
    small_d = theta < 0.5
    t = np.where(small_d, 1.0, theta)
    half = 0.5 * t
    cot = np.cos(half) / np.sin(half)
    csc2 = 1.0 / np.sin(half) ** 2
    dc_closed = (-2.0 / t ** 3 + csc2 / (4.0 * t) + cot / (2.0 * t * t)) / t
    t_c = np.where(small, 1.0, theta)
    c_closed = 1.0 / (t_c * t_c) - np.cos(0.5 * t_c) / np.sin(0.5 * t_c) / (2.0 * t_c)
    c_series = 1.0 / 12.0 + t2 / 720.0 + t2 * t2 / 30240.0 + t2 ** 3 / 1209600.0
    dc_series = (1.0 / 360.0 + t2 / 7560.0 + t2 * t2 / 201600.0 + t2 ** 3 / 5987520.0
                 + t2 ** 4 * (1382.0 / 261534873600.0))
    return np.where(small, c_series, c_closed), np.where(small_d, dc_series, dc_closed)


def so3_left_jacobian_inverse(rotvec):
    """
    Inverse left Jacobian of SO(3): ``log(exp(e) exp(phi)) = phi + Jl^-1(phi) e + O(e^2)``.

    ``Jl^-1(phi) = I - hat(phi)/2 + c(|phi|) hat(phi)^2`` (valid for |phi| < 2 pi).

    Parameters
    ----------
    rotvec : (..., 3) array_like  [rad]
        Rotation vectors phi.

    Returns
    -------
    (..., 3, 3) ndarray

    """
    rotvec = np.asarray(rotvec, dtype=float)
    c, _ = _jl_inv_coefficient(np.linalg.norm(rotvec, axis=-1))
    k = hat(rotvec)
    out = -0.5 * k + c[..., None, None] * (k @ k)
    out[..., 0, 0] += 1.0
    out[..., 1, 1] += 1.0
    out[..., 2, 2] += 1.0
    return out


def so3_left_jacobian_inverse_transpose_derivative(rotvec, vec):
    """
    Differentiate ``Jl^-1(phi)^T s`` with respect to ``phi`` for fixed ``s``.

    With ``Jl^-1(phi)^T s = s + phi x s / 2 + c(t) (phi (phi . s) - t^2 s)``, ``t = |phi|``:
    ``d/dphi = -hat(s)/2 + (c'(t)/t) (phi (phi . s) - t^2 s) phi^T
    + c(t) ((phi . s) I + phi s^T - 2 s phi^T)``.

    Parameters
    ----------
    rotvec : (..., 3) array_like  [rad]
        Rotation vectors phi.
    vec : (..., 3) array_like
        Vectors s.

    Returns
    -------
    (..., 3, 3) ndarray

    """
    phi = np.asarray(rotvec, dtype=float)
    s = np.asarray(vec, dtype=float)
    t2 = np.sum(phi * phi, axis=-1)
    c, dc = _jl_inv_coefficient(np.sqrt(t2))
    ps = np.sum(phi * s, axis=-1)
    a = phi * ps[..., None] - t2[..., None] * s
    out = -0.5 * hat(s)
    out += dc[..., None, None] * (a[..., :, None] * phi[..., None, :])
    out += c[..., None, None] * (phi[..., :, None] * s[..., None, :]
                                 - 2.0 * s[..., :, None] * phi[..., None, :])
    diag = (c * ps)[..., None]
    out[..., 0, 0] += diag[..., 0]
    out[..., 1, 1] += diag[..., 0]
    out[..., 2, 2] += diag[..., 0]
    return out
