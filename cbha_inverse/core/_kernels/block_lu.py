"""
Compiled LU factorisation of non-symmetric matrices made of 6 x 6 frame blocks, and its solve.

The exact tangent of the equilibrium is not symmetric (follower loads, geometric terms), but
it couples the frames as its symmetric part does (:mod:`cbha_inverse.core._kernels.block_band`):
block-banded with ``B`` blocks on either side of the diagonal. Storage::

    blocks[c, B + d] = K_(c + d, c)      c = 0 ... nb - 1, d = -B ... B      (nb, 2B + 1, 6, 6)

the block of frames ``c + d`` (rows) and ``c`` (columns). Newton's method factors it by block
LU, ``K = L U`` (:func:`block_lu`), column of blocks by column of blocks: the diagonal block by
LU with row interchanges within it, ``P_c D_c = L_c U_c``, then

    U_(c, c+e) = L_c⁻¹ P_c K_(c, c+e),   L_(c+d, c) = K_(c+d, c) U_c⁻¹,
    K_(c+d, c+e) -= L_(c+d, c) U_(c, c+e)        (1 <= d, e <= B)

Rows are interchanged within a diagonal block only: the tangent's symmetric part is positive
definite near a stable equilibrium, where elimination without interchanges is stable; a pivot
that vanishes (a limit point) fails the factorisation, and the static solver's fallback chain
takes the material tangent instead.
"""

import math

import numba

FRAME = 6
"""Unknowns of a frame: the size of a block."""


@numba.njit(cache=True, inline='always')
def factor_diagonal_block(blocks, c, centre, pivots):
    """
    Factor the diagonal block ``D = blocks[c, centre]`` in place, ``P D = L U`` (6 x 6).

    ``L`` (unit lower) and ``U`` overwrite ``D``; ``pivots[c, j]`` receives the row swapped with
    row ``j``. Returns 0, or ``j + 1`` for the first column whose pivot is zero or not finite.
    """
    for j in range(FRAME):
        pivot, largest = j, abs(blocks[c, centre, j, j])
        for i in range(j + 1, FRAME):
            value = abs(blocks[c, centre, i, j])
            if value > largest:
                pivot, largest = i, value
        pivots[c, j] = pivot
        if not (largest > 0.0 and math.isfinite(largest)):
            return j + 1
        if pivot != j:
            for k in range(FRAME):
                value = blocks[c, centre, j, k]
                blocks[c, centre, j, k] = blocks[c, centre, pivot, k]
                blocks[c, centre, pivot, k] = value
        inverse = 1.0 / blocks[c, centre, j, j]
        for i in range(j + 1, FRAME):
            blocks[c, centre, i, j] *= inverse
            weight = blocks[c, centre, i, j]
            for k in range(j + 1, FRAME):
                blocks[c, centre, i, k] -= weight * blocks[c, centre, j, k]
    return 0


