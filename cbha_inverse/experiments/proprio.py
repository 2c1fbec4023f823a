"""
What ``cbha_demo`` adds for its camera-less runs (``--feedback proprio``).

:func:`estimate_error` scores ``shape_estimator``'s ``tip/estimated`` against ``tip/true`` of the
same stamps, the estimate's own accuracy beside the run's tracking error.
"""

import numpy as np


def estimate_error(recorder, start, end):
    """
    Return the RMS of ``tip/estimated`` against ``tip/true`` of the same stamp in a lap window.

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
    if not recorder.targets:
        return float('nan')
    first = min(t[0] for t in recorder.targets)
    truth = {round(t[0], 6): np.array(t[1:]) for t in recorder.tips}
    errors = [np.linalg.norm(np.array(e[1:]) - truth[round(e[0], 6)])
              for e in recorder.estimated
              if round(e[0], 6) in truth and start <= e[0] - first <= end]
    return float(np.sqrt(np.mean(np.square(errors)))) if errors else float('nan')
