"""
What ``cbha_demo`` adds for its camera-less runs (``--feedback proprio``).

:func:`estimate_error` scores ``shape_estimator``'s ``tip/estimated`` against ``tip/true``
interpolated at its stamps, the estimate's own accuracy beside the run's tracking error, on the
points of the run's bag (:func:`bag_points`: the demo's in-process subscriber may miss messages
on a loaded machine, the recorder's bag is what the tracking error is scored on too);
:func:`add_plant_pot_arguments` and :func:`plant_pot_parameters` give the plant's string pots
their noise and a calibration of their own (which a scene then has to identify);
:func:`add_estimator_arguments` and :func:`proprio_node_parameters` the estimator's unknowns and
what of them the solver takes into its model (the payload, the sections' stiffness).
"""

import argparse
import math
from types import SimpleNamespace

from cbha_inverse.bag.evaluate import point_series
from cbha_inverse.bag.storage import open_bag
import numpy as np


def bag_points(path, namespace):
    """
    Return a run bag's ``target``, ``tip/true`` and ``tip/estimated`` for :func:`estimate_error`.

    Parameters
    ----------
    path : str or pathlib.Path
        The bag folder.
    namespace : str
        The topics' namespace (``/cbha``).

    Returns
    -------
    types.SimpleNamespace
        ``targets``, ``tips`` and ``estimated``: lists of ``(stamp [s], x, y, z [m])``.

    """
    series = {}
    with open_bag(path) as bag:
        for name, topic in (('targets', 'target'), ('tips', 'tip/true'),
                            ('estimated', 'tip/estimated')):
            _, stamps, points = point_series(bag, f'{namespace}/{topic}')
            series[name] = [(float(t), *map(float, p)) for t, p in zip(stamps, points)]
    return SimpleNamespace(**series)


def estimate_error(recorder, start, end):
    """
    Return the RMS of ``tip/estimated`` against ``tip/true`` at its stamps in a lap window.

    ``tip/true`` is interpolated linearly at each estimate's stamp (the pots and the tip may be
    published at different instants); estimates outside the span of ``tip/true`` are left out.

    Parameters
    ----------
    recorder : Recorder or types.SimpleNamespace
        What the run received or recorded (:func:`bag_points`): ``targets``, ``tips`` and
        ``estimated`` as ``(stamp, x, y, z)``.
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
    parser.add_argument('--stuck-pot', type=int, default=None, metavar='INDEX',
                        help='proprio: the plant pot of this index (string_pots order) sticks '
                        'halfway through the lap (cbha_sim string_pot_stuck)')


def plant_pot_parameters(args):
    """Return the ``cbha_sim`` parameters of the plant's string pots from the parsed options."""
    parameters = {'string_pot_noise_std': args.pot_noise}
    for key, text in (('offset', args.plant_pot_offset), ('gain', args.plant_pot_gain)):
        if text is not None:
            parameters[f'string_pot_{key}'] = [float(v) for v in text.split(',')]
    return parameters


def _section_stds(text):
    """Parse ``--estimate-sections``: ``STD`` or ``STD,GAIN_STD``, finite, not negative."""
    try:
        values = tuple(float(v) for v in text.split(','))
    except ValueError:
        values = ()
    if not 1 <= len(values) <= 2 or not all(math.isfinite(v) and v >= 0.0 for v in values):
        raise argparse.ArgumentTypeError(f'{text!r} is not STD or STD,GAIN_STD (numbers >= 0)')
    return values


def add_estimator_arguments(parser):
    """Add the options of ``shape_estimator``'s unknowns (and what the solver takes of them)."""
    parser.add_argument('--estimate-payload', type=float, default=0.0, metavar='STD',
                        help='proprio: shape_estimator payload_std, solver tip load [kg], 0: none')
    parser.add_argument('--estimate-weight', type=float, default=0.0, metavar='STD',
                        help="with --estimate-payload: prior of the arm's weight error [kg]")
    parser.add_argument('--estimate-sections', type=_section_stds, default=(0.0,),
                        metavar='STD[,GAIN_STD]', help=(
        'proprio: shape_estimator section_stiffness_std [-] (0: none) and gain_std; the '
        "estimated section factors go into the solver's model (see --feed-sections)"))
    parser.add_argument('--feed-sections', action=argparse.BooleanOptionalAction, default=True,
                        help="with --estimate-sections: inverse_solver's section_stiffness_topic "
                        'takes the estimated factors (--no-feed-sections: the estimate alone)')
    parser.add_argument('--feed-gains', action=argparse.BooleanOptionalAction, default=False,
                        help="shape_estimator's publish_gains, inverse_solver's "
                        'actuator_gain_topic: the estimated cavity gains into the model')
    parser.add_argument('--proprio-max-correction', type=float, default=None, metavar='M',
                        help="inverse_solver's max_correction in the proprio runs [m] (default: "
                        'its params file)')
    parser.add_argument('--max-section-change', type=float, default=None, metavar='FACTOR',
                        help="inverse_solver's max_section_change (default: its params file)")


def proprio_node_parameters(args):
    """
    Return the parameters of ``shape_estimator`` and ``inverse_solver`` in a run on the pots.

    Parameters
    ----------
    args : argparse.Namespace
        ``cbha_demo``'s options (:func:`add_estimator_arguments`).

    Returns
    -------
    estimator : dict
        Its unknowns: payload, weight, sections and gains (published with ``--feed-gains``).
    solver : dict
        The closed loop on ``tip/estimated``, the payload, sections and gains topics when
        estimated and fed.

    """
    sections = dict(zip(('section_stiffness_std', 'gain_std'), args.estimate_sections))
    estimator = {'payload_std': args.estimate_payload, 'payload_weight_std': args.estimate_weight,
                 **sections}
    fed = bool(sections['section_stiffness_std']) and args.feed_sections
    solver = {'feedback_topic': 'tip/estimated',
              'payload_topic': 'payload/estimated' if args.estimate_payload else '',
              'section_stiffness_topic': 'sections/estimated' if fed else ''}
    if args.feed_gains:
        estimator['publish_gains'] = True
        solver['actuator_gain_topic'] = 'gains/estimated'
    if args.proprio_max_correction is not None:
        solver['max_correction'] = args.proprio_max_correction
    if args.max_section_change is not None:
        solver['max_section_change'] = args.max_section_change
    return estimator, solver


def proprio_sim_parameters(args, trajectory):
    """
    Return ``cbha_sim``'s parameters of a run closed on the pots: no tip, the stuck-pot fault.

    Parameters
    ----------
    args : argparse.Namespace
        ``cbha_demo``'s options (``--stuck-pot``, ``--start-hold``).
    trajectory : cbha_inverse.robot.trajectory.Trajectory
        The run's trajectory: the stuck pot freezes halfway through its lap.

    Returns
    -------
    dict

    """
    parameters = {'tip_output': 'none'}
    if args.stuck_pot is not None:  # the first command comes with the start point
        parameters.update(string_pot_stuck=args.stuck_pot, string_pot_stuck_after=(
            args.start_hold + 0.5 * trajectory.lap_time))
    return parameters
