"""
Benchmark of the shape estimator on the CBHA's string pots (``cbha_bench_estimator``).

A plant with section-stiffness and cavity-gain errors the nominal scene does not know (and
optionally a tip payload) runs a lap of pressures that sweeps the bending direction of both
sections; at every pose its pot lengths, with Gaussian noise, and its pressures feed
:class:`cbha_inverse.estimate.shape.ShapeEstimator` (one update per pose, as in a loop). The
table gives the update time (median and p99; goal: median <= 100 us), the inverse solver's tick
on the same scene in the same run (for the ratio on a loaded machine), the estimated tip's RMS
error against the plant's true tip and the open-loop model's (the nominal forward solve at the
same pressures), and how many updates were degraded (``--stuck-pot`` freezes one pot from the
middle of the lap on). ``--pressures-bag`` replays the measured pressures of a ``cbha_demo`` run's
bag instead of the lap (its poses, the payload's included), measured over the run's lap window.
"""

import argparse
import json
import sys
import time

from cbha_inverse.bag.evaluate import command_series, point_series
from cbha_inverse.bag.storage import open_bag
from cbha_inverse.estimate.shape import EstimatorOptions, ShapeEstimator
from cbha_inverse.scene import load_scene
from cbha_inverse.scene.calibration import Calibration
import numpy as np

GOAL = 100e-6
"""Median update time goal [s]."""


def pressure_lap(n_poses, mean=6.0e4, amplitude=4.0e4):
    """
    Return a lap of pressures that sweeps the bending direction of both sections.

    Parameters
    ----------
    n_poses : int
        Poses of the lap.
    mean, amplitude : float  [Pa]
        Every tube's pressure is ``mean + amplitude cos(phase - its angle)``, the outer section's
        turning the other way.

    Returns
    -------
    (n_poses, 6) ndarray  [Pa]

    """
    phase = 2.0 * np.pi * np.arange(n_poses) / n_poses
    tubes = np.deg2rad([90.0, 210.0, 330.0])
    inner = mean + amplitude * np.cos(phase[:, None] - tubes[None])
    outer = mean + amplitude * np.cos(-phase[:, None] - tubes[None])
    return np.concatenate([inner, outer], axis=1)


def bag_lap(path, namespace='/cbha', start=1.5):
    """
    Return the measured pressures of a ``cbha_demo`` run's bag and its lap window.

    Parameters
    ----------
    path : str or pathlib.Path
        The bag folder.
    namespace : str
        The topics' namespace.
    start : float  [s]
        The window starts this long after the first ``target`` (as the demo's score).

    Returns
    -------
    pressures : (N, 6) ndarray  [Pa]
        ``pressure_measured`` in the order received.
    measured : (N,) bool ndarray
        The pressures received from ``start`` after the first target to the last target.

    Raises
    ------
    ValueError
        If the bag holds no pressures or no targets.

    """
    with open_bag(path) as bag:
        received, pressures = command_series(bag, f'{namespace}/pressure_measured')
        targets = point_series(bag, f'{namespace}/target')[0]
    if not len(pressures) or not targets.size:
        raise ValueError(f'{path}: no {namespace}/pressure_measured or {namespace}/target')
    measured = (received >= targets[0] + int(start * 1e9)) & (received <= targets[-1])
    return np.array(pressures, dtype=float), measured


def plant_calibration(stiffness_error, gain_error, payload):
    """
    Return the plant's deliberate errors: sections and cavities alternately above and below.

    Parameters
    ----------
    stiffness_error, gain_error : float  [-]
        Relative errors (``inner`` stiffer, ``outer`` softer; the gains alternate in sign).
    payload : float  [kg]
        Mass at the tip.

    Returns
    -------
    cbha_inverse.scene.calibration.Calibration

    """
    valves = ('inner_over', 'inner_right', 'inner_left', 'outer_over', 'outer_right',
              'outer_left')
    signs = (1.0, -1.0, 0.5, -1.0, 1.0, -0.5)
    return Calibration(section_stiffness={'inner': 1.0 + stiffness_error,
                                          'outer': 1.0 - stiffness_error},
                       actuator_gain={v: 1.0 + s * gain_error for v, s in zip(valves, signs)},
                       tip_payload_mass=payload)


