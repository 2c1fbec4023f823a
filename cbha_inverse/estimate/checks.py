"""
Input checks of the shape estimator: malformed vectors and stuck string potentiometers.

:func:`check_vector` gives the reason a reading is rejected (``wrong_length``, ``non_finite``,
``out_of_range``; the first word of the reason is its counter's key); :class:`StuckDetector`
finds a pot that no longer moves while the others do (the compiled
:func:`cbha_inverse.core._kernels.estimation.stuck_pots`).
"""

import math

from cbha_inverse.core._kernels.estimation import stuck_pots
from cbha_inverse.core.input_checks import vector_fault
import numpy as np


def check_vector(values, size, what, limit=None):
    """
    Return a reading as floats, or the reason it is rejected.

    Parameters
    ----------
    values : array_like
        The reading.
    size : int
        Expected number of values.
    what : str
        Its name, for the reason.
    limit : float, optional
        Largest accepted magnitude.

    Returns
    -------
    values : (size,) ndarray or None
    reason : str or None
        ``'<key>: <what is wrong>'``, key one of ``wrong_length``, ``non_finite``,
        ``out_of_range``; None when accepted.

    """
    bound = math.inf if limit is None else limit
    array, key, detail = vector_fault(values, size, what, -bound, bound)
    return array, None if key is None else f'{key}: {detail}'


class StuckDetector:
    """
    Pots whose length no longer moves while the others do.

    Over the last ``window`` updates, a pot is stuck when its range (max - min) is below
    ``tolerance`` while the median range of the other pots exceeds ``motion``. A stuck pot stays
    stuck until its own range exceeds ``tolerance`` again.

    Parameters
    ----------
    count : int
        Number of pots.
    window : int
        Updates looked at (0 disables the detector).
    tolerance : float  [m]
    motion : float  [m]

    """

    def __init__(self, count, window, tolerance, motion):
        """Allocate the window."""
        self.count, self.window = int(count), int(window)
        self.tolerance, self.motion = float(tolerance), float(motion)
        self._history = np.zeros((max(self.window, 1), self.count))
        self._counters = np.zeros(2, dtype=np.int64)
        self.stuck = np.zeros(self.count, dtype=bool)
        self.reset()

    def reset(self):
        """Forget the history."""
        self._counters[:] = 0
        self.stuck[:] = False

    def update(self, lengths):
        """
        Add one reading; return which pots are stuck.

        Parameters
        ----------
        lengths : (count,) ndarray  [m]
            The pots' lengths.

        Returns
        -------
        (count,) ndarray of bool
            A view of :attr:`stuck` (the next update overwrites it).

        """
        if self.window > 0:
            stuck_pots(self._history, self._counters, lengths, self.stuck, self.tolerance,
                       self.motion)
        return self.stuck
