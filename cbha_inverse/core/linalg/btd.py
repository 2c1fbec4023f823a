"""
Symmetric positive definite block-tridiagonal (BTD) factorisation with multi-RHS solves.

The matrix has n diagonal blocks ``D_i`` (b x b, b = 6 for the frame chain) and n - 1 upper
blocks ``U_i`` = block (i, i+1); block (i+1, i) is ``U_i^T`` (paper Sec. III: the global
stiffness of the frame chain is block tridiagonal). Storage::

    [ D_0   U_0                 ]
    [ U_0^T D_1   U_1           ]
    [       U_1^T D_2   ...     ]
    [             ...   D_{n-1} ]

Backends (all exact direct methods; ``method='auto'`` is ``'compiled'`` at every size, see
:func:`choose_method` and the table below):

- ``'compiled'`` (b = 6, the frame chain's blocks): numba kernels
  (:func:`~cbha_inverse.core._kernels.assembly.btd_cholesky`,
  :func:`~cbha_inverse.core._kernels.block_band.block_solve`): the block Cholesky of the
  control tick and of the static solver's fallback
  (:class:`cbha_inverse.core.system.EquilibriumSystem`), one call to factor, one to solve all
  right-hand sides, no LAPACK wrapper; the default for b = 6;
- ``'banded'``: LAPACK banded Cholesky ``dpbtrf``/``dpbtrs`` on the (2b, bn) lower band storage
  (half-bandwidth 2b - 1 = 11), built from the blocks by two strided copies: the standard
  banded comparison point;
- ``'dense'``: LAPACK ``dpotrf``/``dpotrs`` on the assembled (bn x bn) matrix, written through
  strided block views: the dense comparison point.

Factorisation + solve of rest tangents of curved 6-DOF frame chains (n blocks, k right-hand
sides), ``cbha_bench_core`` on the 2-core development machine, ``OPENBLAS_NUM_THREADS=1``,
microseconds; LAPACK pb = ``dpbtrf`` + ``dpbtrs`` on ready band storage::

        n   k   LAPACK pb   compiled  ratio    dense   banded
        6   6        10.8        9.7   0.90     20.3     25.2
        6  20        26.6       11.0   0.41     23.3     41.8
       16   6        26.9       17.8   0.66     49.2     42.9
       16  20        68.8       18.4   0.27     58.7     85.7
      100   6       162.9       84.8   0.52   2596.1    190.6
      100  20       431.1       90.0   0.21   2777.9    461.3
     1000   6      1618.6      804.0   0.50        -   1750.3
     1000  20      4305.4      963.0   0.22        -   4444.0
    10000   6     16341.7     8060.8   0.49        -  17410.5
    10000  20     43589.5     9809.5   0.23        -  44767.2

Every backend detects a matrix that is not positive definite and raises
:class:`NotPositiveDefiniteError` naming the block; :attr:`BTDFactorization.condition_estimate`
is the 1-norm condition number estimate (LAPACK ``dpocon`` for the dense backend, the
Hager-Higham estimator with the factor's own solves otherwise).
"""

from cbha_inverse.core._kernels.assembly import btd_cholesky
from cbha_inverse.core._kernels.block_band import block_solve
import numpy as np
from scipy.linalg import lapack

METHODS = ('auto', 'compiled', 'dense', 'banded')
_MASKS = {}


class NotPositiveDefiniteError(np.linalg.LinAlgError):
    """The block-tridiagonal matrix is not (numerically) positive definite."""


class IllConditionedError(np.linalg.LinAlgError):
    """The condition estimate exceeds the limit given to :func:`factorize`."""


def _check_blocks(diagonal, upper):
    """Validate shapes and return float arrays (n, b, b) and (n - 1, b, b)."""
    diagonal = np.asarray(diagonal, dtype=float)
    upper = np.asarray(upper, dtype=float)
    if diagonal.ndim != 3 or diagonal.shape[1] != diagonal.shape[2] or diagonal.shape[0] < 1:
        raise ValueError(f'diagonal must have shape (n, b, b), got {diagonal.shape}')
    n, b = diagonal.shape[:2]
    if upper.shape != (n - 1, b, b):
        raise ValueError(f'upper must have shape ({n - 1}, {b}, {b}), got {upper.shape}')
    return diagonal, upper


