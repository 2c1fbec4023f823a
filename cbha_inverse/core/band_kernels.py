"""
Compiled (numba) Cholesky factorisation and multi-RHS solve of symmetric band matrices.

Storage is LAPACK's lower band layout in C order, ``band[c, r - c] = K[r, c]`` for
``0 <= r - c <= kd`` (an (N, kd + 1) array: the Fortran (kd + 1, N) array of ``dpbtrf``). The
factorisation is right-looking, as LAPACK's unblocked ``dpbtf2``: every innermost loop is an axpy
over contiguous memory. For the small systems of a control tick (N ≤ ~100, kd ≤ ~20) it costs a few
microseconds, less than the call overhead of the LAPACK wrappers.
"""

import math

import numba


@numba.njit(cache=True)
def band_cholesky(band):
    """
    Factor a symmetric positive definite band matrix in place, ``K = L Lᵀ`` (as LAPACK dpbtf2).

    Right-looking: each column of ``L`` is scaled, then the trailing block takes its rank-one
    update; the innermost loop is an axpy over contiguous memory (no loop-carried dependency).

    Parameters
    ----------
    band : (N, kd + 1) ndarray
        Lower band storage, ``band[c, r - c] = K[r, c]`` for ``0 <= r - c <= kd`` (C order: the
        Fortran ``(kd + 1, N)`` layout of LAPACK; entries past the matrix end are ignored);
        overwritten by ``L`` in the same layout.

    Returns
    -------
    int
        0 on success, else ``j + 1`` for the first column whose pivot is not positive (or not
        finite); ``band`` is then partly overwritten.

    """
    size, width = band.shape
    kd = width - 1
    for j in range(size):
        column = band[j]
        pivot = column[0]
        if not (pivot > 0.0 and math.isfinite(pivot)):
            return j + 1
        diagonal = math.sqrt(pivot)
        column[0] = diagonal
        below = min(kd, size - 1 - j)
        inverse = 1.0 / diagonal
        for a in range(1, below + 1):
            column[a] *= inverse
        for b in range(1, below + 1):
            weight = column[b]
            target = band[j + b]
            for a in range(b, below + 1):
                target[a - b] -= column[a] * weight
    return 0


@numba.njit(cache=True)
def band_solve(factor, rhs):
    """
    Solve ``L Lᵀ X = rhs`` in place with a factor of :func:`band_cholesky`.

    Parameters
    ----------
    factor : (N, kd + 1) ndarray
        ``L`` in lower band storage.
    rhs : (N, c) ndarray
        Right-hand sides (C order), overwritten by ``X``.

    """
    size, width = factor.shape
    kd = width - 1
    n_rhs = rhs.shape[1]
    for j in range(size):
        inverse = 1.0 / factor[j, 0]
        for col in range(n_rhs):
            rhs[j, col] *= inverse
        for a in range(1, min(kd, size - 1 - j) + 1):
            weight = factor[j, a]
            for col in range(n_rhs):
                rhs[j + a, col] -= weight * rhs[j, col]
    for j in range(size - 1, -1, -1):
        for a in range(1, min(kd, size - 1 - j) + 1):
            weight = factor[j, a]
            for col in range(n_rhs):
                rhs[j, col] -= weight * rhs[j + a, col]
        inverse = 1.0 / factor[j, 0]
        for col in range(n_rhs):
            rhs[j, col] *= inverse
