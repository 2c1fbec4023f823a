"""
Factors of a tangent stiffness ``K``, all with one protocol: ``solve(rhs)`` and ``method``.

The equilibrium evaluator (:class:`cbha_inverse.core.system.EquilibriumSystem`) factors its
tangents into these: :class:`BlockCholesky` (the symmetric block band of the control tick and
the material one of the fallback), :class:`BandLU` (the exact, non-symmetric band of Newton's
method), both compiled (:mod:`cbha_inverse.core._kernels.block_band`,
:mod:`cbha_inverse.core._kernels.band_lu`), and :class:`DenseLU` (an exact tangent with a user
load stiffness). The control tick, Newton's method and the static checks use them through
:class:`TangentFactor` alone.
"""

from cbha_inverse.core._kernels.block_band import block_solve
from cbha_inverse.core._kernels.band_lu import band_lu_solve
import numpy as np


class TangentFactor:
    """
    A factorised tangent ``K`` (the protocol of every factor): ``solve`` and ``method``.

    Attributes
    ----------
    method : str
        ``'block_cholesky'``, ``'band_lu'`` or ``'dense_lu'``.

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

    def solve(self, rhs):
        """Solve ``K X = rhs`` as :meth:`TangentFactor.solve` (the tick's path: one copy)."""
        solved = np.array(rhs, dtype=float, order='C')
        block_solve(self._factor, solved if solved.ndim == 2
                    else solved.reshape(solved.shape[0], -1))
        return solved


class BandLU(TangentFactor):
    """
    LU factor of a general band matrix (:func:`cbha_inverse.core._kernels.band_lu.band_lu`).

    Parameters
    ----------
    lu : (N, 3 kd + 1) ndarray
        Factor in the general band storage of
        :meth:`cbha_inverse.core.system.EquilibriumSystem.exact_system` (a buffer of the
        system: valid until its next factorisation).
    kd : int
        Number of sub- and super-diagonals of the factored matrix.
    pivots, lower_reach : (N,) int ndarray
        Row interchanges and the reach of the columns of ``L``.

    """

    method = 'band_lu'

    def __init__(self, lu, kd, pivots, lower_reach):
        """Keep the factor."""
        self._lu, self._kd, self._pivots, self._reach = lu, kd, pivots, lower_reach

    def _solve(self, columns):
        """Solve with the compiled band LU's forward and backward sweeps."""
        solved = np.array(columns, dtype=float, order='C')
        band_lu_solve(self._lu, self._kd, self._pivots, self._reach, solved)
        return solved


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
