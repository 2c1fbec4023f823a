"""
Small SO(3) helpers of the fused tick (:mod:`cbha_inverse.core.tick`), in few numpy calls.

Hats by one matrix product, the ``Jl⁻¹`` coefficients and ``exp`` by power series evaluated as one
matrix product (their terms chosen so that the truncation is below round-off), the retraction
of the frames (:func:`cbha_inverse.core.chain.retract`) and the dense LU of the fallback tangent.
"""

from cbha_inverse.core.se3 import HAT_BASIS, JL_SERIES
import numpy as np
from scipy.linalg import lapack

# c(t) = sum_k a_k t^(2k), the hat(phi)^2 coefficient of Jl^-1: the first 7 terms of the se3
# series (truncation below round-off up to _SERIES_LIMIT), as one matrix product
_JL_SERIES = np.array(JL_SERIES[:7])
_JL_DSERIES = 2.0 * np.arange(1, 7) * _JL_SERIES[1:]
_JL_POWERS = np.arange(7)
_SERIES_LIMIT = 0.5
HALF_HAT_BASIS = -0.5 * HAT_BASIS
# sin(t)/t, (1 - cos t)/t^2 and cos t as series in t^2
_EXP_POWERS = np.arange(8)
_EXP_SERIES = np.array([[(-1.0) ** k / np.prod(np.arange(1.0, 2 * k + 2)),
                         (-1.0) ** k / np.prod(np.arange(1.0, 2 * k + 3)),
                         (-1.0) ** k / np.prod(np.arange(1.0, 2 * k + 1))] for k in range(8)])


def hats_into(out, v):
    """
    Write ``hat(v)`` into a buffer (one small matrix product).

    Parameters
    ----------
    out : (..., 3, 3) ndarray
        C-contiguous buffer.
    v : (..., 3) ndarray
        Vectors.

    Returns
    -------
    (..., 3, 3) ndarray
        ``out``.

    """
    np.matmul(v.reshape(-1, 3), HAT_BASIS, out=out.reshape(-1, 9))
    return out


def jl_coefficients(theta, t2):
    """
    Return ``c(t)`` and ``c'(t)/t`` of ``Jl⁻¹(φ) = I - φ^/2 + c φ^²`` (as in ``se3``).

    Parameters
    ----------
    theta, t2 : (n,) ndarray
        Angles [rad] and their squares.

    Returns
    -------
    c, dc_over_t : (n,) ndarray

    """
    # clamped: powers of tiny angles would be denormal numbers (~100x slower); exact anyway
    powers = np.power(np.maximum(t2, 1e-30)[:, None], _JL_POWERS)
    c = powers @ _JL_SERIES
    dc = powers[:, :6] @ _JL_DSERIES
    if theta.max() >= _SERIES_LIMIT:
        big = theta >= _SERIES_LIMIT
        t = theta[big]
        half = 0.5 * t
        cot = np.cos(half) / np.sin(half)
        c[big] = 1.0 / (t * t) - cot / (2.0 * t)
        dc[big] = (-2.0 / t ** 3 + 1.0 / (4.0 * t * np.sin(half) ** 2)
                   + cot / (2.0 * t * t)) / t
    return c, dc


def exp_rotations(rotvec, t2=None):
    """
    Return ``exp(hat(v))`` for (n, 3) rotation vectors (Rodrigues, few numpy calls).

    ``R = I + a v^ + b v^²`` with ``a = sin t / t`` and ``b = (1 - cos t) / t²``: both from their
    Taylor series (8 terms, truncation below 1e-19 up to 0.5 rad, which is the default
    ``max_rotation_step``), the closed form above.

    Parameters
    ----------
    rotvec : (n, 3) ndarray  [rad]
        Axis times angle.
    t2 : (n,) ndarray, optional
        Squared angles, if known.

    Returns
    -------
    (n, 3, 3) ndarray

    """
    if t2 is None:
        t2 = np.einsum('ni,ni->n', rotvec, rotvec)
    if t2.max() <= 0.25:
        # (clamped: powers of tiny angles would be denormal numbers, ~100x slower)
        ab = np.power(np.maximum(t2, 1e-30)[:, None], _EXP_POWERS) @ _EXP_SERIES
        a, b, cos = ab[:, 0], ab[:, 1], ab[:, 2:]
    else:
        theta = np.sqrt(t2)
        small = theta < 1e-4
        safe = np.where(small, 1.0, theta)
        a = np.where(small, 1.0 - t2 / 6.0, np.sin(safe) / safe)
        b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
        cos = (1.0 - b * t2)[:, None]
    out = (rotvec[:, :, None] * rotvec[:, None, :]).reshape(-1, 9)
    out *= b[:, None]
    out += (a[:, None] * rotvec) @ HAT_BASIS
    out[:, ::4] += cos
    return out.reshape(-1, 3, 3)


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
        Update ``positions`` and ``rotations`` instead of new arrays.

    Returns
    -------
    positions, rotations : ndarray
        ``x += dx``, ``R ← exp(dθ) R``.

    """
    rot = increments[:, 3:]
    t2 = np.einsum('ni,ni->n', rot, rot)
    if max_rotation is not None:
        largest = float(t2.max())
        if largest > max_rotation * max_rotation:
            factor = max_rotation / largest ** 0.5
            increments = increments * factor
            rot = increments[:, 3:]
            t2 = t2 * (factor * factor)
    if in_place:
        new_positions, new_rotations = positions, rotations
    else:
        new_positions = positions.copy()
        new_rotations = np.empty_like(rotations)
        new_rotations[0] = rotations[0]
    new_positions[1:] += increments[:, :3]
    np.matmul(exp_rotations(rot, t2), rotations[1:], out=new_rotations[1:])
    return new_positions, new_rotations


class DenseLU:
    """
    LAPACK LU factorization (``dgetrf``) of a square matrix with multi-RHS solves.

    The fallback factorization of a tick whose tangent is not symmetric positive definite
    (structure plus exact non-symmetric load stiffness at high pressure, see
    :meth:`cbha_inverse.core.control.InverseSolver._factor`).

    Parameters
    ----------
    matrix : (N, N) ndarray
        Square matrix (copied).

    Raises
    ------
    numpy.linalg.LinAlgError
        If the matrix is singular.

    """

    method = 'dense_lu'

    def __init__(self, matrix):
        """Factor a copy."""
        lu, piv, info = lapack.dgetrf(np.array(matrix, dtype=float, order='F'))
        if info != 0:
            raise np.linalg.LinAlgError(f'tangent stiffness singular (LU pivot {info})')
        self._lu, self._piv = lu, piv

    def solve(self, rhs):
        """
        Solve ``K X = rhs``.

        Parameters
        ----------
        rhs : (N,) or (N, k) ndarray
            Right-hand sides.

        Returns
        -------
        ndarray
            Same shape as ``rhs``.

        """
        x, info = lapack.dgetrs(self._lu, self._piv, rhs)
        if info != 0:
            raise np.linalg.LinAlgError(f'dgetrs failed (info {info})')
        return x