def block_one_norm(diagonal, upper):
    """
    Return the 1-norm (max column sum) of a symmetric block-tridiagonal matrix.

    Parameters
    ----------
    diagonal : (n, b, b) array_like
        Diagonal blocks.
    upper : (n - 1, b, b) array_like
        Blocks (i, i+1).

    Returns
    -------
    float

    """
    diagonal, upper = _check_blocks(diagonal, upper)
    col = np.abs(diagonal).sum(axis=1)
    absu = np.abs(upper)
    col[1:] += absu.sum(axis=1)        # block (i, i+1) contributes to columns of block i+1
    col[:-1] += absu.sum(axis=2)       # block (i+1, i) = U_i^T contributes to block i
    return float(col.max())


def to_dense(diagonal, upper):
    """
    Return the dense symmetric matrix of BTD blocks (the dense comparison's input).

    Parameters
    ----------
    diagonal : (n, b, b) array_like
        Diagonal blocks.
    upper : (n - 1, b, b) array_like
        Blocks (i, i+1); block (i+1, i) is the transpose.

    Returns
    -------
    (bn, bn) ndarray

    """
    diagonal, upper = _check_blocks(diagonal, upper)
    n, b = diagonal.shape[:2]
    out = np.zeros((n, b, n, b))
    idx = np.arange(n)
    out[idx, :, idx, :] = diagonal
    out[idx[:-1], :, idx[1:], :] = upper
    out[idx[1:], :, idx[:-1], :] = np.swapaxes(upper, 1, 2)
    return out.reshape(n * b, n * b)


def to_lower_banded(diagonal, upper):
    """
    Convert symmetric BTD blocks to LAPACK lower band storage (``ab[r, j] = A[j + r, j]``).

    With half-bandwidth ``kd = 2b - 1`` the band holds the whole block tridiagonal. In the
    C-ordered (n, b, 2b) array whose transpose-reshape is the Fortran band, row c of block k
    holds ``D_k[c, c:]``, then ``U_k[c, :]``, then c zeros. Both blocks are therefore written
    with one strided view each (row stride ``2b - 1``): the upper triangle of ``D`` (its strict
    lower triangle is written as zeros and lands exactly in the zero tail of the previous row),
    then ``U`` (which overwrites the one slot the diagonal view shares with it); two small
    writes clear the tail of the last row of every block and the ``U`` slots of the last block.
    No intermediate copy is made.

    Parameters
    ----------
    diagonal : (n, b, b) array_like
        Diagonal blocks.
    upper : (n - 1, b, b) array_like
        Blocks (i, i+1).

    Returns
    -------
    (2b, bn) ndarray, Fortran order

    """
    diagonal, upper = _check_blocks(diagonal, upper)
    return _band(diagonal, upper)


def _band(diagonal, upper):
    """Lower band storage of checked blocks (see :func:`to_lower_banded`)."""
    n, b = diagonal.shape[:2]
    w = 2 * b
    band = np.empty((n, b * w))
    # element (k, c, m) of these views is band[k, (w - 1) c + m + offset]: row stride w - 1
    span = b * (w - 1)
    band[:, :span].reshape(n, b, w - 1)[:, :, :b] = diagonal * _upper_mask(b)
    band[:-1, b:b + span].reshape(n - 1, b, w - 1)[:, :, :b] = upper
    band[-1, b:b + span].reshape(b, w - 1)[:, :b] = 0.0
    band[:, (b - 1) * w + b + 1:] = 0.0
    return band.reshape(n * b, w).T


def _upper_mask(b):
    """Return the (b, b) upper-triangular 0/1 mask (cached)."""
    if b not in _MASKS:
        _MASKS[b] = np.triu(np.ones((b, b)))
    return _MASKS[b]