@numba.njit(cache=True)
def block_lu(blocks, pivots):
    """
    Factor a block-banded matrix in place, ``K = L U`` (module docstring).

    Parameters
    ----------
    blocks : (nb, 2B + 1, 6, 6) ndarray
        The blocks (module docstring), overwritten by those of ``L`` and ``U``.
    pivots : (nb, 6) int ndarray
        Receives the row interchanges within each diagonal block.

    Returns
    -------
    int
        0 on success, else ``6 c + j + 1`` for the first unknown whose pivot is zero or not
        finite (column ``j`` of block ``c``); ``blocks`` is then partly overwritten.

    """
    n_blocks, width = blocks.shape[0], blocks.shape[1]
    centre = width // 2
    for c in range(n_blocks):
        info = factor_diagonal_block(blocks, c, centre, pivots)
        if info != 0:
            return FRAME * c + info
        reach = min(centre, n_blocks - 1 - c)
        for e in range(1, reach + 1):
            # U_(c, c+e) = L_c⁻¹ P_c K_(c, c+e): block (c, c + e) is blocks[c + e, centre - e]
            right = centre - e
            for j in range(FRAME):
                pivot = pivots[c, j]
                if pivot != j:
                    for k in range(FRAME):
                        value = blocks[c + e, right, j, k]
                        blocks[c + e, right, j, k] = blocks[c + e, right, pivot, k]
                        blocks[c + e, right, pivot, k] = value
            for k in range(FRAME):
                for i in range(FRAME):
                    value = blocks[c + e, right, i, k]
                    for j in range(i):
                        value -= blocks[c, centre, i, j] * blocks[c + e, right, j, k]
                    blocks[c + e, right, i, k] = value
        for d in range(1, reach + 1):
            # L_(c+d, c) = K_(c+d, c) U_c⁻¹, row by row: x U = a
            for i in range(FRAME):
                for j in range(FRAME):
                    value = blocks[c, centre + d, i, j]
                    for k in range(j):
                        value -= blocks[c, centre + d, i, k] * blocks[c, centre, k, j]
                    blocks[c, centre + d, i, j] = value / blocks[c, centre, j, j]
        for d in range(1, reach + 1):
            for e in range(1, reach + 1):
                # K_(c+d, c+e) -= L_(c+d, c) U_(c, c+e), block (c + d, c + e)
                target = centre + d - e
                for i in range(FRAME):
                    for k in range(FRAME):
                        value = 0.0
                        for j in range(FRAME):
                            value += blocks[c, centre + d, i, j] * blocks[c + e, centre - e, j, k]
                        blocks[c + e, target, i, k] -= value
    return 0


@numba.njit(cache=True)
def block_lu_solve(factor, pivots, rhs):
    """
    Solve ``K X = rhs`` in place with a factor of :func:`block_lu`.

    Forward, block row by block row: ``Y_c = L_c⁻¹ P_c (R_c - Σ_d L_(c, c-d) Y_(c-d))``; then
    backward: ``X_c = U_c⁻¹ (Y_c - Σ_e U_(c, c+e) X_(c+e))``.

    Parameters
    ----------
    factor : (nb, 2B + 1, 6, 6) ndarray
        ``L`` and ``U`` (:func:`block_lu`).
    pivots : (nb, 6) int ndarray
        The row interchanges.
    rhs : (6 nb, k) ndarray
        Right-hand sides (C order), overwritten by ``X``.

    """
    n_blocks, width = factor.shape[0], factor.shape[1]
    centre = width // 2
    n_rhs = rhs.shape[1]
    for c in range(n_blocks):
        row = FRAME * c
        for d in range(1, min(centre, c) + 1):
            # L_(c, c-d) is blocks[c - d, centre + d]
            source = row - FRAME * d
            for i in range(FRAME):
                for j in range(FRAME):
                    weight = factor[c - d, centre + d, i, j]
                    for col in range(n_rhs):
                        rhs[row + i, col] -= weight * rhs[source + j, col]
        for j in range(FRAME):
            pivot = pivots[c, j]
            if pivot != j:
                for col in range(n_rhs):
                    value = rhs[row + j, col]
                    rhs[row + j, col] = rhs[row + pivot, col]
                    rhs[row + pivot, col] = value
        for i in range(FRAME):
            for j in range(i):
                weight = factor[c, centre, i, j]
                for col in range(n_rhs):
                    rhs[row + i, col] -= weight * rhs[row + j, col]
    for c in range(n_blocks - 1, -1, -1):
        row = FRAME * c
        for e in range(1, min(centre, n_blocks - 1 - c) + 1):
            # U_(c, c+e) is blocks[c + e, centre - e]
            source = row + FRAME * e
            for i in range(FRAME):
                for j in range(FRAME):
                    weight = factor[c + e, centre - e, i, j]
                    for col in range(n_rhs):
                        rhs[row + i, col] -= weight * rhs[source + j, col]
        for i in range(FRAME - 1, -1, -1):
            for j in range(i + 1, FRAME):
                weight = factor[c, centre, i, j]
                for col in range(n_rhs):
                    rhs[row + i, col] -= weight * rhs[row + j, col]
            inverse = 1.0 / factor[c, centre, i, i]
            for col in range(n_rhs):
                rhs[row + i, col] *= inverse
