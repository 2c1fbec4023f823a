"""
``cbha_identify BAG [BAG ...] [--scene SCENE] [--output DIR]``: a calibrated scene from a session.

Reads ``tip/measured`` (``--tip-topic``) and the acting valve pressures from the bag:
``pressure_measured`` when recorded (``--pressure-source``), else ``pressure_command`` aligned
through the link ``--latency`` and the valves' ``--valve-time-constant`` (by default the paper's
3 ms and 10 ms; ``--fit-latency`` estimates the delay instead of taking it as given). Keeps at most
``--max-samples`` quasi-static samples and fits the scene's per-section stiffness and
per-actuator (cavity or cable) gain factors, optionally the base position
(``--fit-base-position``) (:func:`cbha_inverse.identify.fit.identify`; a Gaussian prior around
the nominal scene, ``--prior-sigma``, keeps what the data cannot see at the nominal value). Writes
``DIR/<scene>_identified.yaml`` (a complete scene file with the fitted ``calibration`` block:
``-p scene:=...``), ``DIR/<scene>_identified_report.txt`` (values with standard errors, the
least determined combinations, correlation matrix, tip RMS before/after, identifiability
warnings) and ``DIR/<scene>_identified.png`` (measured vs predicted tip, y-z plane, before and
after), and the same numbers as ``DIR/<scene>_identified.json``. When the bags have
``string_pots`` and the scene a ``sensors`` block, the pots' offsets and gains are then fitted
against the identified model (:func:`cbha_inverse.identify.pots.calibrate_pots`; a pot whose
length moves less than ``--pot-min-range`` keeps the scene's gain) and written into the
identified scene's ``sensors`` block. Exit status 0 on a valid fit, 1 when the data cannot give
one (no tip measurements, too little excitation, pot readings that follow another pot's length:
nothing is written), 2 on a bad file.
"""

import argparse
import functools
import json
from pathlib import Path
import sys
import time

from cbha_inverse.bag.storage import BagError
from cbha_inverse.config_files import read_yaml
from cbha_inverse.errors import ConfigError, report_config_error, report_error
from cbha_inverse.identify.fit import identify
from cbha_inverse.identify.pots import (calibrate_pots, calibrated_sensor_items, pot_data,
                                        reading_columns, report_lines)
from cbha_inverse.identify.progress import ProgressLine
from cbha_inverse.identify.samples import (acting_pressures, IdentificationError,
                                           pooled_samples, PRESSURE_SOURCES,
                                           quasi_static_samples, read_session)
from cbha_inverse.robot.safety import valve_order
from cbha_inverse.scene import load_scene, resolve_scene_path
import numpy as np
import yaml

PROGRAM = 'cbha_identify'


def parse_args(argv):
    """Parse the command line."""
    parser = argparse.ArgumentParser(prog=PROGRAM, description=__doc__.split('\n\n')[0])
    parser.add_argument('bags', nargs='+', metavar='BAG',
                        help='the recorded session(s) (rosbag2 folders; the samples of several '
                        'are pooled, e.g. a lap and an excitation program)')
    parser.add_argument('--scene', default='cbha.yaml', help='nominal scene (path or name)')
    parser.add_argument('--output', default='output/identify', help='output folder')
    parser.add_argument('--namespace', default='/cbha', help='namespace of the topics')
    parser.add_argument('--tip-topic', default='tip/measured',
                        help='the tip reference: tip/measured (a tracker), or tip/true of a '
                        'simulated plant')
    parser.add_argument('--valve-names', default=None,
                        help='comma-separated command order (default: the scene order)')
    parser.add_argument('--latency', type=float, default=0.003,
                        help='command -> valve delay [s]')
    parser.add_argument('--valve-time-constant', type=float, default=0.01,
                        help='first-order valve response [s]')
    parser.add_argument('--settle-time', type=float, default=0.05,
                        help='quasi-static: pressures steady over this time [s]')
    parser.add_argument('--settle-tolerance', type=float, default=2000.0,
                        help='quasi-static: largest pressure change over --settle-time [Pa]')
    parser.add_argument('--max-samples', type=int, default=80,
                        help='quasi-static samples fitted at most (evenly spread)')
    parser.add_argument('--prior-sigma', type=_prior_sigma, default=0.5,
                        help='prior standard deviation of each log factor around the nominal '
                        'scene (0.5: within a factor 1.65 at one sigma); "none": no prior')
    parser.add_argument('--pressure-source', choices=PRESSURE_SOURCES, default='auto',
                        help='acting pressures: measured (pressure_measured), commanded '
                        '(pressure_command through --latency and the valve lag), auto: '
                        'measured when recorded')
    parser.add_argument('--measured-latency', type=float, default=0.0,
                        help='measured source: how much later than a tip a measurement of the '
                        'same instant is received [s]')
    parser.add_argument('--fit-latency', action='store_true',
                        help='also estimate the delay of the pressure source (--latency, or '
                        '--measured-latency), starting at the given value')
    parser.add_argument('--latency-sigma', type=_prior_sigma, default=0.01,
                        help='prior standard deviation of the fitted delay [s] ("none")')
    parser.add_argument('--fit-base-position', action='store_true',
                        help="also fit the chain base's position in base_frame (a tracker "
                        'registration error)')
    parser.add_argument('--base-position-sigma', type=_prior_sigma, default=0.01,
                        help='prior standard deviation of each base coordinate [m] ("none")')
    parser.add_argument('--pot-min-range', type=float, default=0.002,
                        help='a string pot whose routed length moves less over the samples '
                        "keeps the scene's gain (only its offset is fitted) [m]")
    shown = parser.add_mutually_exclusive_group()
    shown.add_argument('--quiet', action='store_true', help='no progress line')
    shown.add_argument('--verbose', action='store_true',
                       help='every forward evaluation on its own line (default: one updating '
                            'line)')
    return parser.parse_args(argv)