def bench(n_poses=300, laps=2, noise=1e-4, stiffness_error=0.15, gain_error=0.10, payload=0.0,
          seed=0, options=None, stuck_pot=None, lap=None, measured=None):
    """
    Run the lap and collect the timings and errors.

    Parameters
    ----------
    n_poses : int
        Poses per lap (one estimator update each).
    laps : int
        Laps; the first settles the estimator and is not measured.
    noise : float  [m]
        Standard deviation of the pot noise.
    stiffness_error, gain_error, payload
        As :func:`plant_calibration`.
    seed : int
        Seed of the noise.
    options : EstimatorOptions, optional
        The estimator's options.
    stuck_pot : int, optional
        This pot keeps its reading from the middle of the measured lap on.
    lap : (N, 6) array_like, optional  [Pa]
        The pressures of a lap (default: :func:`pressure_lap` of ``n_poses``).
    measured : (N,) array_like of bool, optional
        The updates of the last lap that are measured (default: all).

    Returns
    -------
    dict
        ``median``, ``p99`` [s], ``tick_median`` [s] (inverse solver), ``rms`` and
        ``open_loop_rms`` [m], ``bias`` (the mean tip error, 3 values) [m], ``degraded``
        (count), ``updates``, ``payload`` and ``weight`` [kg] (the estimate's at the end).

    """
    nominal = load_scene('cbha')
    plant = load_scene('cbha', calibration=plant_calibration(stiffness_error, gain_error,
                                                             payload))
    estimator = ShapeEstimator.from_scene(nominal, options)
    solver = nominal.make_inverse_solver()
    rng = np.random.default_rng(seed)
    lap = pressure_lap(n_poses) if lap is None else np.asarray(lap, dtype=float)
    measured = (np.ones(len(lap), dtype=bool) if measured is None
                else np.asarray(measured, dtype=bool))
    truth, model = [], []
    state = nominal_state = None
    for pressures in lap:
        result = plant.forward(pressures, initial_state=state, strict=True)
        state = result.state
        truth.append((result.effector_positions[-1],
                      plant.sensors.lengths(state.positions, state.rotations).copy()))
        open_loop = nominal.forward(pressures, initial_state=nominal_state, strict=True)
        nominal_state = open_loop.state
        model.append(open_loop.effector_positions[-1])
    times, ticks, errors, open_errors, biases, degraded = [], [], [], [], [], 0
    frozen = None
    for k in range(laps):
        for i, (pressures, (tip, lengths), open_tip) in enumerate(zip(lap, truth, model)):
            readings = nominal.sensors.readings(lengths + noise * rng.standard_normal(6))
            if stuck_pot is not None and k == laps - 1 and i >= len(lap) // 2:
                frozen = readings[stuck_pot] if frozen is None else frozen
                readings[stuck_pot] = frozen
            estimate = estimator.update(readings, pressures)
            tick = solver.step(tip)
            if k < laps - 1 or not measured[i]:
                continue
            times.append(estimate.seconds)
            ticks.append(tick.timings['total'])
            errors.append(np.linalg.norm(estimate.tip - tip))
            biases.append(estimate.tip - tip)
            open_errors.append(np.linalg.norm(open_tip - tip))
            degraded += estimate.status != 'ok'
    return {'median': float(np.median(times)), 'p99': float(np.percentile(times, 99)),
            'tick_median': float(np.median(ticks)),
            'rms': float(np.sqrt(np.mean(np.square(errors)))),
            'open_loop_rms': float(np.sqrt(np.mean(np.square(open_errors)))),
            'bias': [float(v) for v in np.mean(biases, axis=0)],
            'degraded': int(degraded), 'updates': len(times),
            'payload': float(estimate.payload), 'weight': float(estimate.weight),
            'section_stiffness': [float(v) for v in estimate.section_stiffness],
            'finite': bool(np.all(np.isfinite(errors)))}


