"""
What ``cbha_demo`` adds for its camera-less runs (``--feedback proprio``).

:func:`estimate_error` scores ``shape_estimator``'s ``tip/estimated`` against ``tip/true``
interpolated at its stamps, the estimate's own accuracy beside the run's tracking error;
:func:`add_plant_pot_arguments` and :func:`plant_pot_parameters` give the plant's string pots
their noise and a calibration of their own (which a scene then has to identify).
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


def add_plant_pot_arguments(parser):
    """Add the options of the plant's string pots to ``cbha_demo``'s parser."""
    parser.add_argument('--pot-noise', type=float, default=1e-4,
                        help='string-pot length noise of the plant [m]')
    parser.add_argument('--plant-pot-offset', default=None,
                        help='comma-separated plant string-pot offsets [reading] (1 or one per '
                        "pot; cbha_sim string_pot_offset; default: the scene's)")
    parser.add_argument('--plant-pot-gain', default=None,
                        help='comma-separated plant string-pot gains [reading/m] (1 or one per '
                        "pot; cbha_sim string_pot_gain; default: the scene's)")


def plant_pot_parameters(args):
    """Return the ``cbha_sim`` parameters of the plant's string pots from the parsed options."""
    parameters = {'string_pot_noise_std': args.pot_noise}
    for key, text in (('offset', args.plant_pot_offset), ('gain', args.plant_pot_gain)):
        if text is not None:
            parameters[f'string_pot_{key}'] = [float(v) for v in text.split(',')]
    return parameters
