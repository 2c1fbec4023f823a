"""
Factors of a tangent stiffness ``K``, all with one protocol: ``solve(rhs)`` and ``method``.

The equilibrium evaluator (:class:`cbha_inverse.core.system.EquilibriumSystem`) factors its
tangents into these: :class:`BandCholesky` (compiled, the symmetric band of the control tick and
the material band of the fallback), :class:`BandLU` (LAPACK ``dgbtrf``, the exact,
non-symmetric band of Newton's method) and :class:`DenseLU` (an exact tangent with a user load
stiffness). The control tick, Newton's method and the static checks use them through
:class:`TangentFactor` alone.
"""

from cbha_inverse.core._kernels.band import band_solve
import numpy as np
from scipy.linalg import lapack


class TangentFactor:
    """
    A factorised tangent ``K`` (the protocol of every factor): ``solve`` and ``method``.

    Attributes
    ----------
    method : str
        ``'band_cholesky'``, ``'band_lu'`` or ``'dense_lu'``.

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


class BandCholesky(TangentFactor):
    """
    Cholesky factor ``L`` of a symmetric band tangent (compiled kernels).

    Parameters
    ----------
    factor : (N, kd + 1) ndarray
        ``L`` in the lower band storage of
        :meth:`cbha_inverse.core.system.EquilibriumSystem.linearise` (a buffer of the system:
        valid until its next evaluation).

    """

    method = 'band_cholesky'

    def __init__(self, factor):
        """Keep the factor."""
        self._factor = factor

    def solve(self, rhs):
        """Solve ``K X = rhs`` as :meth:`TangentFactor.solve` (the tick's path: one copy)."""
        solved = np.array(rhs, dtype=float, order='C')
        band_solve(self._factor, solved if solved.ndim == 2
                   else solved.reshape(solved.shape[0], -1))
        return solved


class BandLU(TangentFactor):
    """
    LU factor of a general band matrix (LAPACK ``dgbtrf``).

    Parameters
    ----------
    lu : (3 kd + 1, N) ndarray
        Factor in LAPACK's general band layout (Fortran order).
    pivots : (N,) int ndarray
        Row interchanges.
    kd : int
        Number of sub- and super-diagonals of the factored matrix.

    """

    method = 'band_lu'

    def __init__(self, lu, pivots, kd):
        """Keep the factor."""
        self._lu, self._pivots, self._kd = lu, pivots, kd

    def _solve(self, columns):
        """Solve with LAPACK's ``dgbtrs``."""
        x, info = lapack.dgbtrs(self._lu, self._kd, self._kd, columns, self._pivots)
        if info != 0:
            raise np.linalg.LinAlgError(f'dgbtrs failed (info {info})')
        return np.ascontiguousarray(x)


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
