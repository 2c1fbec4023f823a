"""
Factors of a tangent stiffness ``K``, all with one protocol: ``solve(rhs)`` and ``method``.

The equilibrium evaluator (:class:`cbha_inverse.core.system.EquilibriumSystem`) factors its
tangents into these: :class:`BlockCholesky` (the symmetric block band of the control tick and
the material one of the fallback), :class:`BlockLU` (the exact, non-symmetric tangent of
Newton's method), both compiled (:mod:`cbha_inverse.core._kernels.block_band`,
:mod:`cbha_inverse.core._kernels.block_lu`), and :class:`DenseLU` (an exact tangent with a user
load stiffness). The control tick, Newton's method and the static checks use them through
:class:`TangentFactor` alone.
"""

from cbha_inverse.core._kernels.block_band import block_solve
from cbha_inverse.core._kernels.block_lu import block_lu_solve
from cbha_inverse.core._kernels.records import compiled_entry
import numpy as np


class TangentFactor:
    """
    A factorised tangent ``K`` (the protocol of every factor): ``solve`` and ``method``.

    Attributes
    ----------
    method : str
        ``'block_cholesky'``, ``'block_lu'`` or ``'dense_lu'``.

    """

    method = ''

    def solve(self, rhs):
        """
        Solve ``K X = rhs`` (all columns in one pass).

        Parameters
        ----------
        rhs : (N,) or (N, c) ndarray
            Right-hand sides (not modified).

        Returns
        -------
        ndarray
            Same shape as ``rhs`` (C order).

        Raises
        ------
        numpy.linalg.LinAlgError
            If the solve fails (a singular dense tangent).

        """
        rhs = np.asarray(rhs, dtype=float)
        if rhs.ndim == 2:
            return self._solve(rhs)
        return self._solve(rhs.reshape(rhs.shape[0], -1)).reshape(rhs.shape)

    def _solve(self, columns):
        """Return ``K⁻¹ columns`` (N, c), C order."""
        raise NotImplementedError


class BlockCholesky(TangentFactor):
    """
    Block Cholesky factor ``L`` of a symmetric block band tangent (compiled kernels).

    Parameters
    ----------
    factor : (n, B + 1, 6, 6) ndarray
        ``L`` in the block band storage of
        :meth:`cbha_inverse.core.system.EquilibriumSystem.linearise` (a buffer of the system:
        valid until its next evaluation).

    """

    method = 'block_cholesky'

    def __init__(self, factor):
        """Keep the factor."""
        self._factor = factor

    def _solve(self, columns):
        """Solve with the compiled block Cholesky's forward and backward sweeps."""
        solved = np.array(columns, dtype=float, order='C')
        _entry(block_solve, self._factor, solved)(self._factor, solved)
        return solved


class BlockLU(TangentFactor):
    """
    LU factor of a tangent of frame blocks (:func:`cbha_inverse.core._kernels.block_lu.block_lu`).

    Parameters
    ----------
    factor : (n, 2B + 1, 6, 6) ndarray
        ``L`` and ``U`` in the block storage of
        :meth:`cbha_inverse.core.system.EquilibriumSystem.exact_system` (a buffer of the
        system: valid until its next factorisation).
    pivots : (n, 6) int ndarray
        Row interchanges within the diagonal blocks.

    """

    method = 'block_lu'

    def __init__(self, factor, pivots):
        """Keep the factor."""
        self._factor, self._pivots = factor, pivots

    def _solve(self, columns):
        """Solve with the compiled block LU's forward and backward sweeps."""
        solved = np.array(columns, dtype=float, order='C')
        _entry(block_lu_solve, self._factor, self._pivots, solved)(self._factor, self._pivots,
                                                                   solved)
        return solved


_ENTRIES = {}


def _entry(kernel, *arguments):
    """
    Return a kernel's compiled entry for its arguments' types, without numba's type dispatch.

    The factors' arrays are C-ordered float and int arrays of fixed dimensions, and the solves
    C-ordered float columns: one entry per kernel and dimensions
    (:func:`cbha_inverse.core._kernels.records.compiled_entry`).
    """
    key = (kernel,) + tuple((a.dtype.char, a.ndim, a.flags.c_contiguous, a.flags.writeable)
                            for a in arguments)
    entry = _ENTRIES.get(key)
    if entry is None:
        entry = _ENTRIES[key] = compiled_entry(kernel, *arguments)
    return entry


class DenseLU(TangentFactor):
    """
    A dense tangent solved by LU (``numpy.linalg.solve``, factored at each solve).

    The exact tangent plus a user load stiffness, which has no band structure; the static
    solver solves it once per Newton step.

    Parameters
    ----------
    matrix : (N, N) ndarray
        The tangent.

    """

    method = 'dense_lu'

    def __init__(self, matrix):
        """Keep the matrix."""
        self._matrix = matrix

    def _solve(self, columns):
        """Solve with ``numpy.linalg.solve`` (raises ``LinAlgError`` if singular)."""
        return np.ascontiguousarray(np.linalg.solve(self._matrix, columns))
