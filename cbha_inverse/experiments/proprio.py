"""
What ``cbha_demo`` adds for its camera-less runs (``--feedback proprio``).

:func:`estimate_error` scores ``shape_estimator``'s ``tip/estimated`` against ``tip/true`` of the
same stamps, the estimate's own accuracy beside the run's tracking error;
:func:`add_plant_pot_arguments` and :func:`plant_pot_parameters` give the plant's string pots
their noise and a calibration of their own (which a scene then has to identify).
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