def not_pd_error(row, block_size, pivot, how):
    """Build the error for a failed pivot at global row ``row`` (0-based)."""
    block, comp = divmod(int(row), block_size)
    return NotPositiveDefiniteError(
        f'block-tridiagonal matrix is not positive definite: {how} pivot {pivot:.6g} at row '
        f'{row} (block {block}, component {comp})')


def _hager_inverse_one_norm(solve, size):
    """Estimate ||A^-1||_1 of a symmetric A from solves (Hager 1984, Higham 1988)."""
    x = np.full(size, 1.0 / size)
    est = 0.0
    for it in range(5):
        y = solve(x)
        new = float(np.abs(y).sum())
        if it > 0 and new <= est:
            break
        est = new
        z = solve(np.where(y >= 0.0, 1.0, -1.0))
        j = int(np.argmax(np.abs(z)))
        if it > 0 and abs(z[j]) <= z @ x:
            break
        x = np.zeros(size)
        x[j] = 1.0
    alt = np.arange(size, dtype=float)
    alt = (1.0 + alt / max(size - 1, 1)) * np.where(alt % 2 == 0, 1.0, -1.0)
    return max(est, 2.0 * float(np.abs(solve(alt)).sum()) / (3.0 * size))


class BTDFactorization:
    """
    A factorised SPD block-tridiagonal matrix; reusable for any number of solves.

    Attributes
    ----------
    method : str
        Backend used (one of :data:`METHODS` other than 'auto').
    n_blocks : int
        Number of diagonal blocks n.
    block_size : int
        Block size b.

    """

    def __init__(self, method, blocks, solver, dense_factor=None):
        self.method = method
        self.n_blocks, self.block_size = blocks[0].shape[:2]
        self._blocks = blocks
        self._solver = solver
        self._dense_factor = dense_factor
        self._condition = None

    @property
    def size(self):
        """Return the matrix dimension b n."""
        return self.n_blocks * self.block_size

    @property
    def condition_estimate(self):
        """Return the estimated 1-norm condition number ``||A||_1 ||A^-1||_1`` (computed once)."""
        if self._condition is None:
            if self._dense_factor is not None:
                anorm = block_one_norm(*self._blocks)
                rcond, _ = lapack.dpocon(self._dense_factor, anorm, uplo='L')
                self._condition = np.inf if rcond <= 0.0 else 1.0 / rcond
            else:
                inv_norm = _hager_inverse_one_norm(lambda v: self._solver(v[:, None])[:, 0],
                                                   self.size)
                self._condition = block_one_norm(*self._blocks) * inv_norm
        return self._condition

    def solve(self, rhs):
        """
        Solve ``A x = rhs`` for one or many right-hand sides at once.

        Parameters
        ----------
        rhs : (bn,) or (bn, k) array_like
            Right-hand side(s), one per column.

        Returns
        -------
        ndarray
            Same shape as ``rhs``.

        """
        rhs = np.asarray(rhs, dtype=float)
        if rhs.shape[0] != self.size or rhs.ndim not in (1, 2):
            raise ValueError(f'rhs must have shape ({self.size},) or ({self.size}, k), '
                             f'got {rhs.shape}')
        if rhs.ndim == 1:
            return self._solver(rhs[:, None])[:, 0]
        return self._solver(rhs)


def _kernel_array(array):
    """Return ``array`` as a writable C-ordered float array (one numba signature, no recompile)."""
    if array.flags.c_contiguous and array.flags.writeable and array.dtype == np.float64:
        return array
    return np.array(array, dtype=np.float64, order='C')


