"""
Writing symmetric matrices into the lower band storage of :mod:`cbha_inverse.core._kernels.band`.

:func:`scatter_add` and :func:`scatter_more` add the assembled blocks of a tick into the band by
a constant index (:class:`cbha_inverse.core.system.EquilibriumSystem`), :func:`band_rows` views
an assembly buffer without its trash row, and :func:`btd_band_cholesky` writes a symmetric
block-tridiagonal matrix's band from its blocks and factors it.
"""

from cbha_inverse.core._kernels.band import band_cholesky
import numba
import numpy as np


@numba.njit(cache=True)
def btd_band_cholesky(diagonal, upper):
    """
    Build the lower band of a symmetric block-tridiagonal matrix and factor it, ``K = L Lᵀ``.

    The band (half-bandwidth ``kd = 2b - 1``) is written straight from the blocks: row
    ``c = k b + i`` (block k, component i) holds ``D_k[i, i:]`` at offsets ``0 ... b - 1 - i``
    and ``U_k[i, :]`` (block (k+1, k) is ``U_kᵀ``) at offsets ``b - i ... 2b - 1 - i``; its last
    ``i`` slots are zero (Cholesky creates no fill there). Then it is factored in place by
    :func:`band_cholesky` (constant trip counts for b = 6).

    Parameters
    ----------
    diagonal : (n, b, b) ndarray
        Diagonal blocks (C order; only their upper triangles are read).
    upper : (n - 1, b, b) ndarray
        Blocks (k, k+1) (C order).

    Returns
    -------
    factor : (n b, 2b) ndarray
        ``L`` in the lower band storage of :func:`band_cholesky`, ``factor[c, r - c] = L[r, c]``.
    info : int
        0 on success, else ``j + 1`` for the first column whose pivot is not positive (or not
        finite); ``factor[j, 0]`` is then that pivot and ``factor`` is partly overwritten.

    """
    n, b = diagonal.shape[0], diagonal.shape[1]
    band = np.zeros((n * b, 2 * b))
    for k in range(n):
        for i in range(b):
            row = band[k * b + i]
            for m in range(i, b):
                row[m - i] = diagonal[k, i, m]
            if k + 1 < n:
                for m in range(b):
                    row[b - i + m] = upper[k, i, m]
    return band, band_cholesky(band)


@numba.njit(cache=True)
def band_rows(band, size):
    """
    Return the lower band storage of an assembly buffer without its trash row (a view).

    Parameters
    ----------
    band : ((size + 1) (kd + 1),) ndarray
        The symmetric lower band of ``size`` rows in C order, then one row of ``kd + 1`` slots
        that the assembly's base-frame entries are added into (``scatter_add``'s trash).
    size : int
        Unknowns ``N``.

    Returns
    -------
    (N, kd + 1) ndarray
        ``band[c, r - c] = K[r, c]`` (:func:`band_cholesky`), sharing ``band``'s memory.

    """
    width = band.size // (size + 1)
    return band[:size * width].reshape((size, width))


@numba.njit(cache=True)
def scatter_add(index, values, weights, out):
    """
    Zero ``out`` and add ``weights * values`` at ``index`` (a compiled ``np.bincount``).

    Parameters
    ----------
    index, values, weights
        As :func:`scatter_more`.
    out : (S,) ndarray
        Zeroed, then receives the sums.

    """
    out[:] = 0.0
    scatter_more(index, values, weights, out, 0)


@numba.njit(cache=True)
def scatter_more(index, values, weights, out, first):
    """
    Add ``weights * values`` at ``index`` from value ``first`` on (:func:`scatter_add` unzeroed).

    Parameters
    ----------
    index : (V,) int ndarray
        Slot of every value in ``out``.
    values, weights : (V,) ndarray
        Values and their weights.
    out : (S,) ndarray
        Added to.
    first : int
        The values before it are left out.

    """
    for i in range(first, index.size):
        out[index[i]] += weights[i] * values[i]
