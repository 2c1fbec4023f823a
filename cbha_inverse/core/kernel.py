"""
Fused per-tick kernel of the chain mechanics for the online inverse solver.

:mod:`cbha_inverse.core.assembly` is the reference implementation of the internal wrenches and
of the exact block-tridiagonal tangent (paper eq. 5-9, DESIGN §3). This module evaluates the same
quantities with fewer, larger numpy operations and preallocated buffers, writes the tangent
directly into a dense symmetric matrix and factors it with LAPACK Cholesky (``dpotrf``): for the
chain sizes of the control scenes (6n ≤ ~200) one dense factorization is faster in Python than
a block recursion (the BTD benchmark of :mod:`cbha_inverse.report.bench_core` shows the
crossover). The tests check every output against the reference to round-off.
"""

from cbha_inverse.core.se3 import so3_left_jacobian_inverse_transpose_derivative
import numpy as np
from scipy.linalg import lapack

# |B_(2k+2)| / (2k+2)!: coefficients of c(t) = sum_k a_k t^(2k), the hat(phi)^2 coefficient of
# the inverse left Jacobian of SO(3) (same series as cbha_inverse.core.se3).
_JL_SERIES = np.array([1.0 / 12.0, 1.0 / 720.0, 1.0 / 30240.0, 1.0 / 1209600.0,
                       1.0 / 47900160.0, 691.0 / 2730.0 / 479001600.0,
                       7.0 / 6.0 / 87178291200.0])
_SERIES_LIMIT = 0.5


def jl_inverse_coefficients(theta, derivative=True):
    """
    Return ``c(t)`` and ``c'(t)/t`` of ``Jl⁻¹(φ) = I - φ^/2 + c(|φ|) φ^²``.

    Parameters
    ----------
    theta : (n,) ndarray  [rad]
        Rotation angles (< 2π).
    derivative : bool
        Also return ``c'(t)/t`` (else ``None``).

    Returns
    -------
    c, dc_over_t : (n,) ndarray
        Series below 0.5 rad (only the terms that matter at the largest angle: truncation below
        1e-16 relative), closed form above.

    """
    t2 = theta * theta
    t_max = min(float(theta.max()), _SERIES_LIMIT) if theta.size else 0.0
    terms = 1
    while terms < len(_JL_SERIES) and _JL_SERIES[terms] * t_max ** (2 * terms) > 1e-17 / 12.0:
        terms += 1
    terms = min(terms + 1, len(_JL_SERIES))
    c = np.full_like(theta, _JL_SERIES[terms - 1])
    for k in range(terms - 2, -1, -1):
        c = c * t2 + _JL_SERIES[k]
    dc = None
    if derivative:
        dc = np.full_like(theta, 2.0 * (terms - 1) * _JL_SERIES[terms - 1])
        for k in range(terms - 2, 0, -1):
            dc = dc * t2 + 2.0 * k * _JL_SERIES[k]
    big = theta >= _SERIES_LIMIT
    if big.any():
        t = theta[big]
        half = 0.5 * t
        cot = np.cos(half) / np.sin(half)
        c[big] = 1.0 / (t * t) - cot / (2.0 * t)
        if derivative:
            dc[big] = (-2.0 / t ** 3 + 1.0 / (4.0 * t * np.sin(half) ** 2)
                       + cot / (2.0 * t * t)) / t
    return c, dc


def _hat_into(out, v):
    """Write ``hat(v)`` (n, 3) into ``out`` (n, 3, 3) (zero diagonal assumed)."""
    out[:, 0, 1] = -v[:, 2]
    out[:, 0, 2] = v[:, 1]
    out[:, 1, 0] = v[:, 2]
    out[:, 1, 2] = -v[:, 0]
    out[:, 2, 0] = -v[:, 1]
    out[:, 2, 1] = v[:, 0]
    return out


def fast_so3_exp(rotvec):
    """
    Return ``exp(hat(v))`` for (n, 3) rotation vectors (Rodrigues, elementwise).

    Parameters
    ----------
    rotvec : (n, 3) ndarray  [rad]
        Axis times angle.

    Returns
    -------
    (n, 3, 3) ndarray

    """
    t2 = np.einsum('ni,ni->n', rotvec, rotvec)
    theta = np.sqrt(t2)
    small = theta < 1e-4
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - t2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - t2 / 24.0, (1.0 - np.cos(safe)) / (safe * safe))
    out = (b[:, None, None] * rotvec[:, :, None]) * rotvec[:, None, :]
    diag = 1.0 - b * t2
    out[:, 0, 0] += diag
    out[:, 1, 1] += diag
    out[:, 2, 2] += diag
    av = a[:, None] * rotvec
    out[:, 0, 1] -= av[:, 2]
    out[:, 0, 2] += av[:, 1]
    out[:, 1, 0] += av[:, 2]
    out[:, 1, 2] -= av[:, 0]
    out[:, 2, 0] -= av[:, 1]
    out[:, 2, 1] += av[:, 0]
    return out