def _factor_compiled(diagonal, upper):
    """
    Compiled block Cholesky backend (numba, :mod:`cbha_inverse.core._kernels.block_band`).

    One kernel call writes the block band straight from the blocks and factors it; each solve
    copies the right-hand sides into a C-ordered array and runs one forward and one backward
    sweep on all of them at once. Blocks of 6 x 6 (a frame's unknowns) only.
    """
    b = diagonal.shape[1]
    if b != 6:
        raise ValueError(f'the compiled backend factors 6 x 6 blocks, got {b} x {b}: use '
                         "method='banded' or 'dense'")
    factor, info = btd_cholesky(_kernel_array(diagonal), _kernel_array(upper))
    if info > 0:
        row = info - 1
        pivot = factor[row // 6, 0, row % 6, row % 6]
        if not np.isfinite(pivot):
            raise ValueError(f'compiled block Cholesky failed: non-finite pivot at row {row}')
        raise not_pd_error(row, b, pivot, 'compiled block Cholesky')

    def solver(rhs):
        x = np.array(rhs, dtype=np.float64, order='C')
        block_solve(factor, x)
        return x

    return BTDFactorization('compiled', (diagonal, upper), solver)


def choose_method(n_blocks, block_size=6):
    """
    Return the backend ``'auto'`` uses: ``'compiled'`` for 6 x 6 blocks at every size.

    It measured fastest at every n and number of right-hand sides of ``cbha_bench_core`` (see the
    module docstring), and it uses no BLAS, so the choice does not depend on BLAS threading;
    other block sizes take LAPACK's banded Cholesky.

    Parameters
    ----------
    n_blocks : int
        Number of diagonal blocks.
    block_size : int
        ``b``.

    Returns
    -------
    str

    """
    return 'compiled' if block_size == 6 else 'banded'


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


def _factor_dense(diagonal, upper):
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


def _factor_banded(diagonal, upper):
    """LAPACK banded Cholesky backend (dpbtrf / dpbtrs)."""
    factor = _band_cholesky(diagonal, upper)

    def solver(rhs):
        x, _ = lapack.dpbtrs(factor, rhs, lower=1)
        return x

    return BTDFactorization('banded', (diagonal, upper), solver)


_BACKENDS = {'compiled': _factor_compiled, 'dense': _factor_dense, 'banded': _factor_banded}


def factorize(diagonal, upper, method='auto', max_condition=None):
    """
    Factorise a symmetric positive definite block-tridiagonal matrix.

    Parameters
    ----------
    diagonal : (n, b, b) array_like
        Diagonal blocks (symmetric).
    upper : (n - 1, b, b) array_like
        ``upper[i]`` = block (i, i+1); block (i+1, i) is its transpose.
    method : {'auto', 'compiled', 'dense', 'banded'}
        Backend; 'auto' is 'compiled' for 6 x 6 blocks (see :func:`choose_method`).
    max_condition : float, optional
        If given, the condition estimate is computed at once and a larger one raises
        :class:`IllConditionedError` (otherwise it is computed on first access).

    Returns
    -------
    BTDFactorization
        With ``.solve(rhs)``, ``.condition_estimate`` and ``.method``.

    Raises
    ------
    NotPositiveDefiniteError
        If the matrix is not numerically positive definite (message names the block).
    IllConditionedError
        If ``max_condition`` is given and exceeded.
    ValueError
        On bad shapes, an unknown method, or non-finite entries (detected in the factor).

    """
    diagonal, upper = _check_blocks(diagonal, upper)
    if method == 'auto':
        method = choose_method(diagonal.shape[0], diagonal.shape[1])
    backend = _BACKENDS.get(method)
    if backend is None:
        raise ValueError(f'method must be one of {METHODS}, got {method!r}')
    factorization = backend(diagonal, upper)
    if max_condition is not None and not factorization.condition_estimate <= max_condition:
        raise IllConditionedError(
            f'block-tridiagonal matrix is ill-conditioned: 1-norm condition estimate '
            f'{factorization.condition_estimate:.3g} > {max_condition:.3g}')
    return factorization


def solve(diagonal, upper, rhs, method='auto'):
    """
    Solve ``A x = rhs`` for a symmetric positive definite block-tridiagonal A.

    Parameters
    ----------
    diagonal : (n, b, b) array_like
        Diagonal blocks.
    upper : (n - 1, b, b) array_like
        Blocks (i, i+1).
    rhs : (bn,) or (bn, k) array_like
        Right-hand side(s).
    method : str
        See :func:`factorize`.

    Returns
    -------
    ndarray
        Same shape as ``rhs``.

    """
    return factorize(diagonal, upper, method).solve(rhs)