def main(argv=None):
    """
    Print the estimator's update time and accuracy (``cbha_bench_estimator``).

    Parameters
    ----------
    argv : list of str, optional
        Command-line arguments (default: ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit status.

    """
    parser = argparse.ArgumentParser(description=__doc__.strip().splitlines()[0])
    parser.add_argument('--poses', type=int, default=300, help='poses per lap')
    parser.add_argument('--noise', type=float, default=1e-4, help='pot noise [m]')
    parser.add_argument('--stiffness-error', type=float, default=0.15)
    parser.add_argument('--gain-error', type=float, default=0.10)
    parser.add_argument('--payload', type=float, default=0.0, help='plant tip payload [kg]')
    parser.add_argument('--estimate-payload', type=float, default=None, metavar='STD',
                        help='estimate the payload with this prior std [kg]')
    parser.add_argument('--weight-std', type=float, default=None, metavar='STD',
                        help="estimate an error of the arm's own weight with this prior std [kg]")
    parser.add_argument('--section-stiffness-std', type=float, default=None, metavar='STD',
                        help="estimate each chain section's relative stiffness error with this "
                        'prior std [-]')
    parser.add_argument('--gain-std', type=float, default=EstimatorOptions.gain_std,
                        metavar='STD', help="prior std of the actuation's gain errors [-]")
    parser.add_argument('--stuck-pot', type=int, default=None, metavar='INDEX',
                        help='freeze this pot from the middle of the measured lap on')
    parser.add_argument('--pressures-bag', metavar='BAG',
                        help="replay a cbha_demo run's measured pressures (one pass, its lap "
                             'window measured) instead of the lap')
    parser.add_argument('--seed', type=int, default=0, help='seed of the pot noise')
    parser.add_argument('--json', help='write the row to this JSON file')
    args = parser.parse_args(argv)
    started = time.perf_counter()
    lap, measured = bag_lap(args.pressures_bag) if args.pressures_bag else (None, None)
    row = bench(args.poses, laps=1 if args.pressures_bag else 2, noise=args.noise,
                stiffness_error=args.stiffness_error,
                gain_error=args.gain_error, payload=args.payload, seed=args.seed,
                options=EstimatorOptions(payload_std=args.estimate_payload,
                                         weight_std=args.weight_std, gain_std=args.gain_std,
                                         section_stiffness_std=args.section_stiffness_std),
                stuck_pot=args.stuck_pot, lap=lap, measured=measured)
    verdict = 'ok' if row['median'] <= GOAL else 'over'
    median, p99, tick = (row[key] * 1e6 for key in ('median', 'p99', 'tick_median'))
    print(f'cbha: estimator update median {median:.0f} us, p99 {p99:.0f} us (goal '
          f'{GOAL * 1e6:.0f} us: {verdict}); inverse tick median {tick:.0f} us '
          f'(ratio {median / tick:.2f})')
    rms, open_rms = row['rms'] * 1e3, row['open_loop_rms'] * 1e3
    bias = ', '.join(f'{v * 1e3:.2f}' for v in row['bias'])
    sections = (', section stiffness ' + ', '.join(f'{v:.3f}' for v in row['section_stiffness'])
                if row['section_stiffness'] else '')
    print(f'plant: stiffness +-{args.stiffness_error:.0%}, gains +-{args.gain_error:.0%}, '
          f'payload {args.payload:g} kg, pot noise {args.noise * 1e3:g} mm: estimated tip RMS '
          f'{rms:.2f} mm (mean error {bias} mm), open-loop model RMS {open_rms:.2f} mm, '
          f'{row["degraded"]} of '
          f'{row["updates"]} updates degraded, payload {row["payload"]:.4f} kg, weight error '
          f'{row["weight"]:.4f} kg{sections} ({time.perf_counter() - started:.0f} s)')
    if args.json:
        with open(args.json, 'w') as handle:
            json.dump(row, handle, indent=1)
    return 0


if __name__ == '__main__':
    sys.exit(main())