def _prior_sigma(text):
    """Parse ``--prior-sigma``: a finite positive number, or ``none``."""
    if text.strip().lower() == 'none':
        return None
    value = float(text)
    if not (np.isfinite(value) and value > 0.0):
        raise argparse.ArgumentTypeError(f'must be a finite number > 0 or none, got {text}')
    return value


def command_order(scene, valve_names):
    """
    Return, per scene actuator, its entry in the recorded commands (``commands[:, order]``).

    ``valve_names`` is the comma-separated command order (None: the scene order); a wrong one
    raises ``ValueError`` (:func:`cbha_inverse.robot.safety.valve_order`).
    """
    names = None if valve_names is None else valve_names.split(',')
    _, scene_index = valve_order(scene.actuator_names, names)
    return np.argsort(scene_index)


def identified_scene_data(scene_path, calibration, pots=None):
    """
    Return the scene file's data with the calibration block replaced (segment paths absolute).

    Parameters
    ----------
    scene_path : pathlib.Path
        The nominal scene file.
    calibration : cbha_inverse.scene.calibration.Calibration
        The calibration to carry.
    pots : cbha_inverse.identify.pots.PotCalibration, optional
        Fitted string-pot offsets and gains for the ``sensors`` block.

    Returns
    -------
    dict
        A complete scene, loadable from any folder.

    """
    data = read_yaml(scene_path)
    for item in (data.get('chain') or {}).get('sections') or []:
        if isinstance(item, dict) and isinstance(item.get('segment'), str):
            item['segment'] = str((scene_path.parent / item['segment']).resolve())
    data['calibration'] = calibration.as_yaml()
    if pots is not None:
        data['sensors'] = calibrated_sensor_items(data.get('sensors') or [], pots)
    return data


def format_report(result, samples, bag, scene_name, pots=None):
    """Return the text report of an identification (and of the pots' calibration, if any)."""
    lines = [f'cbha_identify: {bag}, scene {scene_name}',
             f'samples: {samples.recorded} tip measurements, {samples.quasi_static} quasi-static, '
             f'{len(samples.tips)} fitted; {result.evaluations} forward evaluations',
             f'pressures: {samples.pressure_source}' + (
                 f' ({samples.measured_dropped} invalid pressure_measured messages dropped)'
                 if samples.measured_dropped else ''),
             f'tip RMS before {result.rms_before * 1e3:.3f} mm, after '
             f'{result.rms_after * 1e3:.3f} mm (residual noise {result.noise * 1e3:.3f} mm per '
             'axis)', '', 'fitted values (factors on top of the scene calibration) +- '
             'standard error (prior standard deviation):']
    lines += [f'  {n:32s} {_value_text(n, v, se, p)}'
              for n, v, se, p in zip(result.names, result.values, result.standard_errors,
                                     result.prior_sigmas)]
    lines += ['', 'prior: each log factor and offset ~ N(0, prior^2) around the nominal scene',
              'principal combinations of the fit coordinates over their prior (log factors, '
              'base position / 10 mm, latency / 5 ms; columns in the order above, least '
              'determined first): standard error, data share of the information:']
    lines += ['  ' + ' '.join(f'{c:+.2f}' for c in direction) + f'   +- {error:.4f}, data '
              f'{share:.0%}' for direction, share, error in
              zip(result.directions.T, result.data_share, result.direction_errors)]
    lines += ['', 'correlation matrix (rows/columns in the order above):']
    lines += ['  ' + ' '.join(f'{c:+.2f}' for c in row) for row in result.correlation]
    lines += ['', 'identifiability warnings:' if result.warnings else
              'identifiability: every factor is separable from this data']
    lines += [f'  {w}' for w in result.warnings]
    if pots is not None:
        lines += report_lines(pots)
    return '\n'.join(lines) + '\n'


