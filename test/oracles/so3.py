"""
SO(3) in batched numpy (oracle): hat/vee, exponential and logarithm, quaternions, Jacobians.

The readable reference of the compiled maps of :mod:`cbha_inverse.core._kernels.so3` (which
:mod:`cbha_inverse.core.so3` serves batched): written independently (matrix products, ``sinc``
forms, its own series of ``c(t)`` with up to 10 terms below 1 rad), so the tests compare two
implementations.

Conventions (`docs/design.md`): rotation vectors are axis * angle [rad]; quaternions are
(x, y, z, w); every function is batched over leading axes (``(..., 3)`` vectors,
``(..., 3, 3)`` matrices). Rotation increments are applied on the left in world axes,
``R <- so3_exp(dtheta) @ R``, so the Jacobians used by the mechanics are the *left* Jacobians of
SO(3).

Where closed forms lose digits to cancellation, ``sinc`` forms or Taylor series are used;
:func:`so3_log` reads the angle with ``atan2`` and, beyond 2.4 rad, goes through a (Shepperd)
quaternion, which stays accurate up to pi.
"""

import numpy as np

_SERIES_ANGLE = 1.0
#: ``|B_(2k+2)| / (2k+2)!``, k = 0..9: Taylor coefficients of ``c(t)`` in ``t**2``, the
#: ``hat(phi)**2`` coefficient of the inverse left Jacobian (see :func:`_jl_inv_coefficient`)
JL_SERIES = (1.0 / 12.0, 1.0 / 720.0, 1.0 / 30240.0, 1.0 / 1209600.0, 1.0 / 47900160.0,
             691.0 / (2730.0 * 479001600.0), 7.0 / (6.0 * 87178291200.0),
             3617.0 / (510.0 * 20922789888000.0), 43867.0 / (798.0 * 6402373705728000.0),
             174611.0 / (330.0 * 2432902008176640000.0))
