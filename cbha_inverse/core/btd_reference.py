"""
Reference and LAPACK backends of the block-tridiagonal solver (see :mod:`cbha_inverse.core.btd`).

- :func:`factor_dense`, :func:`factor_banded`, :func:`factor_hybrid`: LAPACK through scipy
  (``dpotrf``/``dpotrs`` on the dense matrix, ``dpbtrf``/``dpbtrs`` on the band, the band factor
  solved densely), the comparison points of ``cbha_bench_core``;
- :func:`factor_block`: the textbook sequential block Cholesky, one Python iteration per block;
- :func:`factor_cyclic`: block cyclic reduction (block LDL^T of the odd-even permuted matrix),
  each of its log2(n) levels vectorised over all its blocks.

All are exact; ``cbha_bench_core`` measures them against the compiled band kernels that
``factorize(method='auto')`` uses. Call them through ``factorize(..., method=...)`` with
``'dense'``, ``'banded'``, ``'hybrid'``, ``'block'`` or ``'cyclic'``.
"""

import os

from cbha_inverse.core.btd import (BTDFactorization, not_pd_error, NotPositiveDefiniteError,
                                   to_lower_banded)
import numpy as np
from scipy.linalg import blas, lapack


def _dense_lower(diagonal, upper):
    """
    Assemble the dense matrix for LAPACK ``uplo='L'`` without a copy (Fortran order).

    The diagonal and upper blocks are written into a C-ordered array through block views with
    row stride ``b (bn + 1)`` (slices of a reshaped flat buffer); its transpose is
    Fortran-contiguous and holds them as the lower triangle.
    """
    n, b = diagonal.shape[:2]
    size = n * b
    step = b * (size + 1)
    flat = np.zeros(n * step)
    flat.reshape(n, step)[:, :b * size].reshape(n, b, size)[:, :, :b] = diagonal
    flat.reshape(n, step)[:-1, b:b + b * size].reshape(n - 1, b, size)[:, :, :b] = upper
    return flat[:size * size].reshape(size, size).T


def factor_dense(diagonal, upper):
    """Dense LAPACK Cholesky backend."""
    n, b = diagonal.shape[:2]
    factor, info = lapack.dpotrf(_dense_lower(diagonal, upper), lower=1, clean=0, overwrite_a=1)
    if info > 0:
        raise not_pd_error(info - 1, b, factor[info - 1, info - 1], 'dense Cholesky')
    if info < 0 or not np.isfinite(factor.diagonal()).all():
        raise ValueError('dense Cholesky failed: non-finite entries or illegal argument')
    return BTDFactorization('dense', (diagonal, upper), _dense_solver(factor),
                            dense_factor=factor)


def _dense_solver(factor):
    """Return ``rhs -> A^-1 rhs`` for a dense lower Cholesky factor (``dpotrs``, level 3)."""
    def solver(rhs):
        x, _ = lapack.dpotrs(factor, rhs, lower=1)
        return x

    return solver


def _band_cholesky(diagonal, upper):
    """Banded Cholesky factor (``dpbtrf``) of checked blocks; raises on failure."""
    b = diagonal.shape[1]
    factor, info = lapack.dpbtrf(to_lower_banded(diagonal, upper), lower=1, overwrite_ab=1)
    if info > 0:
        raise not_pd_error(info - 1, b, factor[0, info - 1], 'banded Cholesky')
    if info < 0 or not np.isfinite(factor[0]).all():
        raise ValueError('banded Cholesky failed: non-finite entries or illegal argument')
    return factor


def factor_banded(diagonal, upper):
    """LAPACK banded Cholesky backend (dpbtrf / dpbtrs)."""
    factor = _band_cholesky(diagonal, upper)

    def solver(rhs):
        x, _ = lapack.dpbtrs(factor, rhs, lower=1)
        return x

    return BTDFactorization('banded', (diagonal, upper), solver)


def factor_hybrid(diagonal, upper):
    """
    Banded Cholesky factor, solved with dense triangular solves (small n, many RHS).

    ``dpbtrf`` factorises in O(n); the band factor is then scattered into a dense lower
    triangle (one strided copy: column j of the Fortran array holds ``L[j + r, j]`` at offset
    ``j (N + 1) + r``) so that ``dpotrs`` solves all right-hand sides with level-3 ``dtrsm``
    instead of ``dpbtrs``'s column-by-column ``dtbsv``.
    """
    n, b = diagonal.shape[:2]
    band = _band_cholesky(diagonal, upper)
    size = n * b
    flat = np.zeros(size * (size + 1) + 2 * b)
    width = min(2 * b, size + 1)
    flat[:size * (size + 1)].reshape(size, size + 1)[:, :width] = band.T[:, :width]
    factor = flat[:size * size].reshape(size, size).T
    return BTDFactorization('hybrid', (diagonal, upper), _dense_solver(factor),
                            dense_factor=factor)


def blas_single_threaded():
    """
    Return True if the environment pins OpenBLAS/OpenMP to one thread.

    The 'hybrid' backend solves with level-3 ``dtrsm``; with threaded OpenBLAS on a loaded
    machine a 96 x 96 triangular solve with 20 right-hand sides was measured at 30 ms instead of
    30 us (thread wake-up), while the level-2 ``dpbtrs`` of 'banded' is never threaded. 'auto'
    uses 'hybrid' only when ``OPENBLAS_NUM_THREADS`` (or ``OMP_NUM_THREADS``) is 1.

    Returns
    -------
    bool

    """
    value = os.environ.get('OPENBLAS_NUM_THREADS', os.environ.get('OMP_NUM_THREADS'))
    return value is not None and value.strip() == '1'


