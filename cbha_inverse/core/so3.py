"""
Rotation helpers on SO(3), batched: hat/vee, exp/log, quaternions, poses, rpy, ``Jl⁻¹``.

Conventions (`docs/design.md`): rotation vectors are axis * angle [rad]; quaternions are
(x, y, z, w) with ``w >= 0``; every function is batched over leading axes (``(..., 3)`` vectors,
``(..., 3, 3)`` matrices). Rotation increments are applied on the left in world axes,
``R <- so3_exp(dtheta) @ R``, so the Jacobians used by the mechanics are the *left* Jacobians.

The maps with a compiled form run it (:mod:`cbha_inverse.core._kernels.so3`: one implementation
for the kernels and for the numpy callers): ``so3_log`` reads the angle with ``atan2`` and,
beyond 2.4 rad, goes through the (Shepperd) quaternion, which stays accurate up to pi; ``c(t)``
of ``Jl⁻¹`` comes from its Taylor series below 0.5 rad, where the closed form cancels.
"""

from cbha_inverse.core._kernels.so3 import (exp_batch, hat_batch, jl_coefficient_batch,
                                            left_jacobian_inverse_batch, log_batch,
                                            quaternion_batch)
import numpy as np


def _flat(array, item_shape):
    """Return ``array`` as a C-ordered float array of shape (N,) + item_shape and its batch."""
    array = np.asarray(array, dtype=float)
    batch = array.shape[:array.ndim - len(item_shape)]
    if array.shape[len(batch):] != item_shape:
        raise ValueError(f'expected shape (..., {", ".join(map(str, item_shape))}), '
                         f'got {array.shape}')
    return np.ascontiguousarray(array.reshape((-1,) + item_shape)), batch


def _batched(kernel, array, item_shape, out_shape):
    """Run a compiled batch ``kernel`` on the items of ``array``; return (batch + out_shape)."""
    flat, batch = _flat(array, item_shape)
    return kernel(flat).reshape(batch + out_shape)


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
    return _batched(hat_batch, v, (3,), (3, 3))


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


def cross(a, b):
    """
    Return the row-wise cross product ``a × b`` (faster than ``numpy.cross`` for small batches).

    Parameters
    ----------
    a, b : (..., 3) ndarray
        Vectors.

    Returns
    -------
    (..., 3) ndarray
        ``a × b``.

    """
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


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
    return _batched(exp_batch, rotvec, (3,), (3, 3))


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
    return _batched(quaternion_batch, rot, (3, 3), (4,))


def pose_vector(rotation, translation):
    """
    Pack rotations and translations into poses ``[x, y, z, qx, qy, qz, qw]``.

    Parameters
    ----------
    rotation : (..., 3, 3) array_like
        Rotation matrices.
    translation : (..., 3) array_like  [m]
        Translations (same leading shape).

    Returns
    -------
    (..., 7) ndarray
        The poses (quaternions of :func:`quat_from_matrix`, ``qw >= 0``).

    """
    translation = np.asarray(translation, dtype=float)
    return np.concatenate([translation, quat_from_matrix(np.asarray(rotation, dtype=float))],
                          axis=-1)


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


def so3_from_rpy(rpy):
    """
    Rotation matrix of roll, pitch, yaw angles (URDF / ROS convention).

    ``R = Rz(yaw) Ry(pitch) Rx(roll)``: roll about x, then pitch about y, then yaw about z, all
    about the fixed axes of the parent frame (as a URDF ``origin rpy`` or tf2's ``setRPY``).

    Parameters
    ----------
    rpy : (..., 3) array_like  [rad]
        (roll, pitch, yaw).

    Returns
    -------
    (..., 3, 3) ndarray

    """
    flat, batch = _flat(rpy, (3,))
    cr, cp, cy = np.cos(flat).T
    sr, sp, sy = np.sin(flat).T
    rot = np.stack([
        np.stack([cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr], -1),
        np.stack([sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr], -1),
        np.stack([-sp, cp * sr, cp * cr], -1),
    ], axis=-2)
    return rot.reshape(batch + (3, 3))


