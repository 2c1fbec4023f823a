"""
What ``cbha_demo`` adds for its camera-less runs (``--feedback proprio``).

:func:`estimate_error` scores ``shape_estimator``'s ``tip/estimated`` against ``tip/true``
interpolated at its stamps, the estimate's own accuracy beside the run's tracking error.
"""

import numpy as np


def estimate_error(recorder, start, end):
    """
    Return the RMS of ``tip/estimated`` against ``tip/true`` at its stamps in a lap window.

    ``tip/true`` is interpolated linearly at each estimate's stamp (the pots and the tip may be
    published at different instants); estimates outside the span of ``tip/true`` are left out.

    Parameters
    ----------
    recorder : Recorder
        What the run received.
    start, end : float  [s]
        Window from the first target's stamp.

    Returns
    -------
    float  [m]
        NaN without matching samples.

    """
    if not recorder.targets or len(recorder.tips) < 2 or not recorder.estimated:
        return float('nan')
    first = min(t[0] for t in recorder.targets)
    truth = np.array(sorted(recorder.tips))
    estimated = np.array(recorder.estimated)
    stamps = estimated[:, 0]
    keep = ((stamps - first >= start) & (stamps - first <= end) & (stamps >= truth[0, 0])
            & (stamps <= truth[-1, 0]))
    if not keep.any():
        return float('nan')
    reference = np.stack([np.interp(stamps[keep], truth[:, 0], truth[:, 1 + i])
                          for i in range(3)], axis=1)
    errors = np.linalg.norm(estimated[keep, 1:] - reference, axis=1)
    return float(np.sqrt(np.mean(np.square(errors))))
