"""
Compiled block Cholesky of symmetric matrices made of 6 x 6 frame blocks, and its sweeps.

The symmetric tangent of a frame chain couples the six increments of a frame with those of its
neighbours (paper Sec. III): it is block-banded with 6 x 6 blocks, block-tridiagonal when every
link and actuator acts between adjacent frames, with ``B`` blocks below the diagonal when a
cable spans ``B`` links. Storage (the *block band*)::

    blocks[c, d] = K_(c + d, c)      c = 0 ... nb - 1, d = 0 ... B      (nb, B + 1, 6, 6)

the block of frames ``c + d`` (rows) and ``c`` (columns) of the mobile frames; of a diagonal
block ``blocks[c, 0]`` the lower triangle alone is read and written. The block Cholesky
factorisation ``K = L Lᵀ`` (:func:`block_cholesky`) overwrites it with ``L``'s blocks, column of
blocks by column of blocks (of each diagonal block ``L_cc``, the diagonal holds the reciprocals
``1 / L_ii``: the sweeps multiply by them):

    L_cc = chol(K_cc),   L_(c+d, c) = K_(c+d, c) L_cc⁻ᵀ,
    K_(c+e, c+d) -= L_(c+e, c) L_(c+d, c)ᵀ        (1 <= d <= e <= B)

and the sweeps solve ``L Y = R`` (:func:`block_forward`) and ``Lᵀ X = Y``
(:func:`block_backward`) block row by block row. Every inner loop runs over a block's six rows or
columns (a compile-time constant: the loops unroll); the cost is O(nb B²) blocks.
"""

import math

import numba
import numpy as np

FRAME = 6
"""Unknowns of a frame (three translations, three rotations): the size of a block."""


@numba.njit(cache=True, inline='always')
def factor_diagonal_block(block):
    """
    Factor a 6 x 6 block in place, ``K_cc = L_cc L_ccᵀ`` (its lower triangle read and written).

    The diagonal receives the reciprocals ``1 / L_jj`` (module docstring).

    Returns
    -------
    int
        0, or ``j + 1`` for the first column whose pivot is not positive (or not finite); that
        pivot is then left in ``block[j, j]``.

    """
    for j in range(FRAME):
        pivot = block[j, j]
        for k in range(j):
            pivot -= block[j, k] * block[j, k]
        if not (pivot > 0.0 and math.isfinite(pivot)):
            block[j, j] = pivot
            return j + 1
        inverse = 1.0 / math.sqrt(pivot)
        block[j, j] = inverse
        for i in range(j + 1, FRAME):
            value = block[i, j]
            for k in range(j):
                value -= block[i, k] * block[j, k]
            block[i, j] = value * inverse
    return 0


@numba.njit(cache=True, inline='always')
def solve_right_transposed(block, factor):
    """
    Replace ``X = block`` (6 x 6) by ``X L⁻ᵀ``, ``L = factor`` lower triangular, in place.

    ``factor`` holds ``1 / L_jj`` on its diagonal (:func:`factor_diagonal_block`).
    """
    for j in range(FRAME):
        inverse = factor[j, j]
        for i in range(FRAME):
            value = block[i, j]
            for k in range(j):
                value -= factor[j, k] * block[i, k]
            block[i, j] = value * inverse


@numba.njit(cache=True, inline='always')
def subtract_product(target, left, right, lower):
    """``target -= left rightᵀ`` (6 x 6 blocks); its lower triangle alone with ``lower``."""
    for i in range(FRAME):
        for j in range(i + 1 if lower else FRAME):
            value = 0.0
            for k in range(FRAME):
                value += left[i, k] * right[j, k]
            target[i, j] -= value


@numba.njit(cache=True)
def block_cholesky(blocks):
    """
    Factor a symmetric positive definite block band in place, ``K = L Lᵀ`` (module docstring).

    Parameters
    ----------
    blocks : (nb, B + 1, 6, 6) ndarray
        The block band (module docstring), overwritten by ``L``.

    Returns
    -------
    int
        0 on success, else ``6 c + j + 1`` for the first unknown whose pivot is not positive (or
        not finite): column ``j`` of block ``c``, whose pivot is left in ``blocks[c, 0, j, j]``;
        ``blocks`` is then partly overwritten.

    """
    return block_cholesky_forward(blocks, np.empty((blocks.shape[0] * FRAME, 0)),
                                  np.empty(0, dtype=np.int64))


@numba.njit(cache=True)
def block_cholesky_forward(blocks, rhs, starts):
    """
    Factor a block band, ``K = L Lᵀ``, and sweep right-hand sides forward, ``rhs <- L⁻¹ rhs``.

    The sweep of block row ``c`` follows the factorisation of block column ``c``, while its
    blocks are in cache. A right-hand side zero above some row stays zero there (``L`` is lower
    triangular): its sweep starts at that row's block.

    Parameters
    ----------
    blocks : (nb, B + 1, 6, 6) ndarray
        The block band (overwritten by ``L``).
    rhs : (6 nb, k) ndarray
        Right-hand sides (C order, ``k`` may be 0), overwritten by ``L⁻¹ rhs`` when the result
        is 0 (else partly).
    starts : (k,) int ndarray
        The first row of each right-hand side that may be nonzero
        (:func:`first_nonzero_rows`).

    Returns
    -------
    int
        As :func:`block_cholesky`.

    """
    n_blocks, width = blocks.shape[0], blocks.shape[1]
    for c in range(n_blocks):
        info = factor_diagonal_block(blocks[c, 0])
        if info != 0:
            return FRAME * c + info
        below = min(width - 1, n_blocks - 1 - c)
        for d in range(1, below + 1):
            solve_right_transposed(blocks[c, d], blocks[c, 0])
        for d in range(1, below + 1):
            for e in range(d, below + 1):
                subtract_product(blocks[c + d, e - d], blocks[c, e], blocks[c, d], d == e)
        forward_block_row(blocks, rhs, c, starts)
    return 0


