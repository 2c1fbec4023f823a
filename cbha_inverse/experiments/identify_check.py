"""
``cbha_identify_check``: the identification check, end to end on real DDS (``docs/identify.md``).

1. ``cbha_demo`` runs the circle and the square open loop with the nominal model on a simulated
   arm with errors the fit is not tuned to (default: sections x0.85 and x1.1, cavity gains
   0.9-1.1, tip noise 0.2 mm), recording each lap;
2. ``cbha_identify`` fits the scene to the recorded circle lap alone;
3. ``cbha_demo`` runs the square (a different trajectory) open loop with the identified scene.

``--excite PROGRAM`` adds an excitation run to step 1 (``cbha_demo --excite``: ``cbha_excite``
on the same plant, recorded) and gives ``cbha_identify`` both bags, the circle lap and the
excitation (their samples pooled).

``--plant-pot-offset`` / ``--plant-pot-gain`` give the plant's string pots a calibration the
nominal scene does not know (``cbha_identify`` then fits it from the circle lap's
``string_pots``); ``--proprio`` adds the camera-less closed loop (``cbha_demo --feedback
proprio``, no tip measurement) on ``--proprio-shapes``: with pots as the scene knows them (the
reference), with the plant's pots and the nominal scene, and with the identified scene.

Prints the square's tracking RMS (time-aligned, as ``cbha_demo``) and cross-track RMS (distance
to the path, timing ignored) with the nominal and the identified scene, each fitted factor (and
pot offset and gain) against the truth in units of its reported standard error, and the
camera-less runs' RMS; writes ``summary.json``.
"""

import argparse
import json
from pathlib import Path
import subprocess
import sys
import time

from cbha_inverse.bag.evaluate import evaluate_bag
from cbha_inverse.metrics import cross_track_errors
from cbha_inverse.robot.robotino import ARM_VALVES
from cbha_inverse.scene import load_scene
from cbha_inverse.sim.pots import per_pot
import numpy as np


def parse_args(argv):
    """Parse the command line."""
    parser = argparse.ArgumentParser(prog='cbha_identify_check',
                                     description=__doc__.split('\n\n')[0])
    parser.add_argument('--output', default='output/identify_check', help='output folder')
    parser.add_argument('--plant-section-scale', default='0.85,1.1',
                        help='plant stiffness error per section (truth)')
    parser.add_argument('--plant-gain-scale', default='0.9,1.05,1.1,0.95,1.08,0.92',
                        help='plant effective-area error per valve (truth)')
    parser.add_argument('--plant-base-offset', default=None,
                        help='plant base position error x,y,z [m] (truth; cbha_identify then '
                        'fits the base position too)')
    parser.add_argument('--seed', type=int, default=0, help='seed of the plant noise')
    parser.add_argument('--excite', default=None, metavar='PROGRAM',
                        help='also record this cbha_excite program on the plant (cbha_demo '
                        '--excite, e.g. bends) and identify from the circle lap and it')
    parser.add_argument('--plant-pot-offset', default=None,
                        help='plant string-pot offsets per pot [reading] (truth)')
    parser.add_argument('--plant-pot-gain', default=None,
                        help='plant string-pot gains per pot [reading/m] (truth)')
    parser.add_argument('--proprio', action='store_true',
                        help='also run the camera-less closed loop before and after')
    parser.add_argument('--proprio-shapes', default='circle,square',
                        help='shapes of the camera-less runs')
    parser.add_argument('--identify-args', default='',
                        help='extra cbha_identify arguments (one string, e.g. "--fit-latency")')
    return parser.parse_args(argv)


def _run(command, log):
    """Run a module of the package; return its exit code (output into ``log``)."""
    with open(log, 'w') as stream:
        return subprocess.call([sys.executable, '-m', *command], stdout=stream,
                               stderr=subprocess.STDOUT)


def identification_bags(nominal, excite):
    """
    Return the bags ``cbha_identify`` fits.

    Parameters
    ----------
    nominal : pathlib.Path
        The output folder of the nominal ``cbha_demo`` run.
    excite : str or None
        The ``--excite`` program, if one was recorded.

    Returns
    -------
    list of pathlib.Path
        The circle lap's bag, then the excitation run's (from the demo's ``summary.json``).

    """
    bags = [nominal / 'circle_open' / 'bag']
    if excite is not None:
        summary = json.loads((nominal / 'summary.json').read_text())
        bags.append(Path(summary['excitation']['bag']))
    return bags


