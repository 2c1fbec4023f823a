"""
Writing matrices into the block band of :mod:`cbha_inverse.core._kernels.block_band`.

:func:`add_link_block` adds a link's symmetric two-frame block into the block band,
:func:`scatter_add` and :func:`scatter_more` add assembled values into a storage by a constant
index (:class:`cbha_inverse.core.system.EquilibriumSystem` builds it), and
:func:`btd_cholesky` writes a symmetric block-tridiagonal matrix's block band from its blocks
and factors it.
"""

from cbha_inverse.core._kernels.block_band import block_cholesky, FRAME
import numba
import numpy as np


@numba.njit(cache=True, inline='always')
def add_link_block(blocks, link, block):
    """
    Add the symmetric 12 x 12 tangent of a link (frames ``a = link``, ``b = link + 1``).

    Of the block's lower triangle, the frame-``a`` block goes to ``blocks[a - 1, 0]``, the
    coupling block (rows of ``b``, columns of ``a``) to ``blocks[a - 1, 1]`` and the
    frame-``b`` block to ``blocks[b - 1, 0]`` (the mobile frames are numbered from 0); the
    base frame's rows and columns (``link`` 0) are left out.

    Parameters
    ----------
    blocks : (nb + 1, B + 1, 6, 6) ndarray
        Block band storage (module docstring of
        :mod:`~cbha_inverse.core._kernels.block_band`), added to.
    link : int
        The link.
    block : (12, 12) ndarray
        Its symmetric tangent (the lower triangle is read).

    """
    for i in range(FRAME):
        for j in range(i + 1):
            blocks[link, 0, i, j] += block[FRAME + i, FRAME + j]
    if link == 0:
        return
    for i in range(FRAME):
        for j in range(FRAME):
            blocks[link - 1, 1, i, j] += block[FRAME + i, j]
        for j in range(i + 1):
            blocks[link - 1, 0, i, j] += block[i, j]


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
    scatter_more(index, values, weights, out)


@numba.njit(cache=True)
def scatter_more(index, values, weights, out):
    """
    Add ``weights * values`` at ``index`` (:func:`scatter_add` without zeroing ``out``).

    Parameters
    ----------
    index : (V,) int ndarray
        Slot of every value in ``out``.
    values, weights : (V,) ndarray
        Values and their weights.
    out : (S,) ndarray
        Added to.

    """
    for i in range(index.size):
        out[index[i]] += weights[i] * values[i]


@numba.njit(cache=True)
def btd_cholesky(diagonal, upper):
    """
    Write a symmetric block-tridiagonal matrix's block band and factor it, ``K = L Lᵀ``.

    Block ``c`` of the band holds ``D_c`` and ``U_cᵀ`` (block (c + 1, c) is the transpose of the
    upper block (c, c + 1)); :func:`~cbha_inverse.core._kernels.block_band.block_cholesky`
    factors it in place.

    Parameters
    ----------
    diagonal : (n, 6, 6) ndarray
        Diagonal blocks (only their lower triangles are read).
    upper : (n - 1, 6, 6) ndarray
        Blocks (c, c + 1).

    Returns
    -------
    factor : (n, 2, 6, 6) ndarray
        ``L`` in block band storage.
    info : int
        0 on success, else ``6 c + j + 1`` for the first unknown whose pivot is not positive (or
        not finite); ``factor`` is then partly overwritten.

    """
    n = diagonal.shape[0]
    blocks = np.zeros((n, 2, FRAME, FRAME))
    for c in range(n):
        for i in range(FRAME):
            for j in range(FRAME):
                blocks[c, 0, i, j] = diagonal[c, i, j]
                if c + 1 < n:
                    blocks[c, 1, i, j] = upper[c, j, i]
    return blocks, block_cholesky(blocks)