@numba.njit(cache=True)
def first_nonzero_rows(rhs, starts):
    """Write the first nonzero row of each column of ``rhs`` into ``starts`` (its rows if none)."""
    size = rhs.shape[0]
    for col in range(rhs.shape[1]):
        row = 0
        while row < size and rhs[row, col] == 0.0:
            row += 1
        starts[col] = row


@numba.njit(cache=True, inline='always')
def forward_block_row(factor, rhs, c, starts):
    """
    Block row ``c`` of the forward sweep: ``Y_c = L_cc⁻¹ R_c``, then ``R_(c+d) -= L_(c+d, c) Y_c``.

    Right-hand side by right-hand side (the products run over the block's six rows and
    columns); one zero down to this block's end (``starts``) is left as it is.
    """
    row = FRAME * c
    below = min(factor.shape[1] - 1, factor.shape[0] - 1 - c)
    for col in range(rhs.shape[1]):
        if row + FRAME <= starts[col]:
            continue
        for i in range(FRAME):
            value = rhs[row + i, col]
            for k in range(i):
                value -= factor[c, 0, i, k] * rhs[row + k, col]
            rhs[row + i, col] = value * factor[c, 0, i, i]
        for d in range(1, below + 1):
            target = row + FRAME * d
            for i in range(FRAME):
                value = 0.0
                for k in range(FRAME):
                    value += factor[c, d, i, k] * rhs[row + k, col]
                rhs[target + i, col] -= value


@numba.njit(cache=True)
def block_forward(factor, rhs, starts):
    """
    Solve ``L Y = rhs`` in place with a factor of :func:`block_cholesky` (the forward sweep).

    With ``K = L Lᵀ`` the control tick needs only these half-solves for its projection
    (``(L⁻¹ a)ᵀ (L⁻¹ b) = aᵀ K⁻¹ b``, `docs/design.md`); :func:`block_backward` completes a
    solve.

    Parameters
    ----------
    factor : (nb, B + 1, 6, 6) ndarray
        ``L`` in block band storage.
    rhs : (6 nb, k) ndarray
        Right-hand sides (C order), overwritten by ``Y``.
    starts : (k,) int ndarray
        The first row of each right-hand side that may be nonzero (its sweep starts at that
        row's block; :func:`first_nonzero_rows`).

    """
    for c in range(factor.shape[0]):
        forward_block_row(factor, rhs, c, starts)


@numba.njit(cache=True)
def block_backward(factor, rhs):
    """
    Solve ``Lᵀ X = rhs`` in place with a factor of :func:`block_cholesky` (the backward sweep).

    Completes :func:`block_forward`: ``X = K⁻¹ b`` from ``rhs = L⁻¹ b``, block row by block row
    from the last: ``X_c = L_ccᵀ⁻¹ (Y_c - Σ_d L_(c+d, c)ᵀ X_(c+d))``.

    Parameters
    ----------
    factor : (nb, B + 1, 6, 6) ndarray
        ``L`` in block band storage.
    rhs : (6 nb, k) ndarray
        ``L⁻¹ b`` (C order), overwritten by ``X``.

    """
    n_blocks, width = factor.shape[0], factor.shape[1]
    for c in range(n_blocks - 1, -1, -1):
        row = FRAME * c
        below = min(width - 1, n_blocks - 1 - c)
        for col in range(rhs.shape[1]):
            for d in range(1, below + 1):
                source = row + FRAME * d
                for k in range(FRAME):
                    value = 0.0
                    for i in range(FRAME):
                        value += factor[c, d, i, k] * rhs[source + i, col]
                    rhs[row + k, col] -= value
            for i in range(FRAME - 1, -1, -1):
                value = rhs[row + i, col]
                for k in range(i + 1, FRAME):
                    value -= factor[c, 0, k, i] * rhs[row + k, col]
                rhs[row + i, col] = value * factor[c, 0, i, i]


@numba.njit(cache=True)
def block_solve(factor, rhs):
    """
    Solve ``L Lᵀ X = rhs`` in place: :func:`block_forward` then :func:`block_backward`.

    Parameters
    ----------
    factor : (nb, B + 1, 6, 6) ndarray
        ``L`` in block band storage.
    rhs : (6 nb, k) ndarray
        Right-hand sides (C order), overwritten by ``X``.

    """
    block_forward(factor, rhs, np.zeros(rhs.shape[1], dtype=np.int64))
    block_backward(factor, rhs)