def rpy_from_so3(rot):
    """
    Return the roll, pitch, yaw angles of rotation matrices (inverse of :func:`so3_from_rpy`).

    Pitch lies in [-pi/2, pi/2], roll and yaw in (-pi, pi]. At pitch = +-pi/2 (gimbal lock, where
    only yaw -+ roll is defined) roll is set to 0; ``so3_from_rpy`` of the result is ``rot``
    whatever the pitch.

    Parameters
    ----------
    rot : (..., 3, 3) array_like
        Rotation matrices.

    Returns
    -------
    (..., 3) ndarray  [rad]
        (roll, pitch, yaw).

    """
    flat, batch = _flat(rot, (3, 3))
    cos_pitch = np.hypot(flat[:, 0, 0], flat[:, 1, 0])
    pitch = np.arctan2(-flat[:, 2, 0], cos_pitch)
    # below sqrt(eps) the roll read from (R21, R22) ~ cos(pitch) is noise: fold it into yaw
    locked = cos_pitch < 1e-8
    roll = np.where(locked, 0.0, np.arctan2(flat[:, 2, 1], flat[:, 2, 2]))
    yaw = np.where(locked, np.arctan2(-flat[:, 0, 1], flat[:, 1, 1]),
                   np.arctan2(flat[:, 1, 0], flat[:, 0, 0]))
    return np.stack([roll, pitch, yaw], axis=-1).reshape(batch + (3,))


def so3_log(rot):
    """
    Return the rotation vector of a rotation matrix, angle in [0, pi].

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
    flat, batch = _flat(rot, (3, 3))
    vectors, angles = log_batch(flat)
    return vectors.reshape(batch + (3,)), angles.reshape(batch)


def jl_inverse_coefficients(theta):
    """
    Return ``c(t) = 1/t**2 - (1 + cos t) / (2 t sin t)`` and ``c'(t) / t``.

    ``c`` is the coefficient of ``hat(phi)**2`` in the inverse left Jacobian of SO(3).

    Parameters
    ----------
    theta : (...,) array_like  [rad]
        Angles ``t``.

    Returns
    -------
    c, dc_over_t : (...,) ndarray

    """
    theta = np.asarray(theta, dtype=float)
    c, dc = jl_coefficient_batch(np.ascontiguousarray(theta.reshape(-1)))
    return c.reshape(theta.shape), dc.reshape(theta.shape)


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
    return _batched(left_jacobian_inverse_batch, rotvec, (3,), (3, 3))


def shortest_rotation(a, b):
    """
    Return the rotation vector of the shortest rotation taking unit vectors ``a`` to ``b``.

    Its angle is ``atan2(|a × b|, a · b)`` (accurate near 0 and pi), its axis ``a × b``; for
    ``b = -a`` a half turn about a unit vector orthogonal to ``a`` (``a`` crossed with the axis
    of its smallest component), the same one for the same ``a``.

    Parameters
    ----------
    a, b : (..., 3) array_like
        Unit vectors (broadcast against each other).

    Returns
    -------
    (..., 3) ndarray  [rad]
        Axis times angle, the angle in [0, pi] (``so3_exp`` of it carries ``a`` to ``b``).

    """
    a, b = np.broadcast_arrays(np.asarray(a, dtype=float), np.asarray(b, dtype=float))
    axis = cross(a, b)
    sine = np.linalg.norm(axis, axis=-1, keepdims=True)
    angle = np.arctan2(sine, np.sum(a * b, axis=-1, keepdims=True))
    smallest = np.eye(3)[np.argmin(np.abs(a), axis=-1)]
    other = cross(a, smallest)
    other = other / np.linalg.norm(other, axis=-1, keepdims=True)
    turned = sine > 0.0
    unit = np.where(turned, axis / np.where(turned, sine, 1.0), other)
    return unit * angle


def so3_slerp(r0, r1, fraction):
    """
    Return the geodesic interpolation (slerp) of rotations: ``exp(t log(R1 R0ᵀ)) R0``.

    The rotation turns at a constant rate about a fixed axis (world axes) from ``R0`` (``t = 0``)
    to ``R1`` (``t = 1``), the short way (the quaternion slerp of the pair of the same sign).

    Parameters
    ----------
    r0, r1 : (..., 3, 3) array_like
        Rotation matrices.
    fraction : float or (...,) array_like
        ``t`` (0 at ``r0``, 1 at ``r1``).

    Returns
    -------
    (..., 3, 3) ndarray

    """
    r0, r1 = np.asarray(r0, dtype=float), np.asarray(r1, dtype=float)
    step = so3_log(r1 @ np.swapaxes(r0, -1, -2))
    return so3_exp(np.asarray(fraction, dtype=float)[..., None] * step) @ r0