class ChainKernel:
    """
    Preallocated evaluator of the internal wrenches and the dense tangent of one chain model.

    Parameters
    ----------
    model : cbha_inverse.core.chain.ChainModel
        The chain (immutable).

    """

    def __init__(self, model):
        """Precompute constants and buffers."""
        n = model.n_links
        self.n = n
        self.stiffness = np.ascontiguousarray(model.stiffnesses)
        self.rest_offsets = np.ascontiguousarray(model.rest_offsets)
        q0 = np.asarray(model.rest_rotations)
        identity = np.allclose(q0, np.eye(3), atol=0.0, rtol=0.0)
        self._q0t = None if identity else np.ascontiguousarray(np.swapaxes(q0, 1, 2))
        self._b = np.zeros((n, 6, 6))
        self._b[:, :3, :3] = np.eye(3)
        self._tp = np.zeros((n, 6, 6))
        self._tp[:, :3, :3] = np.eye(3)
        self._tp[:, 3:, 3:] = np.eye(3)
        self._rb = np.zeros((3, n, 6, 6))
        self._hat = np.zeros((n, 3, 3))
        self._p_hat = np.zeros((n, 3, 3))
        self._f_hat = np.zeros((n, 3, 3))
        self._m_hat = np.zeros((n, 3, 3))
        self._delta = np.empty((n, 6))
        self._local = np.empty((n, 3, 2))
        self._dense = np.zeros((n, 6, n, 6))
        idx = np.arange(n)
        self._idx = idx
        self._eye3 = np.eye(3)

    def _terms(self, positions, rotations, derivative=True):
        """Return the local link terms shared by the wrenches and the tangent."""
        rot_a = rotations[:-1]
        rot_at = np.swapaxes(rot_a, 1, 2)
        diff = positions[1:] - positions[:-1]
        offset = np.matmul(rot_at, diff[:, :, None])[:, :, 0]
        rel = np.matmul(rot_at, rotations[1:])
        if self._q0t is not None:
            rel = np.matmul(rel, self._q0t)
        flat = rel.reshape(-1, 9)
        d = 0.5 * (flat[:, [7, 2, 3]] - flat[:, [5, 6, 1]])
        sin_t = np.sqrt((d * d).sum(axis=1))
        cos_t = 0.5 * (flat[:, 0] + flat[:, 4] + flat[:, 8] - 1.0)
        if cos_t.min() <= -0.5:
            from cbha_inverse.core.se3 import so3_log
            phi = so3_log(rel)
            theta = np.sqrt((phi * phi).sum(axis=1))
        else:
            theta = np.arctan2(sin_t, cos_t)
            ratio = np.divide(theta, sin_t, out=np.ones_like(theta), where=sin_t > 0.0)
            phi = d * ratio[:, None]
        delta = self._delta
        delta[:, :3] = offset - self.rest_offsets
        delta[:, 3:] = phi
        stress = np.matmul(self.stiffness, delta[:, :, None])[:, :, 0]
        c, dc = jl_inverse_coefficients(theta, derivative)
        s_r = stress[:, 3:]
        phi_dot_s = (phi * s_r).sum(axis=1)
        # Jl^-T s = s + phi x s / 2 + c (phi (phi . s) - t^2 s)
        cr = np.empty_like(s_r)
        cr[:, 0] = phi[:, 1] * s_r[:, 2] - phi[:, 2] * s_r[:, 1]
        cr[:, 1] = phi[:, 2] * s_r[:, 0] - phi[:, 0] * s_r[:, 2]
        cr[:, 2] = phi[:, 0] * s_r[:, 1] - phi[:, 1] * s_r[:, 0]
        t2 = (theta * theta)[:, None]
        moment_local = -(s_r + 0.5 * cr + c[:, None] * (phi * phi_dot_s[:, None] - t2 * s_r))
        local = self._local
        local[:, :, 0] = -stress[:, :3]
        local[:, :, 1] = moment_local
        world = np.matmul(rot_a, local)
        return offset, diff, phi, theta, c, dc, stress, moment_local, world

    @staticmethod
    def _gather(diff, world):
        """Frame wrenches (n, 6) from the b-side world wrenches of every link."""
        force = world[:, :, 0]
        moment = world[:, :, 1]
        internal = np.empty((force.shape[0], 6))
        internal[:, :3] = force
        internal[:, 3:] = moment
        arm_x_f = np.empty_like(force[1:])
        d, f = diff[1:], force[1:]
        arm_x_f[:, 0] = d[:, 1] * f[:, 2] - d[:, 2] * f[:, 1]
        arm_x_f[:, 1] = d[:, 2] * f[:, 0] - d[:, 0] * f[:, 2]
        arm_x_f[:, 2] = d[:, 0] * f[:, 1] - d[:, 1] * f[:, 0]
        internal[:-1, :3] -= f
        internal[:-1, 3:] -= moment[1:] + arm_x_f
        return internal

    def internal(self, positions, rotations):
        """
        Return the internal wrenches on frames 1..n (as :func:`assembly.internal_wrenches`).

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.

        Returns
        -------
        (n, 6) ndarray  [N, N*m]

        """
        terms = self._terms(positions, rotations, derivative=False)
        return self._gather(terms[1], terms[8])

    def linearise(self, positions, rotations, geometric=True):
        """
        Return the internal wrenches and the dense tangent ``K`` (as :func:`assemble_tangent`).

        Parameters
        ----------
        positions : (n + 1, 3) ndarray  [m]
            Frame origins.
        rotations : (n + 1, 3, 3) ndarray
            Frame rotations.
        geometric : bool
            Include the geometric (stress-dependent) part. Without it the tangent is the
            material part of paper eq. 8 (rotated ``Bᵀ K B`` with the lever transport), positive
            definite whatever the stresses: the fallback when the full tangent is not.

        Returns
        -------
        internal : (n, 6) ndarray  [N, N*m]
        dense : (6n, 6n) ndarray
            Symmetric tangent (a view of an internal buffer: copy it to keep it).

        """
        offset, diff, phi, theta, c, dc, stress, moment_local, world = self._terms(positions,
                                                                                   rotations)
        internal = self._gather(diff, world)
        phi_hat = _hat_into(self._hat, phi)
        jinv = c[:, None, None] * np.matmul(phi_hat, phi_hat) - 0.5 * phi_hat
        jinv += self._eye3
        b = self._b
        b[:, 3:, 3:] = jinv
        t_bb = np.matmul(np.swapaxes(b, 1, 2), np.matmul(self.stiffness, b))
        p_hat = _hat_into(self._p_hat, offset)
        tp = self._tp
        tp[:, :3, 3:] = -p_hat
        t_ab = np.matmul(np.swapaxes(tp, 1, 2), t_bb)
        t_aa = np.matmul(t_ab, tp)
        t_ab *= -1.0
        if geometric:
            f_hat = _hat_into(self._f_hat, stress[:, :3])
            m_hat = _hat_into(self._m_hat, moment_local)
            dj = np.matmul(so3_left_jacobian_inverse_transpose_derivative(
                phi, stress[:, 3:], (c, dc)), jinv)
            t_aa[:, :3, 3:] += f_hat
            t_aa[:, 3:, :3] -= f_hat
            t_aa[:, 3:, 3:] += np.matmul(p_hat, f_hat) - m_hat + dj
            t_ab[:, 3:, :3] += f_hat
            t_ab[:, 3:, 3:] -= dj
            t_bb[:, 3:, 3:] += dj
        rb = self._rb
        rot_a = rotations[:-1]
        rb[:, :, :3, :3] = rot_a
        rb[:, :, 3:, 3:] = rot_a
        stacked = np.stack([t_aa, t_ab, t_bb])
        blocks = np.matmul(np.matmul(rb, stacked), np.swapaxes(rb, -1, -2))
        diagonal = blocks[2]
        diagonal[:-1] += blocks[0, 1:]
        diagonal = 0.5 * (diagonal + np.swapaxes(diagonal, 1, 2))
        dense = self._dense
        idx = self._idx
        dense[idx, :, idx, :] = diagonal
        dense[idx[:-1], :, idx[1:], :] = blocks[1, 1:]
        dense[idx[1:], :, idx[:-1], :] = np.swapaxes(blocks[1, 1:], 1, 2)
        return internal, dense.reshape(6 * self.n, 6 * self.n)