def check_steps(args, output):
    """
    Return the check's steps: (label, function returning the module command line).

    The identification's command is built when it runs: the excitation bag is named by the
    nominal run's ``summary.json``.

    Parameters
    ----------
    args : argparse.Namespace
        The parsed command line.
    output : pathlib.Path
        The check's output folder.

    Returns
    -------
    list of (str, callable)
        The nominal runs, the identification, the identified run, then with ``--proprio`` the
        camera-less runs (:data:`CAMERA_LESS_RUNS`).

    """
    plant = ['--stiffness-scale', '1.0', '--plant-section-scale', args.plant_section_scale,
             '--plant-gain-scale', args.plant_gain_scale, '--plant-seed', str(args.seed),
             '--modes', 'open', '--feedback', 'direct']
    fit_base = []
    if args.plant_base_offset is not None:
        plant += ['--plant-base-offset', args.plant_base_offset]
        fit_base = ['--fit-base-position']
    pots = [item for key, text in (('--plant-pot-offset', args.plant_pot_offset),
                                   ('--plant-pot-gain', args.plant_pot_gain))
            if text is not None for item in (key, text)]
    demo = ['cbha_inverse.experiments.demo']
    excite = [] if args.excite is None else ['--excite', args.excite]
    identified = str(output / 'identified' / 'cbha_identified.yaml')
    steps = [
        ('nominal runs', lambda: demo + ['--output', str(output / 'nominal'),
                                         '--shapes', 'circle,square', *plant, *pots, *excite]),
        ('identification', lambda: [
            'cbha_inverse.identify.cli',
            *(str(b) for b in identification_bags(output / 'nominal', args.excite)),
            '--output', str(output / 'identified'), *fit_base, *args.identify_args.split()]),
        ('identified run', lambda: demo + [
            '--output', str(output / 'identified_run'), '--shapes', 'square', '--model-scene',
            identified, *plant, *pots]),
    ]
    camera_less = ['--modes', 'closed', '--feedback', 'proprio', '--proprio-shapes',
                   args.proprio_shapes]
    for label, folder, plant_pots, scene in CAMERA_LESS_RUNS if args.proprio else ():
        extra = (pots if plant_pots else []) + (['--model-scene', identified] if scene else [])
        steps.append((f'camera-less {label}', lambda folder=folder, extra=extra: demo + [
            '--output', str(output / folder), *plant, *camera_less, *extra]))
    return steps


CAMERA_LESS_RUNS = (
    ('reference', 'proprio_reference', False, False),
    ('uncalibrated', 'proprio_nominal', True, False),
    ('identified', 'proprio_identified', True, True))
"""
The camera-less runs: label, output folder, whether the plant has its own pot calibration and
whether the controller runs the identified scene. The reference's pots are those the nominal
scene knows; the uncalibrated run has the plant's pots and the nominal scene.
"""


def pot_scores(args, result):
    """
    Return each fitted pot offset and gain against the plant's: value, error, truth, |error| / SE.

    Parameters
    ----------
    args : argparse.Namespace
        The check's options (the plant's pots; unset: the nominal scene's).
    result : dict
        ``cbha_identified.json``.

    Returns
    -------
    dict
        ``{'<pot>.offset' or '<pot>.gain': {...}}``; empty without fitted pots.

    """
    fitted = result.get('string_pots', {}).get('pots', {})
    if not fitted:
        return {}
    sensors = load_scene('cbha').sensors
    truth = {'offset': sensors.reading_offset, 'gain': sensors.reading_gain}
    for key, text in (('offset', args.plant_pot_offset), ('gain', args.plant_pot_gain)):
        if text is not None:
            truth[key] = per_pot(f'--plant-pot-{key}', text.split(','), sensors.n_sensors)
    scores = {}
    for i, name in enumerate(sensors.names):
        for key in ('offset', 'gain'):
            value, error = fitted[name][key], fitted[name][f'{key}_standard_error']
            scores[f'{name}.{key}'] = {
                'value': value, 'standard_error': error, 'truth': float(truth[key][i]),
                'error_over_standard_error': abs(value - truth[key][i]) / error if error > 0.0
                else float('nan')}
    return scores


def camera_less_rms(output, args):
    """Return ``{run label: {shape: tracking RMS [m]}}`` of the camera-less runs (if run)."""
    if not args.proprio:
        return {}
    table = {}
    for label, folder, _, _ in CAMERA_LESS_RUNS:
        summary = json.loads((output / folder / 'summary.json').read_text())
        table[label] = {r['shape']: r['rms_mm'] * 1e-3 for r in summary['runs']
                        if r['feedback'] == 'proprio'}
    return table


