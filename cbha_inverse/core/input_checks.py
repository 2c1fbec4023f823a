"""
The one check of an incoming vector: its length, that it is finite, that it lies within bounds.

The valve drivers (:func:`cbha_inverse.robot.safety.check_command`) and the shape estimator
(:func:`cbha_inverse.estimate.checks.check_vector`) wrap :func:`vector_fault` in their own
result types; the keys it returns are the nodes' diagnostics counter keys.
"""

import math

import numpy as np


def vector_fault(values, size, what, lower=-math.inf, upper=math.inf, unit=''):
    """
    Return a vector as floats, or why it is rejected.

    Parameters
    ----------
    values : array_like
        The vector (any shape; flattened).
    size : int
        Required number of values.
    what : str
        Its name in the detail (``'pressure'``, ``'readings'``).
    lower, upper : float
        Accepted range of every value (inclusive; default unbounded).
    unit : str
        Appended to the range in the detail (``' Pa'``).

    Returns
    -------
    values : (size,) ndarray or None
        The vector, None when rejected.
    key : str or None
        ``'wrong_length'`` (also for values that are not numbers), ``'non_finite'`` or
        ``'out_of_range'``; None when accepted.
    detail : str
        What is wrong, for the (throttled) log; ``''`` when accepted.

    """
    try:
        array = np.asarray(values, dtype=float).reshape(-1)
    except (TypeError, ValueError):
        return None, 'wrong_length', f'{what} are not numbers'
    if array.size != size:
        return None, 'wrong_length', f'{array.size} values, expected {size}'
    if not np.isfinite(array).all():
        return None, 'non_finite', f'non-finite {what}'
    # array methods, and no comparison against an infinite bound: this runs on every command
    # and message (a few values), where np.any's wrapper costs more than the comparison
    if ((lower > -math.inf and (array < lower).any())
            or (upper < math.inf and (array > upper).any())):
        shown = [float(f'{v:.6g}') for v in array]
        return None, 'out_of_range', f'{what} outside [{lower:g}, {upper:g}]{unit}: {shown}'
    return array, None, ''