class DenseCholesky:
    """
    LAPACK Cholesky factorization of a symmetric positive definite matrix.

    Parameters
    ----------
    matrix : (N, N) ndarray
        Symmetric positive definite (only the lower triangle is read; it is overwritten).

    Raises
    ------
    numpy.linalg.LinAlgError
        If the matrix is not positive definite (LAPACK ``info > 0``: the failing pivot).

    """

    method = 'dense_cholesky'

    def __init__(self, matrix):
        """Factor in place."""
        factor, info = lapack.dpotrf(matrix, lower=1, clean=0, overwrite_a=1)
        if info != 0:
            raise np.linalg.LinAlgError(
                f'tangent stiffness not positive definite (Cholesky pivot {info}, frame '
                f'{(info - 1) // 6 + 1})')
        self._factor = factor

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
        x, info = lapack.dpotrs(self._factor, rhs, lower=1)
        if info != 0:
            raise np.linalg.LinAlgError(f'dpotrs failed (info {info})')
        return x


class DenseLU:
    """
    LAPACK LU factorization (``dgetrf``) of a square matrix.

    The fallback for tangents that are not symmetric positive definite (exact non-symmetric load
    stiffness at high pressure).

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


def fast_retract(positions, rotations, increments):
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

    Returns
    -------
    positions, rotations : new arrays
        ``x += dx``, ``R ← exp(dθ) R``.

    """
    new_positions = positions.copy()
    new_positions[1:] += increments[:, :3]
    new_rotations = rotations.copy()
    new_rotations[1:] = np.matmul(fast_so3_exp(increments[:, 3:]), rotations[1:])
    return new_positions, new_rotations