_EYE3 = np.eye(3)
#: flattened ``R @ LOG_BASIS = (vee(R), tr(R) / 2)`` (9 x 4)
LOG_BASIS = np.zeros((9, 4))
LOG_BASIS[[7, 2, 3], [0, 1, 2]] = 0.5
LOG_BASIS[[5, 6, 1], [0, 1, 2]] = -0.5
LOG_BASIS[[0, 4, 8], 3] = 0.5
#: ``hat(v) = v @ HAT_BASIS`` reshaped to 3x3 (one matmul instead of six scattered writes)
HAT_BASIS = np.array([[0, 0, 0, 0, 0, -1, 0, 1, 0],
                      [0, 0, 1, 0, 0, 0, -1, 0, 0],
                      [0, -1, 0, 1, 0, 0, 0, 0, 0]], dtype=float)


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
    return (v @ HAT_BASIS).reshape(v.shape[:-1] + (3, 3))


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
    """Return ``sin(t)/t`` and ``(1 - cos(t))/t**2 = sinc(t/2)**2 / 2`` without cancellation."""
    a = np.sinc(theta * (1.0 / np.pi))
    b = np.sinc(theta * (0.5 / np.pi))
    return a, 0.5 * b * b


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
    Return the rotation vector of a rotation matrix, angle in [0, pi].

    ``theta = atan2(|vee(R)|, (tr R - 1) / 2)`` and ``phi = vee(R) theta / sin(theta)`` while
    ``tr R > -0.5`` (theta < 2.4 rad) for every input; otherwise through the quaternion,
    ``theta = 2 atan2(|v|, w)``, which keeps full accuracy near pi.

    Parameters
    ----------
    rot : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    (..., 3) ndarray  [rad]

    """
    return so3_log_angle(rot)[0]


def so3_log_angle(rot):
    """
    Return the rotation vectors and angles of rotation matrices (see :func:`so3_log`).

    Parameters
    ----------
    rot : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    rotvec : (..., 3) ndarray  [rad]
        Rotation vectors.
    angle : (...,) ndarray  [rad]
        Their norms, in [0, pi].

    """
    rot = np.asarray(rot, dtype=float)
    # one product gives vee(R) = sin(t) axis and (tr R) / 2 = cos(t) + 1/2
    mixed = rot.reshape(rot.shape[:-2] + (9,)) @ LOG_BASIS
    cos_t = mixed[..., 3] - 0.5
    if cos_t.size and cos_t.min() > -0.75:
        d = mixed[..., :3]
        sin_t = np.sqrt((d * d).sum(axis=-1))
        theta = np.arctan2(sin_t, cos_t)
        # sin_t = 0 only for d = 0, where any finite ratio gives the zero vector
        return d * (theta / np.maximum(sin_t, 1e-300))[..., None], theta
    q = quat_from_matrix(rot)
    v = q[..., :3]
    w = q[..., 3]
    s = np.linalg.norm(v, axis=-1)
    small = s < 1e-8
    safe_s = np.where(small, 1.0, s)
    safe_w = np.where(small, w, 1.0)
    scale = np.where(small, 2.0 / safe_w * (1.0 - s * s / (3.0 * safe_w * safe_w)),
                     2.0 * np.arctan2(s, w) / safe_s)
    return v * scale[..., None], 2.0 * np.arctan2(s, w)


def _jl_inv_coefficient(theta):
    """
    Return ``c(t) = 1/t**2 - (1 + cos t) / (2 t sin t)`` and ``c'(t) / t``.

    ``c`` is the coefficient of ``hat(phi)**2`` in the inverse left Jacobian of SO(3). Below
    ``_SERIES_ANGLE`` both come from ``c = sum_k |B_(2k+2)| / (2k+2)! t**(2k)`` (Bernoulli numbers;
    truncation < 1e-13 relative), where the closed forms cancel (``c'`` like ``1/t**4``).
    """
    theta = np.asarray(theta, dtype=float)
    t2 = theta * theta
    t_max = float(theta.max()) if theta.size else 0.0
    # number of series terms: the first neglected term of c'/t is below 1e-17 of its value
    terms = len(JL_SERIES)
    while terms > 2 and 2.0 * (terms - 1) * JL_SERIES[terms - 1] * min(
            t_max, _SERIES_ANGLE) ** (2 * terms - 4) < 1e-17 / 360.0:
        terms -= 1
    c = np.full_like(t2, JL_SERIES[terms - 1])
    dc = np.full_like(t2, 2.0 * (terms - 1) * JL_SERIES[terms - 1])
    for k in range(terms - 2, -1, -1):
        c = c * t2 + JL_SERIES[k]
        if k > 0:
            dc = dc * t2 + 2.0 * k * JL_SERIES[k]
    if theta.size == 0 or theta.max() < _SERIES_ANGLE:
        return c, dc
    big = theta >= _SERIES_ANGLE
    t = np.where(big, theta, 1.0)
    half = 0.5 * t
    cot = np.cos(half) / np.sin(half)
    csc2 = 1.0 / np.sin(half) ** 2
    c_closed = 1.0 / (t * t) - cot / (2.0 * t)
    dc_closed = (-2.0 / t ** 3 + csc2 / (4.0 * t) + cot / (2.0 * t * t)) / t
    return np.where(big, c_closed, c), np.where(big, dc_closed, dc)


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
    c, _ = _jl_inv_coefficient(np.sqrt(np.sum(rotvec * rotvec, axis=-1)))
    return _jl_inv_from_hat(hat(rotvec), c)


def _jl_inv_from_hat(phi_hat, c):
    """``Jl^-1 = I - hat(phi)/2 + c hat(phi)^2`` from ``hat(phi)`` and ``c(|phi|)``."""
    out = c[..., None, None] * (phi_hat @ phi_hat) - 0.5 * phi_hat
    out += _EYE3
    return out


def so3_left_jacobian_inverse_transpose_derivative(rotvec, vec, coefficients=None):
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
    coefficients : tuple of two (...,) ndarrays, optional
        ``(c(t), c'(t)/t)`` if already computed.

    Returns
    -------
    (..., 3, 3) ndarray

    """
    phi = np.asarray(rotvec, dtype=float)
    s = np.asarray(vec, dtype=float)
    t2 = np.sum(phi * phi, axis=-1)
    c, dc = _jl_inv_coefficient(np.sqrt(t2)) if coefficients is None else coefficients
    ps = np.sum(phi * s, axis=-1)
    a = dc[..., None] * (phi * ps[..., None] - t2[..., None] * s) - 2.0 * c[..., None] * s
    out = a[..., :, None] * phi[..., None, :]
    out += (c[..., None] * phi)[..., :, None] * s[..., None, :]
    out -= 0.5 * hat(s)
    out += (c * ps)[..., None, None] * _EYE3
    return out