def square_errors(bag, window):
    """Return (tracking RMS, cross-track RMS) [m] of a recorded open-loop lap."""
    evaluation = evaluate_bag(bag, tip='true', start=window[0], end=window[1])
    cross = cross_track_errors(evaluation.targets, evaluation.tips)
    return evaluation.tracking.rms, float(np.sqrt(np.mean(cross ** 2)))


def main(argv=None):
    """
    Run the check; return 0 when every step ran (the numbers are printed, not judged).

    Parameters
    ----------
    argv : list of str, optional
        Command line without the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        Exit code (that of the first failing step).

    """
    args = parse_args(sys.argv[1:] if argv is None else argv)
    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    started = time.monotonic()
    steps = check_steps(args, output)
    for label, command in steps:
        print(f'cbha_identify_check: {label} ...', flush=True)
        code = _run(command(), output / f'{label.replace(" ", "_")}.log')
        if code:
            print(f'cbha_identify_check: {label} failed (exit {code}), see its log in {output}')
            return code
    rows = {}
    for label, folder in (('nominal', 'nominal'), ('identified', 'identified_run')):
        summary = json.loads((output / folder / 'summary.json').read_text())
        run = next(r for r in summary['runs'] if r['shape'] == 'square')
        rows[label] = square_errors(run['bag'], run['eval_window_s'])
    truth = dict(zip(
        [f'section_stiffness.{n}' for n in ('inner', 'outer')]
        + [f'actuator_gain.{n}' for n in ARM_VALVES],
        [float(v) for v in args.plant_section_scale.split(',')]
        + [float(v) for v in args.plant_gain_scale.split(',')]))
    if args.plant_base_offset is not None:
        truth.update(zip(('base_position.x', 'base_position.y', 'base_position.z'),
                         (float(v) for v in args.plant_base_offset.split(','))))
    result = json.loads((output / 'identified' / 'cbha_identified.json').read_text())
    fitted = {n: p for n, p in result['parameters'].items() if n in truth}
    print('open-loop square (plant with errors):')
    for label, (rms, cross) in rows.items():
        print(f'  {label:10s} scene: tracking RMS {rms * 1e3:6.2f} mm, cross-track RMS '
              f'{cross * 1e3:6.2f} mm')
    print(f'fitted factor vs truth (| fitted - truth | / standard error), '
          f'{result["samples"]["pressure_source"]} pressures:')
    scores = {}
    for name, p in fitted.items():
        scores[name] = abs(p['value'] - truth[name]) / p['standard_error']
        print(f'  {name:32s} {p["value"]:.5f} +- {p["standard_error"]:.5f} truth '
              f'{truth[name]:.4f}: {scores[name]:.2f}')
    for name, p in result['parameters'].items():
        if name not in truth:
            print(f'  {name:32s} {p["value"]:.5f} +- {p["standard_error"]:.5f}')
    print(f'  within 1 standard error: {sum(z <= 1.0 for z in scores.values())} of '
          f'{len(scores)}, within 2: {sum(z <= 2.0 for z in scores.values())}; largest '
          f'{max(scores.values()):.2f}')
    pots = pot_scores(args, result)
    if pots:
        print('fitted string pots vs the plant (| fitted - truth | / standard error):')
    for name, p in pots.items():
        print(f'  {name:36s} {p["value"]:10.4f} +- {p["standard_error"]:8.4f} truth '
              f'{p["truth"]:10.4f}: {p["error_over_standard_error"]:.2f}')
    camera_less = camera_less_rms(output, args)
    if camera_less:
        print('camera-less closed loop (string pots, no tip measurement), tracking RMS:')
    for label, shapes in camera_less.items():
        rms = ', '.join(f'{shape} {value * 1e3:6.3f} mm' for shape, value in shapes.items())
        print(f'  {label:13s} {rms}')
    (output / 'summary.json').write_text(json.dumps({
        'string_pots': pots, 'camera_less_rms_m': camera_less,
        'square_open': {k: {'tracking_rms_m': v[0], 'cross_track_rms_m': v[1]}
                        for k, v in rows.items()},
        'fitted': {n: {**p, 'truth': truth[n], 'error_over_standard_error': scores[n]}
                   for n, p in fitted.items()},
        'excite': args.excite,
        'identified_from': [str(b) for b in identification_bags(output / 'nominal', args.excite)],
        'wall_s': time.monotonic() - started}, indent=2))
    print(f'cbha_identify_check: wrote {output / "summary.json"} '
          f'({time.monotonic() - started:.0f} s)')
    return 0


if __name__ == '__main__':
    sys.exit(main())