def _value_text(name, value, error, prior):
    """Return a fitted value, its error and prior: factors bare, offsets in mm, delays in ms."""
    scale, unit, digits = ((1e3, ' mm', 3) if name.startswith('base_position.') else
                           (1e3, ' ms', 2) if name == 'latency' else (1.0, '', 4))
    prior = f'(prior {prior * scale:g}{unit})' if np.isfinite(prior) else '(no prior)'
    return (f'{value * scale:.{digits}f}{unit} +- {error * scale:.{digits}f}{unit}   {prior}')


def _delayed_pressures(sessions, samples, order, valve_time_constant, delay):
    """Return the samples' acting pressures (scene order) for another delay of their source."""
    out = np.empty_like(samples.pressures)
    for k, session in enumerate(sessions):
        mine = samples.part == k
        out[mine] = acting_pressures(session, samples.receive_times[mine],
                                     samples.pressure_source, delay, valve_time_constant)[0]
    return out[:, order]


def result_data(result, samples, pots=None):
    """Return the identification as plain data (the ``DIR/<scene>_identified.json`` file)."""
    pot_entry = {} if pots is None else {'string_pots': pot_data(pots)}
    return {
        'parameters': {n: {'value': float(v), 'standard_error': float(se),
                           'prior_sigma': float(p) if np.isfinite(p) else None}
                       for n, v, se, p in zip(result.names, result.values,
                                              result.standard_errors, result.prior_sigmas)},
        'correlation': np.round(result.correlation, 6).tolist(),
        'directions': np.round(result.directions, 6).tolist(),
        'data_share': np.round(result.data_share, 6).tolist(),
        'direction_errors': np.round(result.direction_errors, 8).tolist(),
        'tip_rms_before_m': result.rms_before, 'tip_rms_after_m': result.rms_after,
        'noise_m': result.noise, 'warnings': list(result.warnings),
        'evaluations': result.evaluations,
        'samples': {'recorded': samples.recorded, 'quasi_static': samples.quasi_static,
                    'fitted': len(samples.tips), 'pressure_source': samples.pressure_source,
                    'measured_dropped': samples.measured_dropped}, **pot_entry}


def plot_fit(path, tips, before, after, title):
    """Write the PNG: measured vs predicted tips in the y-z plane, nominal and identified."""
    import matplotlib
    matplotlib.use('Agg')
    import matplotlib.pyplot as plt
    figure, axes = plt.subplots(1, 2, figsize=(10, 4.8), sharex=True, sharey=True)
    for ax, predicted, label in ((axes[0], before, 'nominal scene'),
                                 (axes[1], after, 'identified scene')):
        ax.plot(tips[:, 1] * 1e3, tips[:, 2] * 1e3, 'k.', label='measured')
        ax.plot(predicted[:, 1] * 1e3, predicted[:, 2] * 1e3, 'r+', label='predicted')
        rms = np.sqrt(np.mean(np.sum((predicted - tips) ** 2, axis=1))) * 1e3
        ax.set_title(f'{label}: RMS {rms:.2f} mm')
        ax.set_xlabel('y [mm]')
        ax.set_aspect('equal')
        ax.legend()
    axes[0].set_ylabel('z [mm]')
    figure.suptitle(title)
    figure.tight_layout()
    figure.savefig(path, dpi=100)
    plt.close(figure)


def _pot_calibration(scene_path, scene, result, pressures, samples, min_range):
    """Return the pots' calibration against the fitted model (None: no pots to calibrate)."""
    if samples.pots is None:
        return None
    if scene.sensors is None:
        print(f'{PROGRAM}: the bags have string_pots, scene {scene.name} declares no sensors: '
              'the pots are not calibrated', flush=True)
        return None
    print(f'{PROGRAM}: calibrating {scene.sensors.n_sensors} string pots against the '
          'identified model', flush=True)
    errors = result.standard_errors
    covariance = np.nan_to_num(result.correlation) * np.outer(errors, errors)
    return calibrate_pots(scene_path, result.names, result.values, covariance, pressures,
                          samples.pots, samples.pot_names, min_range=min_range)


