"""
Compiled LU factorisation with partial pivoting of general band matrices, and its solve.

The exact tangent of the equilibrium is not symmetric (follower loads, geometric terms), so
Newton's method factors it by LU with row interchanges, as LAPACK's ``dgbtf2``. Storage is
LAPACK's general band layout in C order, ``lu[c, kv + r - c] = A[r, c]`` for ``-ku <= r - c <= kl``
with ``kv = kl + ku``: an (N, 2 kl + ku + 1) array, the Fortran ``(2 kl + ku + 1, N)`` array of
``dgbtrf``, whose first ``kl`` slots of every column receive the fill of the interchanges.

As :mod:`cbha_inverse.core._kernels.band` does for Cholesky, the loops run over the part of each
row and column that can hold a nonzero: a row's *upper reach* (its last nonzero column) and a
column's *lower reach* (its last nonzero row) start from the matrix's own nonzeros and grow with
the fill of every elimination step and interchange. Entries outside them are zeros whose updates
change nothing.
"""

import math

import numba


@numba.njit(cache=True)
def band_lu(lu, kl, pivots, lower_reach, upper_reach):
    """
    Factor a general band matrix in place, ``P A = L U`` (partial pivoting, as LAPACK dgbtf2).

    Parameters
    ----------
    lu : (N, 2 kl + ku + 1) ndarray
        ``A`` in general band storage (module docstring; its first ``kl`` slots of every row of
        the storage are ignored and overwritten), overwritten by ``L`` (unit lower, below the
        diagonal) and ``U``.
    kl : int
        Subdiagonals of ``A`` (the superdiagonals are ``ku = lu.shape[1] - 2 kl - 1``).
    pivots : (N,) int ndarray
        Receives the interchanges: row ``j`` was swapped with row ``pivots[j] >= j``.
    lower_reach : (N,) int ndarray
        Receives the last row of every column of ``L`` that can be nonzero.
    upper_reach : (N,) int ndarray
        Workspace: the last column of every row that can be nonzero.

    Returns
    -------
    int
        0 on success, else ``j + 1`` for the first column whose pivot is zero or not finite (the
        matrix is singular or not finite; ``lu`` is then partly overwritten).

    """
    size, width = lu.shape
    kv = width - 1 - kl
    ku = kv - kl
    for c in range(size):
        for slot in range(kl):
            lu[c, slot] = 0.0
    for j in range(size):
        last = min(size - 1, j + kl)
        while last > j and lu[j, kv + last - j] == 0.0:
            last -= 1
        lower_reach[j] = last
        end = min(size - 1, j + ku)
        while end > j and lu[end, kv + j - end] == 0.0:
            end -= 1
        upper_reach[j] = end
    for j in range(size):
        last = lower_reach[j]
        pivot, largest = j, abs(lu[j, kv])
        for r in range(j + 1, last + 1):
            value = abs(lu[j, kv + r - j])
            if value > largest:
                pivot, largest = r, value
        pivots[j] = pivot
        if not (largest > 0.0 and math.isfinite(largest)):
            return j + 1
        if pivot != j:
            end = max(upper_reach[j], upper_reach[pivot])
            for c in range(j, end + 1):
                value = lu[c, kv + j - c]
                lu[c, kv + j - c] = lu[c, kv + pivot - c]
                lu[c, kv + pivot - c] = value
            upper_reach[j] = end
            upper_reach[pivot] = end
        inverse = 1.0 / lu[j, kv]
        for r in range(j + 1, last + 1):
            lu[j, kv + r - j] *= inverse
        end = upper_reach[j]
        for c in range(j + 1, end + 1):
            weight = lu[c, kv + j - c]
            if weight != 0.0:
                for r in range(j + 1, last + 1):
                    lu[c, kv + r - c] -= lu[j, kv + r - j] * weight
            lower_reach[c] = max(lower_reach[c], last)
        for r in range(j + 1, last + 1):
            upper_reach[r] = max(upper_reach[r], end)
    return 0


@numba.njit(cache=True)
def band_lu_solve(lu, kl, pivots, lower_reach, rhs):
    """
    Solve ``A X = rhs`` in place with a factor of :func:`band_lu` (as LAPACK dgbtrs).

    Parameters
    ----------
    lu : (N, 2 kl + ku + 1) ndarray
        The factor.
    kl : int
        Subdiagonals of ``A``.
    pivots, lower_reach : (N,) int ndarray
        From :func:`band_lu`.
    rhs : (N, c) ndarray
        Right-hand sides (C order), overwritten by ``X``.

    """
    size, width = lu.shape
    kv = width - 1 - kl
    n_rhs = rhs.shape[1]
    for j in range(size):
        pivot = pivots[j]
        if pivot != j:
            for col in range(n_rhs):
                value = rhs[j, col]
                rhs[j, col] = rhs[pivot, col]
                rhs[pivot, col] = value
        for r in range(j + 1, lower_reach[j] + 1):
            weight = lu[j, kv + r - j]
            for col in range(n_rhs):
                rhs[r, col] -= weight * rhs[j, col]
    for j in range(size - 1, -1, -1):
        inverse = 1.0 / lu[j, kv]
        for col in range(n_rhs):
            rhs[j, col] *= inverse
        for r in range(max(0, j - kv), j):
            weight = lu[j, kv + r - j]
            if weight != 0.0:
                for col in range(n_rhs):
                    rhs[r, col] -= weight * rhs[j, col]