def factor_block(diagonal, upper):
    """
    Sequential block Cholesky ``A = L L^T`` with L block lower bidiagonal (textbook BTD).

    ``S_i = D_i - M_(i-1) M_(i-1)^T``, ``L_i = chol(S_i)``, ``M_i = U_i^T L_i^-T``; solves by
    block forward and back substitution, every right-hand side at once. One Python iteration
    per block (LAPACK ``dpotrf`` and BLAS ``dtrsm`` on 6x6 blocks): the reference
    implementation, kept to show in the benchmark what the compiled band backends save.
    """
    n, b = diagonal.shape[:2]
    chol = np.empty((n, b, b))
    coupling = np.empty((max(n - 1, 0), b, b))      # M_i^T = L_i^-1 U_i
    schur = diagonal[0]
    for i in range(n):
        factor, info = lapack.dpotrf(schur, lower=1, clean=1)
        if info > 0:
            raise not_pd_error(b * i + info - 1, b, factor[info - 1, info - 1], 'block Cholesky')
        if info < 0 or not np.isfinite(factor).all():
            raise ValueError('block Cholesky failed: non-finite entries or illegal argument')
        chol[i] = factor
        if i + 1 < n:
            m_t = blas.dtrsm(1.0, factor, upper[i], lower=1)
            coupling[i] = m_t
            schur = diagonal[i + 1] - m_t.T @ m_t

    def solver(rhs):
        k = rhs.shape[1]
        y = rhs.reshape(n, b, k).copy()
        for i in range(n):
            if i > 0:
                y[i] -= coupling[i - 1].T @ y[i - 1]
            y[i] = blas.dtrsm(1.0, chol[i], y[i], lower=1)
        for i in range(n - 1, -1, -1):
            if i + 1 < n:
                y[i] -= coupling[i] @ y[i + 1]
            y[i] = blas.dtrsm(1.0, chol[i], y[i], lower=1, trans_a=1)
        return y.reshape(n * b, k)

    return BTDFactorization('block', (diagonal, upper), solver)


def _first_bad_block(blocks):
    """Index of the first block whose Cholesky fails, and its smallest eigenvalue."""
    for k, blk in enumerate(blocks):
        try:
            np.linalg.cholesky(blk)
        except np.linalg.LinAlgError:
            return k, float(np.linalg.eigvalsh(0.5 * (blk + blk.T))[0])
    return 0, float('nan')


def _check_pivots(blocks, index):
    """Raise if a pivot block (original block indices ``index``) is not positive definite."""
    try:
        np.linalg.cholesky(blocks)
    except np.linalg.LinAlgError:
        k, eig = _first_bad_block(blocks)
        raise NotPositiveDefiniteError(
            'block-tridiagonal matrix is not positive definite: cyclic-reduction pivot '
            f'block of original block {index[k]} has eigenvalue {eig:.6g}') from None


def factor_cyclic(diagonal, upper):
    """
    Block cyclic reduction backend (block LDL^T of the odd-even permuted matrix).

    At each level the odd blocks j are eliminated: with ``X_l = D_j^-1 U_{j-1}^T`` and ``X_r =
    D_j^-1 U_j``, the even blocks become ``D_i -= U_{i-1}^T X_r(i-1) + U_i X_l(i+1)`` and
    couple to the next even block by ``-U_i X_r(i+1)``. The Schur complements of an SPD matrix
    are SPD, so a failed Cholesky of a pivot block proves the matrix is not positive definite.
    """
    n, b = diagonal.shape[:2]
    if not (np.isfinite(diagonal).all() and np.isfinite(upper).all()):
        raise ValueError('block-tridiagonal matrix has non-finite entries')
    d = diagonal
    u = upper
    index = np.arange(n)
    levels = []
    while d.shape[0] > 1:
        m = d.shape[0]
        d_odd = d[1::2]
        _check_pivots(d_odd, index[1::2])
        d_inv = np.linalg.inv(d_odd)
        u_left = u[0::2]
        u_right = u[1::2]
        n_right = u_right.shape[0]
        x_left = d_inv @ np.swapaxes(u_left, 1, 2)
        x_right = d_inv[:n_right] @ u_right
        d_even = d[0::2].copy()
        d_even[1:1 + n_right] -= np.swapaxes(u_right, 1, 2) @ x_right
        d_even[:m // 2] -= u_left @ x_left
        u = -(u_left[:n_right] @ x_right)
        levels.append((d_inv, x_left, x_right, np.swapaxes(x_left, 1, 2).copy(),
                       np.swapaxes(x_right, 1, 2).copy()))
        d = d_even
        index = index[0::2]
    _check_pivots(d, index)
    last_inv = np.linalg.inv(d)

    def solver(rhs):
        k = rhs.shape[1]
        r = rhs.reshape(n, b, k)
        odds = []
        for d_inv, x_left, x_right, x_left_t, x_right_t in levels:
            r_odd = r[1::2]
            n_right = x_right.shape[0]
            r = r[0::2].copy()
            r[1:1 + n_right] -= x_right_t @ r_odd[:n_right]
            r[:x_left.shape[0]] -= x_left_t @ r_odd
            odds.append(r_odd)
        x = last_inv @ r
        for (d_inv, x_left, x_right, _, _), r_odd in zip(reversed(levels), reversed(odds)):
            m_even = x.shape[0]
            m = m_even + r_odd.shape[0]
            full = np.empty((m, b, k))
            full[0::2] = x
            x_odd = d_inv @ r_odd
            x_odd -= x_left @ x[:r_odd.shape[0]]
            x_odd[:x_right.shape[0]] -= x_right @ x[1:1 + x_right.shape[0]]
            full[1::2] = x_odd
            x = full
        return x.reshape(n * b, k)

    return BTDFactorization('cyclic', (diagonal, upper), solver)