def main(argv=None):
    """
    Run ``cbha_identify``.

    Parameters
    ----------
    argv : list of str, optional
        Command line without the program name (default ``sys.argv[1:]``).

    Returns
    -------
    int
        0 on a valid fit, 1 when the data cannot give one, 2 on a bad file or argument.

    """
    args = parse_args(sys.argv[1:] if argv is None else argv)
    started = time.monotonic()
    progress = ProgressLine(mode='quiet' if args.quiet else 'verbose' if args.verbose else 'line')
    try:
        scene_path = resolve_scene_path(args.scene)
        scene = load_scene(scene_path)
        order = command_order(scene, args.valve_names)
        sessions, parts = [], []
        for bag in args.bags:
            print(f'{PROGRAM}: reading {bag}', flush=True)
            session = read_session(bag, args.namespace, args.tip_topic)
            if session[1].shape[1] != len(order):
                raise IdentificationError(f'{bag}: commands of {session[1].shape[1]} valves, '
                                          f'the scene has {len(order)} actuators')
            sessions.append(session)
            try:
                parts.append(quasi_static_samples(
                    session, latency=args.latency, valve_time_constant=args.valve_time_constant,
                    settle_time=args.settle_time, settle_tolerance=args.settle_tolerance,
                    max_samples=sys.maxsize, pressure_source=args.pressure_source,
                    measured_latency=args.measured_latency))
            except IdentificationError as exc:
                raise IdentificationError(f'{bag}: {exc}') from None
            print(f'{PROGRAM}: {bag}: {parts[-1].recorded} tip samples, '
                  f'{parts[-1].quasi_static} quasi-static ({parts[-1].pressure_source} '
                  'pressures)', flush=True)
        samples = pooled_samples(parts, args.max_samples)
        if samples.pots is not None and scene.sensors is not None:
            reading_columns(scene.sensors.names, samples.pot_names)   # before the long fit
        print(f'{PROGRAM}: fitting {len(samples.tips)} samples through scene {scene.name}',
              flush=True)
        pressures = samples.pressures[:, order]
        if args.fit_latency:
            if samples.pressure_source == 'mixed':
                raise IdentificationError('--fit-latency needs one pressure source in every bag '
                                          '(some have pressure_measured, some not): choose one '
                                          'with --pressure-source')
            pressures = functools.partial(_delayed_pressures, sessions, samples, order,
                                          args.valve_time_constant)
        result = identify(scene_path, pressures, samples.tips, prior_sigma=args.prior_sigma,
                          base_position=args.fit_base_position,
                          base_position_sigma=args.base_position_sigma,
                          latency=samples.delay if args.fit_latency else None,
                          latency_sigma=args.latency_sigma,
                          progress=progress)
        pots = _pot_calibration(scene_path, scene, result, pressures, samples,
                                args.pot_min_range)
    except (ConfigError, FileNotFoundError, BagError) as exc:
        return report_config_error(PROGRAM, exc)
    except (IdentificationError, ValueError) as exc:
        return report_error(PROGRAM, exc, 1)
    finally:
        progress.close()
    output = Path(args.output)
    output.mkdir(parents=True, exist_ok=True)
    stem = f'{scene_path.stem}_identified'
    scene_file = output / f'{stem}.yaml'
    header = (f'# {scene_file.name}: written by {PROGRAM} from {", ".join(args.bags)} '
              f'(nominal scene {scene_path}); see {stem}_report.txt\n')
    scene_file.write_text(header + yaml.safe_dump(
        identified_scene_data(scene_path, result.calibration, pots), sort_keys=False))
    report = format_report(result, samples, ', '.join(args.bags), scene.name, pots)
    (output / f'{stem}_report.txt').write_text(report)
    (output / f'{stem}.json').write_text(json.dumps(result_data(result, samples, pots),
                                                    indent=1))
    plot_fit(output / f'{stem}.png', samples.tips, result.predicted_before,
             result.predicted_after,
             f'{PROGRAM}: {", ".join(Path(b).name for b in args.bags)}')
    print(report, end='')
    print(f'{PROGRAM}: wrote {scene_file} (use -p scene:={scene_file.resolve()}), report and '
          f'PNG in {time.monotonic() - started:.1f} s', flush=True)
    return 0


if __name__ == '__main__':
    sys.exit(main())
